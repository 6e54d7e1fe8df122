#include "dicom_values.h"

#include <gdcmTrace.h>
#include <iconv.h>
#include <zlib.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace organfit::dicom::detail {

std::vector<double> numbers(const std::string& value) {
  std::vector<double> out;
  std::stringstream ss(value);
  std::string item;
  while (std::getline(ss, item, '\\')) {
    try {
      out.push_back(std::stod(item));
    } catch (const std::exception&) {
      out.push_back(std::nan(""));
    }
  }
  return out;
}

}  // namespace organfit::dicom::detail

namespace organfit::dicom::detail {

void quiet_gdcm() {
  gdcm::Trace::WarningOff();
  gdcm::Trace::ErrorOff();
  gdcm::Trace::DebugOff();
}

namespace {

constexpr const char* kLongVrs[] = {"OB", "OW", "OF", "SQ", "UT", "UN", "OD",
                                    "OL", "UC", "UR", "OV", "SV", "UV"};
/// Every VR of PS3.5 (2023); an element naming another makes GDCM 3.0 abort (found by fuzzing).
bool known_vr(const unsigned char* v) {
  static const char* all[] = {"AE", "AS", "AT", "CS", "DA", "DS", "DT", "FL", "FD",
                              "IS", "LO", "LT", "OB", "OD", "OF", "OL", "OV", "OW",
                              "PN", "SH", "SL", "SQ", "SS", "ST", "SV", "TM", "UC",
                              "UI", "UL", "UN", "UR", "US", "UT", "UV"};
  return std::any_of(std::begin(all), std::end(all),
                     [&](const char* a) { return a[0] == v[0] && a[1] == v[1]; });
}

std::uint32_t u32_at(const unsigned char* p) {
  return p[0] | (p[1] << 8) | (p[2] << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}

/// Walks explicit-VR little-endian elements in [at, end): every declared length must fit,
/// sequences and items included (undefined lengths end at their delimiters). Returns the
/// position after the last element walked, or -1 when a length runs past `end`. Stops
/// (returning `at`) at anything that is not explicit VR: GDCM decides about those.
long long walk(const std::vector<unsigned char>& b, long long at, long long end, int depth,
               bool& ok, bool implicit, bool raw_items = false, bool big = false,
               bool undefined_length = false) {
  auto r16 = [big](const unsigned char* p) {
    return static_cast<std::uint16_t>(big ? (p[0] << 8) | p[1] : p[0] | (p[1] << 8));
  };
  auto r32 = [big](const unsigned char* p) {
    return big ? (static_cast<std::uint32_t>(p[0]) << 24) | (p[1] << 16) | (p[2] << 8) | p[3]
               : u32_at(p);
  };
  if (depth > 32) return ok = false, -1;  // nesting deeper than any real structure set
  while (at + 8 <= end) {
    const unsigned char* e = b.data() + at;
    const std::uint16_t group = r16(e), element = r16(e + 2);
    if (group == 0xFFFE && depth == 0)
      return ok = false, -1;  // items belong in sequences (GDCM aborts)
    if (group == 0xFFFE) {    // item or delimiter: tag + 4-byte length, no VR
      const std::uint32_t length = r32(e + 4);
      if (element == 0xE00D || element == 0xE0DD) return at + 8;  // item / sequence delimiter
      if (element != 0xE000) return ok = false, -1;
      if (length == 0xFFFFFFFFu) {
        if (raw_items) return ok = false, -1;  // fragments always have a length
        at = walk(b, at + 8, end, depth + 1, ok, implicit, false, big, true);
        if (!ok) return -1;
      } else {
        if (at + 8 + length > end) return ok = false, -1;
        if (!raw_items)
          walk(b, at + 8, at + 8 + length, depth + 1, ok, implicit, false,
               big);  // fragments hold data
        if (!ok) return -1;
        at += 8 + length;
      }
      continue;
    }
    if (implicit) {  // tag, 4-byte length; undefined lengths are sequences of items
      const std::uint32_t length = r32(e + 4);
      if (length == 0xFFFFFFFFu) {
        at = walk(b, at + 8, end, depth + 1, ok, implicit, false, big, true);
        if (!ok) return -1;
        continue;
      }
      if (at + 8 + static_cast<long long>(length) > end) return ok = false, -1;
      at += 8 + length;
      continue;
    }
    if (!known_vr(e + 4)) return ok = false, -1;  // explicit VR must name a VR
    const std::string vr(reinterpret_cast<const char*>(e + 4), 2);
    const bool long_form = std::any_of(std::begin(kLongVrs), std::end(kLongVrs),
                                       [&](const char* v) { return vr == v; });
    long long header = 8, length = r16(e + 6);
    if (long_form) {
      if (at + 12 > end) return ok = false, -1;
      header = 12;
      length = r32(e + 8);
      if (length ==
          0xFFFFFFFFLL) {  // undefined length: a sequence, or encapsulated pixel fragments
        // UN of undefined length is a sequence in implicit VR little endian (PS3.5
        // 6.2.2), as gdcmconv writes private sequences; OB/OW ones hold pixel fragments.
        if (vr == "UN")
          at = walk(b, at + 12, end, depth + 1, ok, true, false, false, true);
        else
          at = walk(b, at + 12, end, depth + 1, ok, implicit, vr != "SQ", big, true);
        if (!ok) return -1;
        continue;
      }
    }
    if (at + header + length > end) return ok = false, -1;
    if (vr == "SQ") {
      walk(b, at + header, at + header + length, depth + 1, ok, implicit, false, big);
      if (!ok) return -1;
    }
    at += header + length;
  }
  // Content of undefined length must end at its delimiter, not at the end of the file:
  // an item left open made GDCM abort (found by fuzzing).
  if (undefined_length) return ok = false, -1;
  return at;
}

/// How a raw data set (no preamble, no File Meta group) is encoded.
struct RawEncoding {
  bool implicit = false, big = false;
};

/// The encoding GDCM 3.0 reads a raw data set in, from its first 8 bytes as
/// gdcm::FileMetaInformation::ReadCompat guesses it: the first tag read little endian; a
/// group 0008 (or 0800, big endian) or an element 0010 (a private creator) is explicit when
/// a VR follows, implicit otherwise; any other tag followed by a VR is explicit, big endian
/// when its group or element exceeds 0xff as read. None when GDCM gives up (no VR after
/// another tag) or cannot read it (implicit big endian), and for a first element (0000,0000)
/// that GDCM reads past to guess again (not a structure set's).
std::optional<RawEncoding> raw_data_set_encoding(const std::vector<unsigned char>& b) {
  if (b.size() < 8) return std::nullopt;
  const unsigned group = b[0] | (b[1] << 8), element = b[2] | (b[3] << 8);
  const bool vr = known_vr(&b[4]) || (b[4] == '?' && b[5] == '?');  // GDCM: "??" is a VR
  if (group == 0x0008) return RawEncoding{!vr, false};
  if (group == 0x0800) return vr ? std::optional(RawEncoding{false, true}) : std::nullopt;
  if (element == 0x0010) return RawEncoding{!vr, false};
  if (!vr) return std::nullopt;
  return RawEncoding{false, group > 0xff || element > 0xff};
}

/// Inflates a raw deflate stream (RFC 1951, as the Deflated Explicit VR Little Endian
/// transfer syntax stores the data set). False when it is not one, or would exceed 2 GiB.
bool inflate_raw(const unsigned char* data, size_t size, std::vector<unsigned char>& out) {
  z_stream z{};
  if (inflateInit2(&z, -MAX_WBITS) != Z_OK) return false;
  z.next_in = const_cast<unsigned char*>(data);
  z.avail_in = static_cast<uInt>(size);
  unsigned char chunk[1 << 16];
  int rc = Z_OK;
  while (rc == Z_OK) {
    z.next_out = chunk;
    z.avail_out = sizeof chunk;
    rc = inflate(&z, Z_NO_FLUSH);
    if (rc != Z_OK && rc != Z_STREAM_END) break;
    out.insert(out.end(), chunk, chunk + (sizeof chunk - z.avail_out));
    if (out.size() > (size_t{1} << 31)) rc = Z_MEM_ERROR;
    if (rc == Z_OK && z.avail_in == 0 && z.avail_out != 0) rc = Z_BUF_ERROR;  // cut short
  }
  inflateEnd(&z);
  return rc == Z_STREAM_END;
}

}  // namespace

bool to_utf8(const std::string& value, const std::string& charset, std::string& utf8) {
  std::string term = charset;
  while (!term.empty() && (term.back() == ' ' || term.back() == '\0'))
    term.pop_back();
  while (!term.empty() && term.front() == ' ')
    term.erase(term.begin());
  if (term.find('\\') != std::string::npos || term.rfind("ISO 2022", 0) == 0) return false;
  static const std::pair<const char*, const char*> names[] = {{"", "ISO-8859-1"},
                                                              {"ISO_IR 6", "ISO-8859-1"},
                                                              {"ISO_IR 100", "ISO-8859-1"},
                                                              {"ISO_IR 101", "ISO-8859-2"},
                                                              {"ISO_IR 109", "ISO-8859-3"},
                                                              {"ISO_IR 110", "ISO-8859-4"},
                                                              {"ISO_IR 144", "ISO-8859-5"},
                                                              {"ISO_IR 127", "ISO-8859-6"},
                                                              {"ISO_IR 126", "ISO-8859-7"},
                                                              {"ISO_IR 138", "ISO-8859-8"},
                                                              {"ISO_IR 148", "ISO-8859-9"},
                                                              {"ISO_IR 203", "ISO-8859-15"},
                                                              {"ISO_IR 166", "TIS-620"},
                                                              {"ISO_IR 13", "JIS_X0201"},
                                                              {"ISO_IR 192", "UTF-8"},
                                                              {"GB18030", "GB18030"},
                                                              {"GBK", "GBK"}};
  const char* from = nullptr;
  for (const auto& [dicom, iconv_name] : names)
    if (term == dicom) from = iconv_name;
  if (!from) return false;
  iconv_t cd = iconv_open("UTF-8", from);
  if (cd == reinterpret_cast<iconv_t>(-1)) return false;
  std::string in = value;
  std::string out(4 * in.size() + 4, '\0');
  char* in_p = in.data();
  size_t in_left = in.size();
  char* out_p = out.data();
  size_t out_left = out.size();
  const size_t rc = iconv(cd, &in_p, &in_left, &out_p, &out_left);
  iconv_close(cd);
  if (rc == static_cast<size_t>(-1)) return false;
  out.resize(out.size() - out_left);
  utf8 = out;
  return true;
}

bool looks_like_dicom(const std::string& file) {
  std::string ext = std::filesystem::path(file).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext == ".dcm" || ext == ".dicom" || is_part10(file);
}

bool safe_for_gdcm(const std::string& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return false;
  std::vector<unsigned char> b((std::istreambuf_iterator<char>(in)), {});
  const long long size = static_cast<long long>(b.size());
  if (size < 132 || std::memcmp(b.data() + 128, "DICM", 4) != 0) {
    // Not Part 10: a raw data set, which GDCM reads in the encoding its first element
    // suggests. It must walk cleanly in that one (a 29-byte file made GDCM allocate 2.4 GB,
    // and a 180-byte one that walks as explicit little endian, read as big endian, 2.8 GB:
    // fuzzing). A File Meta group (0002) without the preamble made GDCM abort (fuzzing).
    if (size >= 2 && b[0] == 0x02 && b[1] == 0x00) return false;
    const std::optional<RawEncoding> encoding = raw_data_set_encoding(b);
    bool ok = true;
    return encoding && walk(b, 0, size, 0, ok, encoding->implicit, false, encoding->big) == size &&
           ok;
  }
  // The File Meta group: (0002,0000) UL 4 <length> first, then group-2 elements that must
  // each be well formed and end inside the group (GDCM 3.0 aborts on an assertion there).
  if (size < 144) return false;
  const unsigned char* m = b.data() + 132;
  if (!(m[0] == 0x02 && m[1] == 0x00 && m[2] == 0x00 && m[3] == 0x00 && m[4] == 'U' && m[5] == 'L'))
    return false;
  const long long meta_end = 144 + static_cast<long long>(u32_at(m + 8));
  if (meta_end > size) return false;
  std::string syntax;
  for (long long at = 144; at < meta_end;) {
    if (at + 8 > meta_end) return false;
    const unsigned char* e = b.data() + at;
    if (e[2] == 0x10 && e[3] == 0x00 &&
        at + 8 + (e[6] | (e[7] << 8)) <= meta_end)  // (0002,0010) Transfer Syntax UID
      syntax.assign(reinterpret_cast<const char*>(e + 8), static_cast<size_t>(e[6] | (e[7] << 8)));
    if (!(e[0] == 0x02 && e[1] == 0x00 && known_vr(e + 4))) return false;
    const std::string vr(reinterpret_cast<const char*>(e + 4), 2);
    const bool long_form = std::any_of(std::begin(kLongVrs), std::end(kLongVrs),
                                       [&](const char* v) { return vr == v; });
    const long long header = long_form ? 12 : 8;
    const long long length =
        long_form ? (at + 12 <= meta_end ? u32_at(e + 8) : -1) : (e[6] | (e[7] << 8));
    if (length < 0 || at + header + length > meta_end) return false;
    at += header + length;
  }
  // The data set: every declared length must fit in the file. GDCM allocates by declared
  // length before reading: a corrupt length cost 1.8 GB per file (found by fuzzing).
  while (!syntax.empty() && (syntax.back() == '\0' || syntax.back() == ' '))
    syntax.pop_back();
  if (syntax == "1.2.840.10008.1.2.1.99") {  // deflated explicit VR: walk it inflated
    std::vector<unsigned char> inflated;
    if (!inflate_raw(b.data() + meta_end, static_cast<size_t>(size - meta_end), inflated))
      return false;
    bool ok = true;
    const long long n = static_cast<long long>(inflated.size());
    return walk(inflated, 0, n, 0, ok, false, false, false) == n && ok;
  }
  bool ok = true;  // explicit big endian (retired) is walked too: GDCM allocated 2.4 GB on one
  const long long end = walk(b, meta_end, size, 0, ok, syntax == "1.2.840.10008.1.2", false,
                             syntax == "1.2.840.10008.1.2.2");
  return ok && end == size;  // a few stray bytes after the last element also made GDCM abort
}

bool native_pixel_data_complete(const std::string& file) {
  std::ifstream in(file, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), {});
  const std::string tag("\xE0\x7F\x10\x00", 4);
  for (size_t at = bytes.find(tag, 132 < bytes.size() ? 132 : 0); at != std::string::npos;
       at = bytes.find(tag, at + 1)) {
    auto u32 = [&](size_t p) {
      return static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[p])) |
             (static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[p + 1])) << 8) |
             (static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[p + 2])) << 16) |
             (static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[p + 3])) << 24);
    };
    if (at + 12 <= bytes.size() &&
        (bytes.compare(at + 4, 2, "OW") == 0 || bytes.compare(at + 4, 2, "OB") == 0)) {
      const std::uint32_t length = u32(at + 8);
      return length == 0xFFFFFFFFu || at + 12 + static_cast<size_t>(length) <= bytes.size();
    }
    if (at + 8 <= bytes.size()) {  // implicit VR: the length follows the tag
      const std::uint32_t length = u32(at + 4);
      return length == 0xFFFFFFFFu || at + 8 + static_cast<size_t>(length) <= bytes.size();
    }
  }
  return true;  // no pixel data element found: GDCM has said what it read
}

}  // namespace organfit::dicom::detail

namespace organfit::dicom {

bool is_part10(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  char head[132] = {};
  in.read(head, sizeof head);
  return in.gcount() == 132 && std::memcmp(head + 128, "DICM", 4) == 0;
}

}  // namespace organfit::dicom
