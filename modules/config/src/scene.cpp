#include "organfit/config/scene.h"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <sstream>

#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::config {
namespace {

/// Levenshtein distance, for "did you mean" on misspelled keys.
size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<size_t> prev(b.size() + 1), cur(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j)
    prev[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (size_t j = 1; j <= b.size(); ++j) {
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (a[i - 1] != b[j - 1])});
    }
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

std::string suggestion(const std::string& given, const std::vector<std::string>& known) {
  std::string best;
  size_t best_d = std::max<size_t>(2, given.size() / 3) + 1;
  for (const auto& k : known) {
    const size_t d = edit_distance(given, k);
    if (d < best_d) best_d = d, best = k;
  }
  return best.empty() ? "" : fmt::format(" (did you mean '{}'?)", best);
}

class Parser {
 public:
  Parser(fs::path file, const Schema& schema) : file_(std::move(file)), schema_(schema) {}

  /// Keys given by --set, with the text that gave them (for messages).
  std::map<std::string, std::string> overrides;

  [[noreturn]] void fail(int line0, const std::string& key, const std::string& reason) const {
    if (const auto it = overrides.find(key); it != overrides.end())
      throw InputError(fmt::format("--set {}: {}", echo(it->second), reason));
    throw InputError(fmt::format("{}:{}: {}{}{}", file_.string(), line0 + 1, echo(key),
                                 key.empty() ? "" : ": ", reason));
  }

  Value convert(const ParamSpec& spec, const YAML::Node& node) const {
    const int line = node.Mark().line;
    const std::string key = spec.key();
    auto scalar_text = [&]() -> std::string {
      if (!node.IsScalar())
        fail(line, key,
             fmt::format("expected a {}, got a {}", to_string(spec.type),
                         node.IsSequence() ? "list" : "mapping"));
      return node.Scalar();
    };
    auto as_number = [&](const YAML::Node& n, const std::string& what) -> double {
      double v = 0;
      if (!n.IsScalar() || !YAML::convert<double>::decode(n, v)) {
        fail(n.Mark().line, key,
             fmt::format("expected {}, got '{}'", what,
                         n.IsScalar() ? echo(n.Scalar()) : std::string("a list")));
      }
      if (!std::isfinite(v))
        fail(n.Mark().line, key, fmt::format("must be finite, got '{}'", echo(n.Scalar())));
      return v;
    };
    auto check_range = [&](double v, int at) {
      if ((spec.min && (spec.min_exclusive ? !(v > *spec.min) : !(v >= *spec.min))) ||
          (spec.max && !(v <= *spec.max))) {
        fail(at, key,
             fmt::format("{} is out of range {}{}", value_to_text(Value(v)), spec.range_text(),
                         spec.unit.empty() ? "" : " " + spec.unit));
      }
    };
    switch (spec.type) {
      case ParamType::kNumber: {
        const double v = as_number(node, "a number");
        check_range(v, line);
        return v;
      }
      case ParamType::kInteger: {
        const std::string s = scalar_text();
        long long v = 0;
        if (!YAML::convert<long long>::decode(node, v)) {
          fail(line, key, fmt::format("expected an integer, got '{}'", echo(s)));
        }
        check_range(static_cast<double>(v), line);
        return v;
      }
      case ParamType::kBool: {
        const std::string s = scalar_text();
        bool v = false;
        if (!YAML::convert<bool>::decode(node, v)) {
          fail(line, key, fmt::format("expected true or false, got '{}'", echo(s)));
        }
        return v;
      }
      case ParamType::kString:
        return scalar_text();
      case ParamType::kEnum: {
        const std::string s = scalar_text();
        if (std::find(spec.choices.begin(), spec.choices.end(), s) == spec.choices.end()) {
          fail(line, key,
               fmt::format("'{}' is not one of {}{}", echo(s), spec.range_text(),
                           suggestion(s, spec.choices)));
        }
        return s;
      }
      case ParamType::kInputPath: {
        const std::string s = scalar_text();
        if (s.empty()) fail(line, key, "empty path");
        fs::path p(s);
        // A path on the command line is the user's, from where they are.
        if (p.is_relative())
          p = (overrides.count(key) ? fs::current_path() : file_.parent_path()) / p;
        std::error_code ec;  // a name too long or a folder not searchable: the user's to fix
        const bool exists = fs::exists(p, ec);
        if (ec) fail(line, key, fmt::format("{}: {}", ec.message(), echo(p.string(), 200)));
        if (!exists)
          fail(line, key, fmt::format("no such file or folder: {}", echo(p.string(), 200)));
        return fs::absolute(p).lexically_normal().string();
      }
      case ParamType::kVec3: {
        if (!node.IsSequence() || node.size() != 3) {
          fail(line, key, "expected three numbers [x, y, z]");
        }
        Eigen::Vector3d v;
        for (int i = 0; i < 3; ++i) {
          v[i] = as_number(node[i], "a number");
          check_range(v[i], node[i].Mark().line);
        }
        return v;
      }
      case ParamType::kMatrix4: {
        // 16 numbers, or four rows of four.
        std::vector<YAML::Node> flat;
        if (node.IsSequence() && node.size() == 4 && node[0].IsSequence()) {
          for (const auto& row : node) {
            if (!row.IsSequence() || row.size() != 4)
              fail(line, key, "expected four rows of four numbers");
            for (const auto& x : row)
              flat.push_back(x);
          }
        } else if (node.IsSequence() && node.size() == 16) {
          for (const auto& x : node)
            flat.push_back(x);
        } else {
          fail(line, key, "expected a 4x4 matrix: 16 numbers row by row, or four rows of four");
        }
        Eigen::Matrix4d m;
        for (int i = 0; i < 16; ++i)
          m(i / 4, i % 4) = as_number(flat[static_cast<size_t>(i)], "a number");
        return m;
      }
    }
    fail(line, key, "unsupported type");
  }

