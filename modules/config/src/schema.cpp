#include "organfit/config/schema.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <sstream>
#include <stdexcept>

namespace organfit::config {

const char* to_string(ParamType type) {
  switch (type) {
    case ParamType::kNumber:
      return "number";
    case ParamType::kInteger:
      return "integer";
    case ParamType::kBool:
      return "bool";
    case ParamType::kString:
      return "string";
    case ParamType::kEnum:
      return "enum";
    case ParamType::kInputPath:
      return "path";
    case ParamType::kVec3:
      return "vec3";
    case ParamType::kMatrix4:
      return "matrix4";
  }
  return "?";
}

namespace {
/// Six significant digits when they give the number back, else as many as it takes: a
/// resolved scene holds exactly the values that ran.
std::string format_number(double v) {
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  const std::string short_form = fmt::format("{:g}", v);
  return std::strtod(short_form.c_str(), nullptr) == v ? short_form : fmt::format("{}", v);
}
}  // namespace

std::string value_to_text(const Value& value) {
  struct Visitor {
    std::string operator()(std::monostate) const { return "(required)"; }
    std::string operator()(double v) const { return format_number(v); }
    std::string operator()(long long v) const { return std::to_string(v); }
    std::string operator()(bool v) const { return v ? "true" : "false"; }
    std::string operator()(const std::string& v) const { return v; }
    std::string operator()(const Eigen::Matrix4d& m) const {
      std::string out = "[";
      for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c)
          out += (r + c ? ", " : "") + format_number(m(r, c));
      return out + "]";
    }
    std::string operator()(const Eigen::Vector3d& v) const {
      return fmt::format("[{}, {}, {}]", format_number(v.x()), format_number(v.y()),
                         format_number(v.z()));
    }
  };
  return std::visit(Visitor{}, value);
}

std::string ParamSpec::range_text() const {
  if (type == ParamType::kEnum) {
    std::string s = "{";
    for (size_t i = 0; i < choices.size(); ++i)
      s += (i ? ", " : "") + choices[i];
    return s + "}";
  }
  if (!min && !max) return "";
  return fmt::format("{}{}, {}]", min_exclusive ? "(" : "[", min ? format_number(*min) : "-inf",
                     max ? format_number(*max) : "inf");
}

namespace {
/// "fit.method: paper" or "points.source: generate and ultrasound.source: simulate".
std::string conditions_text(const std::vector<UseCondition>& all) {
  std::string out;
  for (const auto& c : all) {
    std::string values;
    for (const auto& v : c.values)
      values += (values.empty() ? "" : " or ") + v;
    out += (out.empty() ? "" : " and ") + c.key + ": " + values;
  }
  return out;
}
}  // namespace

std::string ParamSpec::used_when_text() const {
  std::string out;
  for (const auto& alternative : used_when)
    out += (out.empty() ? "" : "; or ") + conditions_text(alternative);
  return out;
}

std::string SectionSpec::parent() const {
  const auto dot = name.rfind('.');
  return dot == std::string::npos ? std::string() : name.substr(0, dot);
}

std::string SectionSpec::leaf() const {
  const auto dot = name.rfind('.');
  return dot == std::string::npos ? name : name.substr(dot + 1);
}

int SectionSpec::depth() const {
  return static_cast<int>(std::count(name.begin(), name.end(), '.'));
}

Schema& Schema::used_when(std::vector<UseCondition> conditions) {
  if (params_.empty()) throw std::logic_error("schema: used_when before any key");
  for (const auto& c : conditions)
    if (c.key.find('.') == std::string::npos || c.values.empty())
      throw std::logic_error("schema: a condition names section.key and its values");
  params_.back().used_when.push_back(std::move(conditions));
  return *this;
}

Schema& Schema::section(const std::string& name, const std::string& doc, bool always_present) {
  if (name.empty() || name.find('.') != std::string::npos)
    throw std::logic_error("schema: a section's name has no dot (subsection): " + name);
  if (find_section(name)) throw std::logic_error("schema: section declared twice: " + name);
  sections_.push_back({name, doc, always_present, {}});
  return *this;
}

