"""Writes an organfit model file as organfit does: compact JSON, its checksum last.

The checksum (modules/pipeline/include/organfit/pipeline/model_file.h) is 16 hexadecimal
digits of geometry::hash_bytes over the file's text before the key: 8-byte little-endian
words (the last zero-padded) folded through splitmix64, then the length. Tests that edit a
model to make one thing wrong write it with this, so that the refusal they expect is of that
thing, not of the edit itself.

    python3 model_checksum.py FILE   # prints FILE's checksum as organfit computes it
"""
import json
import sys

_MASK = (1 << 64) - 1


def _splitmix64(z):
    z = (z + 0x9E3779B97F4A7C15) & _MASK
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK
    return z ^ (z >> 31)


def hash_bytes(data, h=0):
    for at in range(0, len(data), 8):
        h = _splitmix64(h ^ int.from_bytes(data[at:at + 8].ljust(8, b'\0'), 'little'))
    return _splitmix64(h ^ len(data))


def write_model(model, path):
    """`model` (a dict, its old checksum dropped) written to `path` with a checksum."""
    body = dict(model)
    body.pop('checksum', None)
    text = json.dumps(body, separators=(',', ':'))[:-1]
    with open(path, 'w') as f:
        f.write(text + ',"checksum":"%016x"}\n' % hash_bytes(text.encode()))


if __name__ == '__main__':
    text = open(sys.argv[1], 'rb').read()
    print('%016x' % hash_bytes(text[:text.rindex(b',"checksum":"')]))