  fs::path file_;
  const Schema& schema_;
};

/// The names a misspelled section is compared with: the top-level ones, or all
/// ("fit.paper") for --set.
std::vector<std::string> section_names(const Schema& schema, bool top_level_only = false) {
  std::vector<std::string> out;
  for (const auto& s : schema.sections())
    if (!top_level_only || s.depth() == 0) out.push_back(s.name);
  return out;
}

/// An unknown key's hint: the nearest key or sub-section of its own section, else the
/// same key in another section of the same stage (a key given one level too high or in
/// the other method's sub-section: "fit.alpha" is "fit.paper.alpha").
std::string key_hint(const Schema& schema, const std::string& section, const std::string& name) {
  std::vector<std::string> known;
  for (const auto* p : schema.params_of(section))
    known.push_back(p->name);
  for (const auto* sub : schema.subsections_of(section))
    known.push_back(sub->leaf());
  const std::string near = suggestion(name, known);
  if (!near.empty()) return near;
  const std::string stage = section.substr(0, section.find('.'));
  for (const auto& p : schema.params())
    if (p.name == name && p.section != section && p.section.substr(0, p.section.find('.')) == stage)
      return fmt::format(" (did you mean '{}'?)", p.key());
  return "";
}

/// The first line (from 0) whose indentation holds a tab, or -1.
int first_tab_indented_line(const std::string& text) {
  int line = 0;
  for (size_t start = 0; start < text.size(); ++line) {
    const size_t end = std::min(text.find('\n', start), text.size());
    const size_t content = text.find_first_not_of(" \t\r", start);
    if (content != std::string::npos && content < end && text.find('\t', start) < content)
      return line;
    start = end + 1;
  }
  return -1;
}

}  // namespace

