#include "organfit/pipeline/points_file.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <initializer_list>
#include <iterator>
#include <limits>
#include <string>

#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::pipeline {
namespace {

constexpr size_t kMaxFileBytes = size_t{64} << 20;  // 100,000 points take about 4 MB

void append_utf8(std::string& out, char32_t c) {
  if (c < 0x80) {
    out += static_cast<char>(c);
  } else if (c < 0x800) {
    out += static_cast<char>(0xC0 | (c >> 6));
    out += static_cast<char>(0x80 | (c & 0x3F));
  } else if (c < 0x10000) {
    out += static_cast<char>(0xE0 | (c >> 12));
    out += static_cast<char>(0x80 | ((c >> 6) & 0x3F));
    out += static_cast<char>(0x80 | (c & 0x3F));
  } else {
    out += static_cast<char>(0xF0 | (c >> 18));
    out += static_cast<char>(0x80 | ((c >> 12) & 0x3F));
    out += static_cast<char>(0x80 | ((c >> 6) & 0x3F));
    out += static_cast<char>(0x80 | (c & 0x3F));
  }
}

/// The file's text as UTF-8: a UTF-8 mark dropped, UTF-16 (by its mark, or by the zero
/// bytes of ASCII text without one) converted. Empty optional: not text.
bool decode(const std::string& bytes, std::string& text) {
  auto u8 = [&](size_t i) { return static_cast<unsigned char>(bytes[i]); };
  const size_t n = bytes.size();
  int utf16 = 0;  // 1 little endian, 2 big endian
  size_t start = 0;
  if (n >= 3 && u8(0) == 0xEF && u8(1) == 0xBB && u8(2) == 0xBF) {
    start = 3;
  } else if (n >= 2 && u8(0) == 0xFF && u8(1) == 0xFE) {
    utf16 = 1, start = 2;
  } else if (n >= 2 && u8(0) == 0xFE && u8(1) == 0xFF) {
    utf16 = 2, start = 2;
  } else if (n >= 4 && n % 2 == 0 && u8(0) != 0 && u8(1) == 0 && u8(2) != 0 && u8(3) == 0) {
    utf16 = 1;
  } else if (n >= 4 && n % 2 == 0 && u8(0) == 0 && u8(1) != 0 && u8(2) == 0 && u8(3) != 0) {
    utf16 = 2;
  }
  if (!utf16) {
    text = bytes.substr(start);
    return text.find('\0') == std::string::npos;  // NUL bytes: a binary file
  }
  if ((n - start) % 2 != 0) return false;
  text.clear();
  for (size_t i = start; i + 1 < n; i += 2) {
    char32_t unit = utf16 == 1 ? u8(i) | (u8(i + 1) << 8) : (u8(i) << 8) | u8(i + 1);
    if (unit >= 0xD800 && unit < 0xDC00 && i + 3 < n) {  // a surrogate pair
      const char32_t low = utf16 == 1 ? u8(i + 2) | (u8(i + 3) << 8) : (u8(i + 2) << 8) | u8(i + 3);
      if (low < 0xDC00 || low > 0xDFFF) return false;
      unit = 0x10000 + ((unit - 0xD800) << 10) + (low - 0xDC00);
      i += 2;
    } else if (unit >= 0xD800 && unit <= 0xDFFF) {
      return false;
    }
    if (unit == 0) return false;
    append_utf8(text, unit);
  }
  return true;
}

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\"'");
  const auto e = s.find_last_not_of(" \t\"'");
  return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
}

/// A line's cells: split at ';' (then ',' is a decimal comma), else at tabs (likewise),
/// else at ',', else at runs of spaces.
std::vector<std::string> cells_of(const std::string& line) {
  std::vector<std::string> cells;
  char sep = ' ';
  bool decimal_comma = false;
  if (line.find(';') != std::string::npos) {
    sep = ';', decimal_comma = true;
  } else if (line.find('\t') != std::string::npos) {
    sep = '\t', decimal_comma = true;
  } else if (line.find(',') != std::string::npos) {
    sep = ',';
  }
  std::string cell;
  auto push = [&]() {
    std::string c = trim(cell);
    if (decimal_comma && c.find(',') != std::string::npos && c.find('.') == std::string::npos)
      for (auto& ch : c)
        if (ch == ',') ch = '.';
    if (sep != ' ' || !c.empty()) cells.push_back(c);
    cell.clear();
  };
  for (char ch : line) {
    if (ch == sep || (sep == ' ' && ch == '\t')) {
      push();
    } else {
      cell += ch;
    }
  }
  push();
  // A trailing separator (as some spreadsheets write) adds no column.
  if (sep != ' ' && cells.size() > 1 && cells.back().empty()) cells.pop_back();
  return cells;
}