Schema& Schema::subsection(const std::string& name, const std::string& doc,
                           std::vector<UseCondition> used_when) {
  const auto top = std::find_if(sections_.rbegin(), sections_.rend(),
                                [](const SectionSpec& s) { return s.depth() == 0; });
  if (top == sections_.rend()) throw std::logic_error("schema: subsection before any section");
  if (name.empty() || name.find('.') != std::string::npos)
    throw std::logic_error("schema: a subsection's name has no dot: " + name);
  const std::string full = top->name + "." + name;
  if (find_section(full)) throw std::logic_error("schema: section declared twice: " + full);
  if (find(top->name, name))
    throw std::logic_error("schema: subsection named as a key of its section: " + full);
  for (const auto& c : used_when)
    if (c.key.find('.') == std::string::npos || c.values.empty())
      throw std::logic_error("schema: a condition names section.key and its values");
  sections_.push_back({full, doc, true, std::move(used_when)});
  return *this;
}

bool number_in_range(const ParamSpec& s, double v) {
  if (s.min && (s.min_exclusive ? !(v > *s.min) : !(v >= *s.min))) return false;
  if (s.max && !(v <= *s.max)) return false;
  return true;
}

Schema& Schema::add(ParamSpec spec) {
  if (sections_.empty()) throw std::logic_error("schema: key declared before any section");
  spec.section = sections_.back().name;
  if (find(spec.section, spec.name)) {
    throw std::logic_error("schema: key declared twice: " + spec.key());
  }
  if (find_section(spec.key()))
    throw std::logic_error("schema: key named as a subsection: " + spec.key());
  // A default outside its own range is a declaration bug: catch it at start-up.
  bool ok = true;
  if (auto* d = std::get_if<double>(&spec.default_value)) ok = number_in_range(spec, *d);
  if (auto* i = std::get_if<long long>(&spec.default_value))
    ok = number_in_range(spec, static_cast<double>(*i));
  if (auto* s = std::get_if<std::string>(&spec.default_value); s && spec.type == ParamType::kEnum) {
    ok = std::find(spec.choices.begin(), spec.choices.end(), *s) != spec.choices.end();
  }
  if (!ok) throw std::logic_error("schema: default out of range for " + spec.key());
  params_.push_back(std::move(spec));
  return *this;
}

Schema& Schema::number(const std::string& name, std::optional<double> def, const std::string& unit,
                       std::optional<double> min, std::optional<double> max, const std::string& doc,
                       bool min_exclusive) {
  ParamSpec s;
  s.name = name;
  s.type = ParamType::kNumber;
  if (def) s.default_value = *def;
  s.unit = unit;
  s.min = min;
  s.max = max;
  s.min_exclusive = min_exclusive;
  s.doc = doc;
  return add(std::move(s));
}

Schema& Schema::integer(const std::string& name, std::optional<long long> def,
                        std::optional<double> min, std::optional<double> max,
                        const std::string& doc) {
  ParamSpec s;
  s.name = name;
  s.type = ParamType::kInteger;
  if (def) s.default_value = *def;
  s.min = min;
  s.max = max;
  s.doc = doc;
  return add(std::move(s));
}

Schema& Schema::flag(const std::string& name, bool def, const std::string& doc) {
  ParamSpec s;
  s.name = name;
  s.type = ParamType::kBool;
  s.default_value = def;
  s.doc = doc;
  return add(std::move(s));
}

Schema& Schema::text(const std::string& name, std::optional<std::string> def,
                     const std::string& doc) {
  ParamSpec s;
  s.name = name;
  s.type = ParamType::kString;
  if (def) s.default_value = *def;
  s.doc = doc;
  return add(std::move(s));
}

Schema& Schema::choice(const std::string& name, const std::string& def,
                       std::vector<std::string> choices, const std::string& doc) {
  ParamSpec s;
  s.name = name;
  s.type = ParamType::kEnum;
  s.default_value = def;
  s.choices = std::move(choices);
  s.doc = doc;
  return add(std::move(s));
}

