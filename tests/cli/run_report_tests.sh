#!/usr/bin/env bash
# report.html in headless Chromium, as a physicist opens it: no console message; the DOM
# holds the values run.json has, labelled and rounded as shown; a screenshot for each CT
# window (#window=soft, lung, bone), each different; every axial slice through the organ
# browsable; printed on A4. Prints "N passed, N failed" and exits non-zero on any failure.
source "$(dirname "$0")/check.sh"
chrome=(chromium --headless --no-sandbox --disable-gpu --no-pdf-header-footer)
command -v chromium >/dev/null || { echo "FAIL chromium is not installed (scripts/setup.sh)"; exit 1; }

"$bin" -q run "$src/pipelines/default.yaml" --out "$tmp/run" --set export.uncertainty=sigma.nrrd \
  --set export.mesh=prostate_fit.vtp || { echo "FAIL the default scene"; exit 1; }
page="file://$tmp/run/report.html"
start=$(date +%s%N)
"${chrome[@]}" --enable-logging=stderr --v=0 --dump-dom "$page" >"$tmp/dom.html" 2>"$tmp/chromium.log"
load_s=$(( ($(date +%s%N) - start) / 1000000 ))
echo "     report.html: $(stat -c %s "$tmp/run/report.html") bytes; Chromium start, load and render (dump-dom): ${load_s} ms"

check "no console message" bash -c "! grep -q 'CONSOLE' '$tmp/chromium.log'"
check "the scripts ran (3D view and slice browser)" bash -c "
  grep -q 'data-rendered=\"yes\"' '$tmp/dom.html' && grep -q 'id=\"slice-label\">[0-9]* of [0-9]*<' '$tmp/dom.html'"
check "the DOM holds run.json's values, labelled, with units and rounded as shown" $py - "$tmp/dom.html" "$tmp/run/run.json" <<'EOF'
import html.parser, json, math, re, sys
dom, run = open(sys.argv[1]).read(), json.load(open(sys.argv[2]))

class Cells(html.parser.HTMLParser):
    def __init__(self):
        super().__init__(); self.cells = []; self.open = None
    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if 'data-key' in a: self.open = [a['data-key'], a['data-value'], '']
    def handle_data(self, data):
        if self.open is not None: self.open[2] += data
    def handle_endtag(self, tag):
        if self.open is not None and tag in ('td', 'b', 'span'):
            self.cells.append(self.open); self.open = None

def value_of(key):
    if key.startswith('stages.'):
        name = key.split('.')[1]
        return next(s['wall_s'] for s in run['stages'] if s['name'] == name)
    v = run
    for part in key.split('.'): v = v[part]
    return v

p = Cells(); p.feed(dom)
keys = {k for k, _, _ in p.cells}
for needed in ['export.roi', 'export.volume_on_ct_grid_cm3', 'export.contours',
               'export.checks.topology_kept', 'export.checks.volume_kept', 'truth.dice',
               'truth.hd95_mm', 'truth.msd_mm', 'fit.residual_mean_mm', 'fit.volume_change_pct',
               'organ.volume_cm3', 'model.particles', 'stages.fit.wall_s', 'status']:
    assert needed in keys, needed
for key, raw, text in p.cells:
    v = value_of(key)
    text = text.replace('\xa0', ' ').strip()
    if isinstance(v, bool):
        assert raw == json.dumps(v) and text == ('yes' if v else 'no'), (key, raw, text)
    elif isinstance(v, (int, float)):
        assert math.isclose(float(raw), v, rel_tol=1e-12, abs_tol=1e-12), (key, raw, v)
        m = re.fullmatch(r'(-?[0-9.]+)( (mm|cm3|%|s))?', text)
        assert m, (key, text)
        decimals = len(m.group(1).split('.')[1]) if '.' in m.group(1) else 0
        assert abs(float(m.group(1)) - v) <= 0.5 * 10 ** -decimals + 1e-9, (key, text, v)
        assert not re.search(r'e[+-]', text), (key, text)  # no 3.403e+04
        if key.endswith('_mm'): assert m.group(3) == 'mm', (key, text)
        if key.endswith('_cm3'): assert m.group(3) == 'cm3', (key, text)
        if key.endswith('_pct'): assert m.group(3) == '%', (key, text)
        if key.endswith('wall_s') or key.endswith('_s'): assert m.group(3) == 's', (key, text)
    else:
        assert raw == v and text == v, (key, raw, text, v)
# No raw key is shown as a label.
assert not re.search(r'<th>[a-z_]+_(mm|cm3|pct)</th>', dom)
print(len(p.cells), 'values checked')
EOF
check "the window chosen for the prostate is soft tissue, from its surroundings" bash -c "
  grep -q '<body data-window=\"soft\"' '$tmp/dom.html' && grep -q 'soft tissue (median -\?[0-9]* HU within 10 mm of the organ)' '$tmp/dom.html'"
for w in soft lung bone; do
  "${chrome[@]}" --window-size=1400,2600 --screenshot="$tmp/$w.png" "$page#window=$w" >/dev/null 2>&1
  "${chrome[@]}" --dump-dom "$page#window=$w" >"$tmp/dom-$w.html" 2>/dev/null