Scene parse_scene(const std::string& text, const fs::path& file, const Schema& schema,
                  const std::vector<std::string>& overrides) {
  Parser parser(file, schema);
  YAML::Node root;
  try {
    // One document: a second one (after a '---') would be read by nobody.
    const std::vector<YAML::Node> documents = YAML::LoadAll(text);
    if (!documents.empty()) root = documents.front();
    for (size_t d = 1; d < documents.size(); ++d)
      if (documents[d] && !documents[d].IsNull())
        parser.fail(documents[d].Mark().line, "",
                    "a second YAML document: a scene file holds one, and the run would ignore "
                    "this one");
  } catch (const YAML::Exception& e) {
    const int line = std::max(0, e.mark.line);
    // A tab in a line's indentation is the error editors that insert tabs make, and
    // yaml-cpp reports it as what follows ("illegal map value"): name the tab.
    if (const int tab = first_tab_indented_line(text); tab >= 0 && tab <= line + 1)
      parser.fail(tab, "",
                  "YAML syntax error: this line is indented with a tab (YAML indents with spaces)");
    parser.fail(line, "", "YAML syntax error: " + e.msg);
  }
  if ((!root || root.IsNull()) && overrides.empty()) parser.fail(0, "", "the scene is empty");
  if (!root || root.IsNull()) root = YAML::Node(YAML::NodeType::Map);
  if (!root.IsMap()) parser.fail(root.Mark().line, "", "a scene is a mapping of sections");
  // --set section.key=value: into the tree before validation, which then names --set.
  for (const auto& o : overrides) {
    auto refuse = [&](const std::string& why) {
      throw InputError(fmt::format("--set {}: {}", echo(o), why));
    };
    const auto eq = o.find('=');
    const std::string key = o.substr(0, eq);
    const auto dot = key.rfind('.');
    if (eq == std::string::npos || dot == std::string::npos || dot == 0 || dot + 1 == key.size())
      refuse("expected section.key=value");
    const std::string sec = key.substr(0, dot), name = key.substr(dot + 1);
    if (!schema.find_section(sec))
      refuse("unknown section" + suggestion(sec, section_names(schema)));
    if (!schema.find(sec, name)) refuse("unknown key" + key_hint(schema, sec, name));
    if (parser.overrides.count(key)) refuse("the key is set twice");
    YAML::Node value;
    try {
      value = YAML::Load(o.substr(eq + 1));
    } catch (const YAML::Exception& e) {
      refuse("YAML syntax error: " + e.msg);
    }
    if (!value || value.IsNull()) refuse("no value");
    // Down the section's path ("fit.paper": root[fit][paper]), making what is missing.
    YAML::Node at = root;
    std::string path;
    for (size_t start = 0; start <= sec.size();) {
      const size_t end = std::min(sec.find('.', start), sec.size());
      const std::string part = sec.substr(start, end - start);
      path += (path.empty() ? "" : ".") + part;
      if (!at[part] || at[part].IsNull()) at[part] = YAML::Node(YAML::NodeType::Map);
      if (!at[part].IsMap())
        parser.fail(at[part].Mark().line, path, "a section is a mapping of keys");
      at.reset(at[part]);
      start = end + 1;
    }
    at[name] = value;
    parser.overrides[key] = o;
  }

  Scene scene;
  scene.file_ = file;
  scene.schema_ = &schema;
  // One section's body: its keys, its sub-sections (given or not), their defaults.
  std::function<void(const std::string&, const YAML::Node*, int)> read_section =
      [&](const std::string& sec, const YAML::Node* body, int sec_line) {
        if (scene.sections_.count(sec)) parser.fail(sec_line, sec, "section given twice");
        scene.sections_.insert(sec);
        scene.section_lines_[sec] = sec_line + 1;
        if (body && !body->IsNull() && !body->IsMap())
          parser.fail(body->Mark().line, sec, "a section is a mapping of keys");
        std::set<std::string> given_subsections;
        if (body && body->IsMap()) {
          for (const auto& item : *body) {
            const std::string name = item.first.Scalar();
            const int line = item.first.Mark().line;
            if (schema.find_section(sec + "." + name)) {
              given_subsections.insert(sec + "." + name);
              scene.given_sections_.insert(sec + "." + name);
              read_section(sec + "." + name, &item.second, line);
              continue;
            }
            const ParamSpec* spec = schema.find(sec, name);
            if (!spec) {
              parser.fail(line, sec + "." + name, "unknown key" + key_hint(schema, sec, name));
            }
            if (scene.entries_.count(spec->key()))
              parser.fail(line, spec->key(), "key given twice");
            const auto set = parser.overrides.find(spec->key());
            scene.entries_[spec->key()] = {parser.convert(*spec, item.second), line + 1, true,
                                           set == parser.overrides.end() ? "" : set->second};
          }
        }
        for (const auto* p : schema.params_of(sec)) {
          if (scene.entries_.count(p->key())) continue;
          if (p->required()) parser.fail(sec_line, p->key(), "required key is missing");
          scene.entries_[p->key()] = {p->default_value, sec_line + 1, false, {}};
        }
        // A sub-section not written takes its defaults, placed at its parent's line.
        for (const auto* sub : schema.subsections_of(sec))
          if (!given_subsections.count(sub->name)) read_section(sub->name, nullptr, sec_line);
      };
  for (const auto& kv : root) {
    const std::string sec = kv.first.Scalar();
    const int sec_line = kv.first.Mark().line;
    const SectionSpec* spec = schema.find_section(sec);
    if (!spec || spec->depth() > 0) {
      parser.fail(sec_line, sec, "unknown section" + suggestion(sec, section_names(schema, true)));
    }
    scene.given_sections_.insert(sec);
    read_section(sec, &kv.second, sec_line);
  }
  for (const auto& sec : schema.sections()) {
    if (!sec.always_present || sec.depth() > 0 || scene.sections_.count(sec.name)) continue;
    read_section(sec.name, nullptr, 0);
    scene.section_lines_[sec.name] = 1;
  }
  // A key (or a sub-section) the run would ignore is refused: its value would silently
  // not be what ran.
  auto refuse_ignored = [&](const std::string& key, int line0, const UseCondition& failed,
                            const std::string& used_with) {
    const auto it = scene.entries_.find(failed.key);
    const std::string value =
        it == scene.entries_.end() ? std::string() : value_to_text(it->second.value);
    parser.fail(line0, key,
                fmt::format("not used when {}: the run would ignore it (it is used with {})",
                            it != scene.entries_.end()
                                ? failed.key + " is '" + echo(value) + "'"
                                : "the scene has no '" +
                                      failed.key.substr(0, failed.key.rfind('.')) + "' section",
                            used_with));
  };
  for (const auto& [key, entry] : scene.entries_) {
    if (!entry.given) continue;
    const ParamSpec* spec = schema.find_key(key);
    if (!spec) continue;
    if (const UseCondition* failed = scene.unmet_condition(*spec))
      refuse_ignored(key, entry.line - 1, *failed, scene.used_when_text(*spec));
  }
  for (const auto& sec : scene.given_sections_) {
    const SectionSpec* spec = schema.find_section(sec);
    if (const UseCondition* failed = scene.unmet_section_condition(sec))
      refuse_ignored(sec, scene.section_lines_.at(sec) - 1, *failed, scene.used_when_text(*spec));
  }
  return scene;
}