/// The whole cell as a number (locale-independent), or false.
bool parse_number(const std::string& cell, double& v) {
  if (cell.empty()) return false;
  const char* b = cell.data();
  const char* e = b + cell.size();
  if (*b == '+') ++b;
  const auto [end, ec] = std::from_chars(b, e, v);
  if (ec == std::errc::result_out_of_range) {
    v = std::numeric_limits<double>::infinity();
    return end == e;
  }
  return ec == std::errc() && end == e;
}

/// The file's text, decoded (InputError naming it when it cannot be).
std::string text_of(const fs::path& file) {
  const std::string name = file.string();
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) throw InputError(name + ": not a regular file");
  if (fs::file_size(file, ec) > kMaxFileBytes)
    throw InputError(fmt::format("{}: larger than {} MiB: not a points file of at most {} points",
                                 name, kMaxFileBytes >> 20, kMaxPointsInFile));
  std::ifstream in(file, std::ios::binary);
  if (!in) throw InputError(name + ": cannot read the points file");
  const std::string bytes((std::istreambuf_iterator<char>(in)), {});
  std::string text;
  if (!decode(bytes, text))
    throw InputError(name + ": not a text file (neither UTF-8 nor UTF-16 text)");
  return text;
}

/// A comment line "# key: value" that declares the table's CT, taken into `ct`.
void take_declaration(const std::string& comment, PointsCt& ct) {
  const auto colon = comment.find(':');
  if (colon == std::string::npos) return;
  const std::string key = trim(comment.substr(0, colon));
  const std::string value = trim(comment.substr(colon + 1));
  if (key == "series_instance_uid") ct.series_instance_uid = value;
  if (key == "frame_of_reference_uid") ct.frame_of_reference_uid = value;
}

}  // namespace

std::string points_ct_comment(const PointsCt& ct) {
  std::string out;
  if (!ct.series_instance_uid.empty())
    out += "# series_instance_uid: " + ct.series_instance_uid + "\n";
  if (!ct.frame_of_reference_uid.empty())
    out += "# frame_of_reference_uid: " + ct.frame_of_reference_uid + "\n";
  return out;
}