done
check "a screenshot for each window, each its own" $py -c "
import hashlib, os
shots = [open('$tmp/%s.png' % w, 'rb').read() for w in ('soft', 'lung', 'bone')]
assert all(len(s) > 60000 for s in shots), [len(s) for s in shots]
assert len({hashlib.sha256(s).hexdigest() for s in shots}) == 3
for w in ('soft', 'lung', 'bone'):
    d = open('$tmp/dom-%s.html' % w).read()
    assert 'data-window=\"%s\"' % w in d.split('>')[0] + d[d.find('<body'):d.find('<body') + 60], w
print([len(s) for s in shots])"
check "every axial slice through the planning and the fitted organ is in the browser" $py -c "
import pydicom, re
zs = set()
for f in ('$tmp/run/phantom/rtstruct.dcm', '$tmp/run/prostate_fit_rtstruct.dcm'):
    d = pydicom.dcmread(f)
    roi = [r.ROINumber for r in d.StructureSetROISequence if r.ROIName in ('Prostate', 'Prostate_fit')][0]
    for c in d.ROIContourSequence:
        if c.ReferencedROINumber == roi:
            zs |= {round(float(s.ContourData[2]), 2) for s in c.ContourSequence}
dom = open('$tmp/dom.html').read()
n = len(re.findall(r'<figure class=\"axial', dom))
expected = round((max(zs) - min(zs)) / 2.5) + 1
assert n == expected, (n, expected)
assert len(re.findall(r'<figure class=\"axial current', dom)) == 1
print(n, 'axial slices')"
"${chrome[@]}" --print-to-pdf="$tmp/report.pdf" "$page" >/dev/null 2>&1
check "prints on A4" $py -c "
import re
pdf = open('$tmp/report.pdf', 'rb').read()
boxes = re.findall(rb'/MediaBox \[0 0 ([0-9.]+) ([0-9.]+)\]', pdf)
assert boxes and all(abs(float(w) - 595.3) < 1 and abs(float(h) - 841.9) < 1 for w, h in boxes), boxes
assert len(boxes) <= 6, len(boxes)
print(len(boxes), 'A4 pages')"
# The uncertainty (fitting/surface_uncertainty.h) as run.json, the CT-grid map, the mesh
# and the 3D view carry it.
check "the uncertainty: calibrated on this case, larger where unseen, bounded by its prior" $py -c "
import json; d = json.load(open('$tmp/run/run.json')); u = d['fit']['uncertainty']
assert u['seen']['median_mm'] < u['unseen']['median_mm'] <= u['far_sd_mm'], u
assert u['all']['p95_mm'] <= u['far_sd_mm'] + 1e-9 and u['surface_samples'] == 4000, u
assert d['truth']['uncertainty']['within_2sd_share'] >= 0.9, d['truth']['uncertainty']
assert d['export']['uncertainty']['file'] == 'sigma.nrrd', d['export']"
check "sigma.nrrd: the prior (with the resolution) far from the points, less near them, on the CT's grid" $py -c "
import json, struct
d = json.load(open('$tmp/run/run.json')); u = d['fit']['uncertainty']
raw = open('$tmp/run/sigma.nrrd', 'rb').read()
head, body = raw.split(b'\n\n', 1)
assert b'sizes: 320 320 56' in head and b'type: float' in head, head
v = struct.unpack('<%df' % (len(body) // 4), body)
assert len(v) == 320 * 320 * 56
far = u['far_sd_mm']  # the widest prior and the model's resolution
assert far >= (u['prior_sd_mm'] ** 2 + u['resolution_sd_mm'] ** 2) ** 0.5 - 1e-9, u
assert 0 < u['resolution_sd_mm'] < u['prior_sd_mm'], u
assert abs(v[0] - far) < 1e-5 and abs(v[-1] - far) < 1e-5, (v[0], v[-1], far)
# above that only near a point the fit left off (the posterior mean of its residual)
top = (far ** 2 + d['fit']['residual_max_mm'] ** 2) ** 0.5
assert min(v) >= u['resolution_sd_mm'] - 1e-5 and max(v) <= top and min(v) < 0.6 * far, (min(v), max(v), top)"
check "the VTP mesh carries sigma_mm at each point" $py - "$tmp/run/prostate_fit.vtp" <<'EOF'
import re, sys
x = open(sys.argv[1]).read()
a = re.search(r'<DataArray type="Float32" Name="sigma_mm"[^>]*RangeMin="([0-9.e+-]+)" *RangeMax="([0-9.e+-]+)"', x)
assert a and 0 < float(a.group(1)) < float(a.group(2)) < 5, a
EOF
check "the 3D view is coloured by sigma" bash -c "
  grep -q 'coloured by its uncertainty sigma' '$tmp/dom.html' && grep -q '\"s\":\\[' '$tmp/run/report.html'"
check "export.uncertainty without a fit is refused naming the key" bash -c "
  printf 'phantom: {kind: pelvis}\norgan: {roi: Prostate}\nmodel: {radius_mm: 2.0}\nexport: {uncertainty: s.nrrd}\n' >'$tmp/nofit.yaml'
  '$bin' validate '$tmp/nofit.yaml' 2>'$tmp/nofit.err'; test \$? -eq 2 &&
  grep -q 'nofit.yaml:4: export.uncertainty: the uncertainty is the fit.s' '$tmp/nofit.err'"
finish