Scene load_scene(const fs::path& file, const Schema& schema,
                 const std::vector<std::string>& overrides) {
  std::error_code ec;
  if (fs::is_directory(file, ec))
    throw InputError(file.string() + ": is a folder, not a scene file");
  std::ifstream in(file);
  if (!in) throw InputError(file.string() + ": cannot read the scene file");
  std::stringstream ss;
  ss << in.rdbuf();
  return parse_scene(ss.str(), file, schema, overrides);
}

bool Scene::is_given(const std::string& section, const std::string& name) const {
  auto it = entries_.find(section + "." + name);
  return it != entries_.end() && it->second.given;
}

const Scene::Entry& Scene::entry(const std::string& section, const std::string& name,
                                 ParamType type) const {
  const ParamSpec* spec = schema_->find(section, name);
  if (!spec || spec->type != type) {
    throw std::logic_error(
        fmt::format("scene key {}.{} is not declared as {}", section, name, to_string(type)));
  }
  auto it = entries_.find(spec->key());
  if (it == entries_.end()) {
    throw std::logic_error(fmt::format("scene key {}.{} read but section absent", section, name));
  }
  return it->second;
}

double Scene::number(const std::string& s, const std::string& n) const {
  return std::get<double>(entry(s, n, ParamType::kNumber).value);
}
long long Scene::integer(const std::string& s, const std::string& n) const {
  return std::get<long long>(entry(s, n, ParamType::kInteger).value);
}
bool Scene::flag(const std::string& s, const std::string& n) const {
  return std::get<bool>(entry(s, n, ParamType::kBool).value);
}
const std::string& Scene::text(const std::string& s, const std::string& n) const {
  const ParamSpec* spec = schema_->find(s, n);
  const ParamType t =
      spec && spec->type == ParamType::kEnum ? ParamType::kEnum : ParamType::kString;
  return std::get<std::string>(entry(s, n, t).value);
}
fs::path Scene::path(const std::string& s, const std::string& n) const {
  return std::get<std::string>(entry(s, n, ParamType::kInputPath).value);  // "" when not given
}
Eigen::Matrix4d Scene::matrix4(const std::string& s, const std::string& n) const {
  return std::get<Eigen::Matrix4d>(entry(s, n, ParamType::kMatrix4).value);
}

