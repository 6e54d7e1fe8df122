#pragma once
// Scene keys bound to the fields of an option struct, so that each setting is declared
// once: its name, unit, range and doc here, its default the struct's own initialiser.
// The same list declares the keys in the schema and reads a scene into the struct.
//
//   const Binding<PaperForceParams> keys = Binding<PaperForceParams>("fit.paper")
//       .number("alpha", &PaperForceParams::alpha, "", 1.0, 20.0, "fall-off exponent");
//   keys.declare(schema);                // after schema.subsection("paper", ...)
//   PaperForceParams p = keys.read(scene);  // the struct's defaults, then the scene's values
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "organfit/config/scene.h"
#include "organfit/config/schema.h"

namespace organfit::config {

template <class Options>
class Binding {
 public:
  /// `section` is where the keys live ("fit", "fit.paper").
  explicit Binding(std::string section) : section_(std::move(section)) {}

  /// A real-valued field (double).
  Binding& number(const std::string& name, double Options::*field, const std::string& unit,
                  std::optional<double> min, std::optional<double> max, const std::string& doc,
                  bool min_exclusive = false) {
    ParamSpec spec;
    spec.name = name, spec.type = ParamType::kNumber, spec.unit = unit;
    spec.min = min, spec.max = max, spec.min_exclusive = min_exclusive, spec.doc = doc;
    keys_.push_back({std::move(spec), [field](const Options& o) { return Value(o.*field); },
                     [field, name](const Scene& s, const std::string& sec, Options& o) {
                       o.*field = s.number(sec, name);
                     }});
    return *this;
  }

  /// A whole-number field (int, long long, ...).
  template <class Int,
            class = std::enable_if_t<std::is_integral_v<Int> && !std::is_same_v<Int, bool>>>
  Binding& integer(const std::string& name, Int Options::*field, std::optional<double> min,
                   std::optional<double> max, const std::string& doc) {
    ParamSpec spec;
    spec.name = name, spec.type = ParamType::kInteger, spec.min = min, spec.max = max;
    spec.doc = doc;
    keys_.push_back({std::move(spec),
                     [field](const Options& o) { return Value(static_cast<long long>(o.*field)); },
                     [field, name](const Scene& s, const std::string& sec, Options& o) {
                       o.*field = static_cast<Int>(s.integer(sec, name));
                     }});
    return *this;
  }

  /// A true/false field.
  Binding& flag(const std::string& name, bool Options::*field, const std::string& doc) {
    ParamSpec spec;
    spec.name = name, spec.type = ParamType::kBool, spec.doc = doc;
    keys_.push_back({std::move(spec), [field](const Options& o) { return Value(o.*field); },
                     [field, name](const Scene& s, const std::string& sec, Options& o) {
                       o.*field = s.flag(sec, name);
                     }});
    return *this;
  }

  /// A three-vector field (Eigen::Vector3d), `min` on each component.
  Binding& vec3(const std::string& name, Eigen::Vector3d Options::*field, const std::string& unit,
                std::optional<double> min, const std::string& doc, bool min_exclusive = false) {
    ParamSpec spec;
    spec.name = name, spec.type = ParamType::kVec3, spec.unit = unit, spec.min = min;
    spec.min_exclusive = min_exclusive, spec.doc = doc;
    keys_.push_back({std::move(spec),
                     [field](const Options& o) { return Value((o.*field).eval()); },
                     [field, name](const Scene& s, const std::string& sec, Options& o) {
                       o.*field = s.vec3(sec, name);
                     }});
    return *this;
  }

  /// The last bound key is used only when all of `conditions` hold (Schema::used_when).
  Binding& used_when(std::vector<UseCondition> conditions) {
    if (keys_.empty()) throw std::logic_error("binding: used_when before any key");
    keys_.back().spec.used_when.push_back(std::move(conditions));
    return *this;
  }

  /// Declares the keys in `schema`'s last declared section, which must be this
  /// binding's, with `defaults`' values as their defaults.
  void declare(Schema& schema, const Options& defaults = Options{}) const {
    if (schema.sections().empty() || schema.sections().back().name != section_)
      throw std::logic_error("binding: declare " + section_ + " after declaring its section");
    for (const auto& key : keys_) {
      ParamSpec spec = key.spec;
      spec.default_value = key.get(defaults);
      schema.add(std::move(spec));
    }
  }

  /// `into` with every bound field set from the scene (given or default).
  Options read(const Scene& scene, Options into = Options{}) const {
    for (const auto& key : keys_)
      key.set(scene, section_, into);
    return into;
  }

  const std::string& section() const { return section_; }
  /// The declaration of the bound key `name` (its range, unit and doc), or nullptr.
  const ParamSpec* find(const std::string& name) const {
    for (const auto& key : keys_)
      if (key.spec.name == name) return &key.spec;
    return nullptr;
  }

 private:
  struct Key {
    ParamSpec spec;
    std::function<Value(const Options&)> get;
    std::function<void(const Scene&, const std::string&, Options&)> set;
  };
  std::string section_;
  std::vector<Key> keys_;
};

}  // namespace organfit::config
