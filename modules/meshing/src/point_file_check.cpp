#include "point_file_check.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "organfit/support/error.h"

namespace organfit::meshing::detail {
namespace {

constexpr size_t kMaxHeaderBytes = 1 << 16;

std::string read_all(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw InputError(file.string() + ": cannot be read");
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

/// The header's lines up to and including `last` (its first word), and where the data
/// after it begins; InputError when it has none within 64 KB.
std::vector<std::string> header_lines(const std::string& text, const std::string& file,
                                      const std::string& last, size_t& data_at) {
  std::vector<std::string> lines;
  size_t at = 0;
  while (at < text.size() && at < kMaxHeaderBytes) {
    size_t end = text.find('\n', at);
    if (end == std::string::npos) end = text.size();
    std::string line = text.substr(at, end - at);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    lines.push_back(line);
    at = end + 1;
    std::istringstream words(line);
    std::string first;
    words >> first;
    if (first == last) {
      data_at = std::min(at, text.size());
      return lines;
    }
  }
  throw InputError(file + ": no '" + last + "' line within its first 64 KB: not a whole header");
}

/// Bytes of a PLY scalar type; 0 when unknown.
int ply_type_bytes(const std::string& type) {
  static const std::map<std::string, int> bytes = {
      {"char", 1},   {"int8", 1},    {"uchar", 1},  {"uint8", 1},  {"short", 2}, {"int16", 2},
      {"ushort", 2}, {"uint16", 2},  {"int", 4},    {"int32", 4},  {"uint", 4},  {"uint32", 4},
      {"float", 4},  {"float32", 4}, {"double", 8}, {"float64", 8}};
  const auto it = bytes.find(type);
  return it == bytes.end() ? 0 : it->second;
}

/// Whether `word` is a number whole (as strtod reads it: nan and inf included).
bool is_number(const std::string& word) {
  char* end = nullptr;
  std::strtod(word.c_str(), &end);
  return !word.empty() && end == word.c_str() + word.size();
}

struct PlyElement {
  std::string name;
  long long count = 0;
  int properties = 0;
  long long record_bytes = 0;  // its scalar properties' bytes
  bool has_list = false;
  std::vector<std::string> names;  // its properties'
};

void check_ply(const std::string& text, const std::string& file) {
  size_t data_at = 0;
  const std::vector<std::string> lines = header_lines(text, file, "end_header", data_at);
  std::string format;
  std::vector<PlyElement> elements;
  for (const std::string& line : lines) {
    std::istringstream words(line);
    std::string key;
    words >> key;
    if (key == "format") {
      words >> format;
    } else if (key == "element") {
      PlyElement e;
      if (!(words >> e.name >> e.count) || e.count < 0)
        throw InputError(
            fmt::format("{}: header line '{}' is not 'element NAME COUNT'", file, echo(line)));
      if (e.count > static_cast<long long>(text.size()))  // each takes a byte at least
        throw InputError(fmt::format(
            "{}: its header declares {} {} records, but the file holds {} bytes: cut short or "
            "damaged",
            file, e.count, echo(e.name, 40), text.size()));
      elements.push_back(e);
    } else if (key == "property") {
      if (elements.empty())
        throw InputError(
            fmt::format("{}: header line '{}' comes before any element", file, echo(line)));
      PlyElement& e = elements.back();
      std::string type, name;
      words >> type;
      ++e.properties;
      if (type != "list" && words >> name) {
        if (std::find(e.names.begin(), e.names.end(), name) != e.names.end())
          throw InputError(fmt::format("{}: header: element {} has two properties '{}'", file,
                                       e.name, echo(name, 40)));
        e.names.push_back(name);
      }
      if (type == "list") {
        e.has_list = true;
      } else if (const int b = ply_type_bytes(type); b > 0) {
        e.record_bytes += b;
      } else {
        throw InputError(
            fmt::format("{}: header line '{}': unknown property type", file, echo(line)));
      }
    }
  }
  if (format != "ascii" && format != "binary_little_endian" && format != "binary_big_endian")
    throw InputError(file + ": no 'format ascii|binary_little_endian|binary_big_endian 1.0' line");
  // The elements up to the vertices: those hold what is read. Elements after them (faces)
  // are not read as points.
  long long records = 0, bytes = 0, vertices = -1;
  bool measurable = true;  // no list before or in the vertices: their bytes are known
  size_t vertex_index = elements.size();
  for (size_t k = 0; k < elements.size(); ++k) {
    records += elements[k].count;
    measurable = measurable && !elements[k].has_list;
    bytes += elements[k].count * elements[k].record_bytes;
    if (elements[k].name == "vertex") {
      vertices = elements[k].count, vertex_index = k;
      break;
    }
  }
  if (vertices < 0) throw InputError(file + ": its header declares no 'element vertex'");
  for (const char* axis : {"x", "y", "z"})
    if (const auto& names = elements[vertex_index].names;
        std::find(names.begin(), names.end(), axis) == names.end())
      throw InputError(fmt::format("{}: header: its vertices have no '{}' property", file, axis));
  const size_t data_bytes = text.size() - data_at;
  if (format != "ascii") {
    // Exactly its bytes when the vertices are the last element: more is as damaged as less.
    const bool last = vertex_index + 1 == elements.size();
    if (measurable && (static_cast<long long>(data_bytes) < bytes ||
                       (last && static_cast<long long>(data_bytes) > bytes)))
      throw InputError(fmt::format(
          "{}: its header declares {} vertices ({} bytes of data), but the file holds {} bytes "
          "after its header: {}",
          file, vertices, bytes, data_bytes,
          static_cast<long long>(data_bytes) < bytes ? "cut short or damaged" : "damaged"));
    return;
  }
  // ASCII: one line a record; a vertex line holds one value a property.
  const PlyElement& vertex = elements[vertex_index];
  const long long first_vertex = records - vertices;  // the records before it: other elements
  long long line_number = static_cast<long long>(lines.size()), record = 0;
  std::istringstream data(text.substr(data_at));
  std::string line;
  while (record < records && std::getline(data, line)) {
    ++line_number;
    std::istringstream words(line);
    long long values = 0;
    for (std::string w; words >> w; ++values)
      if (record >= first_vertex && !is_number(w))
        throw InputError(
            fmt::format("{}:{}: '{}' is not a number: damaged", file, line_number, echo(w, 40)));
    if (values == 0) continue;  // a blank line
    if (record >= first_vertex && !vertex.has_list && values != vertex.properties)
      throw InputError(fmt::format(
          "{}:{}: vertex {} has {} values where the header declares {} properties: damaged", file,
          line_number, record - first_vertex + 1, values, vertex.properties));
    ++record;
  }
  if (record == records && vertex_index + 1 == elements.size())
    while (std::getline(data, line)) {
      ++line_number;
      if (line.find_first_not_of(" \t\r") != std::string::npos)
        throw InputError(
            fmt::format("{}:{}: data beyond the {} vertices its header declares: damaged", file,
                        line_number, vertices));
    }
  if (record < records)
    throw InputError(fmt::format(
        "{}: its header declares {} vertices, but the file holds {}: cut short or damaged", file,
        vertices, std::max(0LL, record - first_vertex)));
}

void check_legacy_vtk(const std::string& text, const std::string& file) {
  size_t data_at = 0;
  const std::vector<std::string> lines = header_lines(text, file, "POINTS", data_at);
  bool binary = false;
  for (const std::string& line : lines)
    binary = binary || line.rfind("BINARY", 0) == 0;
  std::istringstream points(lines.back());
  std::string key, type;
  long long n = -1;
  if (!(points >> key >> n >> type) || n < 0)
    throw InputError(fmt::format("{}: '{}' is not 'POINTS n type'", file, echo(lines.back())));
  if (n > static_cast<long long>(text.size()))  // 3 values a point, a byte each at least
    throw InputError(fmt::format(
        "{}: POINTS declares {} points, but the file holds {} bytes: cut short or damaged", file, n,
        text.size()));
  if (binary) {
    static const std::map<std::string, int> bytes = {{"float", 4}, {"double", 8}};
    const auto it = bytes.find(type);
    if (it != bytes.end() && static_cast<long long>(text.size() - data_at) < 3 * n * it->second)
      throw InputError(fmt::format(
          "{}: POINTS declares {} points ({} bytes), but the file holds {} bytes after it: cut "
          "short or damaged",
          file, n, 3 * n * it->second, text.size() - data_at));
    return;
  }
  // ASCII: 3 n numbers (VTK's reader stops at the first that is not one, the rest left 0).
  long long values = 0;
  std::istringstream data(text.substr(data_at));
  for (std::string w; values < 3 * n && data >> w; ++values)
    if (!is_number(w)) {
      if (std::isalpha(static_cast<unsigned char>(w[0])) &&
          std::isupper(static_cast<unsigned char>(w[0])))
        break;  // the next section's keyword: the points end short of n
      throw InputError(fmt::format("{}: point value {} of {}, '{}', is not a number: damaged", file,
                                   values + 1, 3 * n, echo(w, 40)));
    }
  if (std::string w; values == 3 * n && data >> w &&
                     !(std::isalpha(static_cast<unsigned char>(w[0])) &&
                       std::isupper(static_cast<unsigned char>(w[0]))))
    throw InputError(fmt::format("{}: values beyond the {} points POINTS declares ('{}'): damaged",
                                 file, n, echo(w, 40)));
  if (values < 3 * n)
    throw InputError(fmt::format(
        "{}: POINTS declares {} points ({} values), but the file holds {} values: cut short or "
        "damaged",
        file, n, 3 * n, values));
}

}  // namespace

void check_point_file_complete(const std::filesystem::path& file) {
  const std::string ext = file.extension().string();
  if (ext != ".ply" && ext != ".vtk") return;
  const std::string text = read_all(file);
  if (ext == ".ply") {
    if (text.rfind("ply", 0) != 0)
      throw InputError(file.string() + ": not a PLY file (no 'ply' first)");
    check_ply(text, file.string());
  } else {
    check_legacy_vtk(text, file.string());
  }
}

}  // namespace organfit::meshing::detail