Eigen::Vector3d Scene::vec3(const std::string& s, const std::string& n) const {
  return std::get<Eigen::Vector3d>(entry(s, n, ParamType::kVec3).value);
}

bool Scene::holds(const UseCondition& c) const {
  // A condition compares the value's text: "rtstruct", "0", "true".
  const auto it = entries_.find(c.key);
  if (it == entries_.end() || std::holds_alternative<std::monostate>(it->second.value))
    return false;
  return std::find(c.values.begin(), c.values.end(), value_to_text(it->second.value)) !=
         c.values.end();
}

const UseCondition* Scene::unmet_section_condition(const std::string& section) const {
  // From the top: "fit", then "fit.paper".
  for (size_t dot = 0; dot != std::string::npos;) {
    dot = section.find('.', dot + 1);
    const SectionSpec* spec = schema_->find_section(section.substr(0, dot));
    if (!spec) continue;
    for (const auto& c : spec->used_when)
      if (!holds(c)) return &c;
  }
  return nullptr;
}

const UseCondition* Scene::unmet_condition(const ParamSpec& spec) const {
  if (const UseCondition* failed = unmet_section_condition(spec.section)) return failed;
  if (spec.used_when.empty()) return nullptr;
  // The condition to name: the first that fails in the alternative that came closest.
  const UseCondition* failed = nullptr;
  size_t best_held = 0;
  for (const auto& alternative : spec.used_when) {
    size_t held = 0;
    for (const auto& c : alternative) {
      if (!holds(c)) {
        if (!failed || held > best_held) failed = &c, best_held = held;
        break;
      }
      ++held;
    }
    if (held == alternative.size()) return nullptr;
  }
  return failed;
}

std::string Scene::used_when_text(const SectionSpec& section) const {
  std::string out;
  for (size_t dot = 0; dot != std::string::npos;) {
    dot = section.name.find('.', dot + 1);
    const SectionSpec* spec = schema_->find_section(section.name.substr(0, dot));
    if (!spec) continue;
    for (const auto& c : spec->used_when) {
      std::string values;
      for (const auto& v : c.values)
        values += (values.empty() ? "" : " or ") + v;
      out += (out.empty() ? "" : " and ") + c.key + ": " + values;
    }
  }
  return out;
}

std::string Scene::used_when_text(const ParamSpec& spec) const {
  const SectionSpec* section = schema_->find_section(spec.section);
  const std::string of_section = section ? used_when_text(*section) : std::string();
  const std::string of_key = spec.used_when_text();
  if (of_section.empty() || of_key.empty()) return of_section + of_key;
  return of_section + ", and " + of_key;
}

int Scene::line_of(const std::string& s, const std::string& n) const {
  auto it = entries_.find(s + "." + n);
  if (it != entries_.end()) return it->second.line;
  auto sl = section_lines_.find(s);
  return sl == section_lines_.end() ? 1 : sl->second;
}

