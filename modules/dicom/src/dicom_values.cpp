#include "dicom_values.h"

#include <gdcmTrace.h>

#include <algorithm>
#include <cctype>
#include <vector>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <string>

#include <cmath>
#include <sstream>

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

bool safe_for_gdcm(const std::string& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return false;
  in.seekg(0, std::ios::end);
  const long long size = in.tellg();
  if (size < 132) return size > 0;  // no preamble: a raw data set, GDCM reads it or refuses
  char head[144] = {};
  in.seekg(0);
  in.read(head, std::min<long long>(size, 144));
  if (std::memcmp(head + 128, "DICM", 4) != 0) return true;  // not Part 10: GDCM tries as raw
  // The first meta element is (0002,0000) UL 4 <length>: the group must fit in the file.
  if (size < 144) return false;
  const auto* b = reinterpret_cast<const unsigned char*>(head + 132);
  if (!(b[0] == 0x02 && b[1] == 0x00 && b[2] == 0x00 && b[3] == 0x00 && b[4] == 'U' && b[5] == 'L')) return true;
  const std::uint32_t group_length = b[8] | (b[9] << 8) | (b[10] << 16) | (static_cast<std::uint32_t>(b[11]) << 24);
  if (144 + static_cast<long long>(group_length) > size) return false;
  // The data set's top-level elements (explicit VR little endian): each declared length
  // must fit in the file. GDCM allocates by declared length before reading: a corrupt
  // length of a gigabyte cost 1.8 GB and seconds per file (found by fuzzing). Checking
  // stops at the first element of undefined length (a sequence: its items are not walked).
  std::vector<char> rest(static_cast<size_t>(size));
  in.clear();
  in.seekg(0);
  in.read(rest.data(), size);
  long long at = 144 + group_length;
  static const char* long_vrs[] = {"OB", "OW", "OF", "SQ", "UT", "UN", "OD", "OL", "UC", "UR", "OV"};
  while (at + 8 <= size) {
    const auto* e = reinterpret_cast<const unsigned char*>(rest.data() + at);
    const std::string vr(reinterpret_cast<const char*>(e + 4), 2);
    if (!(std::isupper(e[4]) && std::isupper(e[5]))) return true;  // implicit VR or not parseable: GDCM decides
    const bool long_form = std::any_of(std::begin(long_vrs), std::end(long_vrs), [&](const char* v) { return vr == v; });
    long long header = 8, length = e[6] | (e[7] << 8);
    if (long_form) {
      if (at + 12 > size) return false;
      header = 12;
      length = e[8] | (e[9] << 8) | (e[10] << 16) | (static_cast<long long>(e[11]) << 24);
      if (length == 0xFFFFFFFFLL) return true;
    }
    if (at + header + length > size) return false;
    at += header + length;
  }
  return true;
}

bool native_pixel_data_complete(const std::string& file) {
  std::ifstream in(file, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), {});
  const std::string tag("\xE0\x7F\x10\x00", 4);
  for (size_t at = bytes.find(tag, 132 < bytes.size() ? 132 : 0); at != std::string::npos; at = bytes.find(tag, at + 1)) {
    auto u32 = [&](size_t p) {
      return static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[p])) |
             (static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[p + 1])) << 8) |
             (static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[p + 2])) << 16) |
             (static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[p + 3])) << 24);
    };
    if (at + 12 <= bytes.size() && (bytes.compare(at + 4, 2, "OW") == 0 || bytes.compare(at + 4, 2, "OB") == 0)) {
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