namespace {
/// A column name's words: its runs of letters, lower-cased ("X (cm)": x, cm; "pos_x_metres":
/// pos, x, metres), each with whether a digit follows it ("m1": a marker's number).
struct Word {
  std::string text;
  bool numbered = false;
};
std::vector<Word> words_of(const std::string& cell) {
  std::vector<Word> words;
  std::string word;
  for (const char ch : cell + " ") {
    if (std::isalpha(static_cast<unsigned char>(ch))) {
      word += static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    } else if (!word.empty()) {
      words.push_back({word, std::isdigit(static_cast<unsigned char>(ch)) != 0});
      word.clear();
    }
  }
  return words;
}

/// What a header line's coordinate column names say of its unit and frame: nothing, or why
/// the points are not in mm LPS. A column names a unit by a word of its own (words_of), so
/// "x", "xmm" or "index" name none; nor does a word a digit follows ("m1": a marker's
/// number, not metres).
std::string header_mismatch(const std::vector<std::string>& cells) {
  std::vector<std::vector<std::string>> words(std::min<size_t>(cells.size(), 3));  // per column
  std::vector<std::string> unit_words;
  for (size_t c = 0; c < words.size(); ++c)
    for (const Word& w : words_of(cells[c])) {
      words[c].push_back(w.text);
      if (!w.numbered) unit_words.push_back(w.text);
    }
  auto said = [&](std::initializer_list<const char*> any) {
    for (const std::string& w : unit_words)
      for (const char* a : any)
        if (w == a) return true;
    return false;
  };
  // The three columns' first words when each is one letter ("S (mm),P,L": "spl"), else "".
  std::string letters;
  for (const auto& column : words)
    if (!column.empty() && column[0].size() == 1) letters += column[0];
  if (letters.size() != 3) letters.clear();
  if (said({"cm", "centimeter", "centimeters", "centimetre", "centimetres"}))
    return "its columns are named in centimetres";
  if (said({"m", "meter", "meters", "metre", "metres"})) return "its columns are named in metres";
  if (said({"inch", "inches"})) return "its columns are named in inches";
  if (said({"ras"}) || letters == "ras")
    return "its columns are named in RAS (as 3D Slicer's are): x and y point the other way";
  if (letters == "ijk") return "its columns are named i, j, k: voxel indices, not positions";
  // The axes named in another order (z, y, x): read as x, y, z they would be swapped.
  for (const std::string axes : {"xyz", "lps"})
    if (!letters.empty() && letters != axes &&
        std::is_permutation(letters.begin(), letters.end(), axes.begin(), axes.end()))
      return fmt::format("its columns are named {}, {}, {}: they are read as {}, {}, {}",
                         letters[0], letters[1], letters[2], axes[0], axes[1], axes[2]);
  return "";
}

/// 3D Slicer's markups table (.fcsv) declares its columns and frame in comment lines:
/// "# columns = id,x,y,z,ow,..." and "# CoordinateSystem = LPS" (or RAS; Slicer 4 wrote 0
/// for RAS, 1 for LPS). Its rows hold text (an id, a label) beside the numbers.
struct DeclaredColumns {
  int x = -1, y = -1, z = -1;  ///< the coordinates' columns; -1: no columns declared
  int confidence = -1;         ///< the confidence's column; -1: none
  bool ras = false;            ///< x and y point the other way: negated into LPS
  bool declared() const { return x >= 0; }
  /// A row's cells in the named columns' order: x, y, z, and the confidence when asked and
  /// named (the row holds them all).
  std::vector<std::string> taken(const std::vector<std::string>& cells,
                                 bool with_confidence) const {
    std::vector<std::string> out = {cells[static_cast<size_t>(x)], cells[static_cast<size_t>(y)],
                                    cells[static_cast<size_t>(z)]};
    if (with_confidence && confidence >= 0) out.push_back(cells[static_cast<size_t>(confidence)]);
    return out;
  }
};

/// A header line's columns by name, when it names x, y and z (a column's first word,
/// words_of: "x", "X (mm)", "x_mm") other than first, second and third
/// ("id,x,y,z", "z,y,x"): those, and a column named "confidence". Otherwise none: the first
/// three columns are x, y, z and a fourth the confidence, as for a table without a header.
DeclaredColumns columns_named(const std::vector<std::string>& cells) {
  DeclaredColumns d;
  for (size_t c = 0; c < cells.size(); ++c) {
    const std::vector<Word> words = words_of(cells[c]);
    const std::string word = words.empty() ? "" : words.front().text;
    const int at = static_cast<int>(c);
    if (word == "x" && d.x < 0) d.x = at;
    if (word == "y" && d.y < 0) d.y = at;
    if (word == "z" && d.z < 0) d.z = at;
    if (word == "confidence" && d.confidence < 0) d.confidence = at;
  }
  if (d.x < 0 || d.y < 0 || d.z < 0 || (d.x == 0 && d.y == 1 && d.z == 2)) return {};
  return d;
}

/// Takes a "# key = value" comment line into `d`; returns why it cannot be read, or "".
std::string take_slicer_declaration(const std::string& comment, DeclaredColumns& d) {
  const auto equals = comment.find('=');
  if (equals == std::string::npos) return "";
  const std::string key = trim(comment.substr(0, equals));
  const std::string value = trim(comment.substr(equals + 1));
  if (key == "CoordinateSystem") {
    if (value == "LPS" || value == "1") {
      d.ras = false;
    } else if (value == "RAS" || value == "0") {
      d.ras = true;
    } else {
      return fmt::format("CoordinateSystem '{}': LPS or RAS expected", echo(value));
    }
  } else if (key == "columns") {
    const std::vector<std::string> names = cells_of(value);
    for (size_t c = 0; c < names.size(); ++c) {
      const std::string n = trim(names[c]);
      const int at = static_cast<int>(c);
      if (n == "x") d.x = at;
      if (n == "y") d.y = at;
      if (n == "z") d.z = at;
    }
    if (d.x < 0 || d.y < 0 || d.z < 0)
      return "its declared columns name no x, y and z: " + echo(value);
  }
  return "";
}

}  // namespace