Schema& Schema::input_path(const std::string& name, const std::string& doc, bool required) {
  ParamSpec s;
  s.name = name;
  s.type = ParamType::kInputPath;
  if (!required) s.default_value = std::string();
  s.doc = doc;
  return add(std::move(s));
}

Schema& Schema::matrix4(const std::string& name, const std::string& doc) {
  ParamSpec s;
  s.name = name;
  s.type = ParamType::kMatrix4;
  s.default_value = Eigen::Matrix4d::Identity().eval();
  s.unit = "mm";
  s.doc = doc;
  return add(std::move(s));
}

Schema& Schema::vec3(const std::string& name, std::optional<Eigen::Vector3d> def,
                     const std::string& unit, std::optional<double> min, const std::string& doc,
                     bool min_exclusive) {
  ParamSpec s;
  s.name = name;
  s.type = ParamType::kVec3;
  if (def) s.default_value = *def;
  s.unit = unit;
  s.min = min;
  s.min_exclusive = min_exclusive;
  s.doc = doc;
  return add(std::move(s));
}

const SectionSpec* Schema::find_section(const std::string& name) const {
  for (const auto& s : sections_)
    if (s.name == name) return &s;
  return nullptr;
}

const ParamSpec* Schema::find(const std::string& section, const std::string& name) const {
  for (const auto& p : params_)
    if (p.section == section && p.name == name) return &p;
  return nullptr;
}

std::vector<const ParamSpec*> Schema::params_of(const std::string& section) const {
  std::vector<const ParamSpec*> out;
  for (const auto& p : params_)
    if (p.section == section) out.push_back(&p);
  return out;
}

std::vector<const SectionSpec*> Schema::subsections_of(const std::string& name) const {
  std::vector<const SectionSpec*> out;
  for (const auto& s : sections_)
    if (s.parent() == name && s.depth() > 0) out.push_back(&s);
  return out;
}

const ParamSpec* Schema::find_key(const std::string& dotted) const {
  const auto dot = dotted.rfind('.');
  if (dot == std::string::npos || dot == 0) return nullptr;
  return find(dotted.substr(0, dot), dotted.substr(dot + 1));
}

std::string Schema::to_text() const {
  std::ostringstream out;
  for (const auto& sec : sections_) {
    const std::string indent(2 * static_cast<size_t>(sec.depth()), ' ');
    const std::string when = conditions_text(sec.used_when);
    out << indent << sec.leaf() << ":  # " << sec.doc
        << (when.empty() ? "" : " [used with " + when + "]") << "\n";
    for (const auto* p : params_of(sec.name)) {
      const std::string key_when = p->used_when_text();
      out << fmt::format("{}  {:<22} {:<8} default {:<16} {:<6} {:<14} {}{}\n", indent, p->name,
                         to_string(p->type), value_to_text(p->default_value),
                         p->unit.empty() ? "-" : p->unit, p->range_text(), p->doc,
                         key_when.empty() ? "" : " [used with " + key_when + "]");
    }
  }
  return out.str();
}

nlohmann::json Schema::to_json() const {
  nlohmann::json sections = nlohmann::json::array();
  for (const auto& sec : sections_) {
    nlohmann::json keys = nlohmann::json::array();
    for (const auto* p : params_of(sec.name)) {
      nlohmann::json k = {{"name", p->name},
                          {"type", to_string(p->type)},
                          {"required", p->required()},
                          {"default", p->required() ? "" : value_to_text(p->default_value)},
                          {"unit", p->unit},
                          {"range", p->range_text()},
                          {"doc", p->doc},
                          {"used_when", p->used_when_text()}};
      keys.push_back(k);
    }
    sections.push_back({{"section", sec.name},
                        {"doc", sec.doc},
                        {"used_when", conditions_text(sec.used_when)},
                        {"keys", keys}});
  }
  return sections;
}

}  // namespace organfit::config