KeyRef Scene::key(const std::string& s, const std::string& n) const {
  if (const auto it = entries_.find(s + "." + n);
      it != entries_.end() && !it->second.set_on_command_line.empty())
    return KeyRef(fmt::format("--set {}", echo(it->second.set_on_command_line)));
  // An empty key: the rule is about the whole section.
  return KeyRef(
      fmt::format("{}:{}: {}{}{}", file_.string(), line_of(s, n), s, n.empty() ? "" : ".", n));
}

void Scene::fail(const std::string& s, const std::string& n, const std::string& reason) const {
  key(s, n).fail(reason);
}

void KeyRef::fail(const std::string& reason) const {
  throw InputError(prefix_.empty() ? reason : prefix_ + ": " + reason);
}

std::string Scene::resolved_yaml() const {
  std::ostringstream out;
  out << "# Fully resolved scene: every key of each section used, defaults filled in.\n";
  out << "# Source: " << file_.string() << "\n";
  for (const auto& [key, e] : entries_)
    if (!e.set_on_command_line.empty())
      out << "# Set on the command line: --set " << e.set_on_command_line << "\n";
  // Sub-sections follow their parent's keys in the schema: one pass, indented by depth.
  for (const auto& sec : schema_->sections()) {
    if (!has_section(sec.name)) continue;
    const std::string indent(2 * static_cast<size_t>(sec.depth()), ' ');
    // What this run does not use is shown, commented out, so that the file stays a
    // scene that runs the same.
    const bool section_unused = unmet_section_condition(sec.name) != nullptr;
    const std::string hide = section_unused ? "# " : "";
    if (sec.depth() > 0)
      out << indent << hide << sec.leaf() << ":  # "
          << (section_unused ? "not used by this run; " : "") << sec.doc << "\n";
    else
      out << sec.name << ":\n";
    for (const auto* p : schema_->params_of(sec.name)) {
      const auto& e = entries_.at(p->key());
      std::string v = value_to_text(e.value);
      if (p->type == ParamType::kString || p->type == ParamType::kInputPath) {
        YAML::Emitter em;
        em << YAML::DoubleQuoted << v;
        v = em.c_str();
      }
      const bool unused = unmet_condition(*p) != nullptr ||
                          (p->type == ParamType::kInputPath && value_to_text(e.value).empty());
      out << fmt::format("{}  {}{}: {}  # {}{}{}{}\n", indent, unused ? "# " : "", p->name, v,
                         p->unit.empty() ? "" : p->unit + "; ", e.given ? "" : "default; ",
                         unused && !section_unused ? "not used by this run; " : "", p->doc);
    }
  }
  return out.str();
}

nlohmann::json Scene::to_json() const {
  nlohmann::json j = nlohmann::json::object();
  for (const auto& sec : schema_->sections()) {
    if (!has_section(sec.name)) continue;
    nlohmann::json s = nlohmann::json::object();
    for (const auto* p : schema_->params_of(sec.name)) {
      const auto& v = entries_.at(p->key()).value;
      if (auto* d = std::get_if<double>(&v))
        s[p->name] = *d;
      else if (auto* i = std::get_if<long long>(&v))
        s[p->name] = *i;
      else if (auto* b = std::get_if<bool>(&v))
        s[p->name] = *b;
      else if (auto* str = std::get_if<std::string>(&v))
        s[p->name] = *str;
      else if (auto* vec = std::get_if<Eigen::Vector3d>(&v))
        s[p->name] = {vec->x(), vec->y(), vec->z()};
      else if (auto* m = std::get_if<Eigen::Matrix4d>(&v)) {
        nlohmann::json rows = nlohmann::json::array();
        for (int r = 0; r < 4; ++r)
          rows.push_back({(*m)(r, 0), (*m)(r, 1), (*m)(r, 2), (*m)(r, 3)});
        s[p->name] = rows;
      }
    }
    // "fit.paper" is j["fit"]["paper"]; the parent came first.
    std::string pointer = "/" + sec.name;
    std::replace(pointer.begin(), pointer.end(), '.', '/');
    j[nlohmann::json::json_pointer(pointer)] = s;
  }
  return j;
}

}  // namespace organfit::config