std::vector<fitting::AttractivePoint> read_points_csv(const fs::path& file) {
  return read_points_table(file).points;
}

PointsTable read_points_table(const fs::path& file) {
  const std::string name = file.string();
  const std::string text = text_of(file);

  PointsTable table;
  std::vector<fitting::AttractivePoint>& points = table.points;
  int line_no = 0;
  bool header_seen = false;
  DeclaredColumns declared;
  size_t at = 0;
  while (at <= text.size()) {
    size_t end = text.find_first_of("\r\n", at);
    if (end == std::string::npos) end = text.size();
    const std::string line = text.substr(at, end - at);
    at = end + ((end + 1 < text.size() && text[end] == '\r' && text[end + 1] == '\n') ? 2 : 1);
    ++line_no;
    auto fail = [&](const std::string& why) {
      throw InputError(fmt::format("{}:{}: {}", name, line_no, why));
    };
    const auto first = line.find_first_not_of(" \t");
    if (first == std::string::npos) continue;
    if (line[first] == '#') {
      take_declaration(line.substr(first + 1), table.ct);
      if (const std::string why = take_slicer_declaration(line.substr(first + 1), declared);
          !why.empty())
        fail(why);
      continue;
    }
    std::vector<std::string> cells = cells_of(line);
    if (declared.declared()) {  // the named columns alone: x, y, z[, confidence]
      const int last = std::max({declared.x, declared.y, declared.z, declared.confidence});
      if (static_cast<int>(cells.size()) <= last)
        fail(fmt::format("{} columns where its named columns need {}", cells.size(), last + 1));
      cells = declared.taken(cells, true);
    }
    std::vector<double> v;
    for (const auto& c : cells) {
      double d = 0;
      if (!parse_number(c, d)) {
        // One line of column names may come before the first point; what it says of the
        // unit and frame is not ignored.
        // (Not where its columns were declared: a row there is a row.)
        if (points.empty() && v.empty() && !header_seen && !declared.declared()) {
          // Its coordinate columns: those it names x, y, z, or its first three.
          DeclaredColumns named = columns_named(cells);
          const std::string mismatch =
              header_mismatch(named.declared() ? named.taken(cells, false) : cells);
          if (!mismatch.empty())
            fail(mismatch +
                 "; points are read in mm, in the planning CT's patient coordinates "
                 "(LPS)");
          named.ras = declared.ras;  // a "# CoordinateSystem" comment before it
          declared = named;
          break;
        }
        fail(fmt::format("'{}' is not a number", echo(c)));
      }
      if (!std::isfinite(d)) fail("non-finite coordinate");
      v.push_back(d);
    }
    if (v.empty()) {
      header_seen = true;
      continue;
    }
    if (v.size() != 3 && v.size() != 4)
      fail(fmt::format("expected x,y,z[,confidence], got {} columns", v.size()));
    for (int c = 0; c < 3; ++c)
      if (std::abs(v[c]) > kMaxCoordinateMm)
        fail(
            fmt::format("coordinate {:g} mm lies beyond 10 m: no patient is there (mm are "
                        "expected; metres or another column?)",
                        v[c]));
    if (v.size() == 4 && !(v[3] > 0 && v[3] <= 1)) fail("confidence must be in (0, 1]");
    if (static_cast<long>(points.size()) == kMaxPointsInFile)
      throw InputError(fmt::format("{}: more than {} points (the most a points file may hold)",
                                   name, kMaxPointsInFile));
    if (declared.ras) v[0] = -v[0], v[1] = -v[1];  // into LPS
    points.push_back({Eigen::Vector3d(v[0], v[1], v[2]), v.size() == 4 ? v[3] : 1.0});
  }
  if (points.empty()) throw InputError(name + ": no points in the file");
  return table;
}

}  // namespace organfit::pipeline
