#pragma once
// The scene schema: every scene key declared once, with its type, default, unit,
// allowed range and a one-line doc. `organfit schema` prints it; loading enforces it.
//
// A scene is YAML, `section: {key: value}`. A section names a stage or a part of the
// model; scenes name only the sections they use (SOFA-like). A section may hold
// sub-sections ("fit.paper" is `fit: {paper: {key: value}}`): one method's settings
// within its stage.
#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <variant>
#include <vector>

namespace organfit::config {

enum class ParamType {
  kNumber,     ///< real number (finite)
  kInteger,    ///< whole number
  kBool,       ///< true/false
  kString,     ///< free text
  kEnum,       ///< one of `choices`
  kInputPath,  ///< existing file or folder, relative to the scene file's folder
  kVec3,       ///< three numbers [x, y, z]
  kMatrix4     ///< a 4x4 transform: 16 numbers row by row, or four rows of four
};

const char* to_string(ParamType type);

/// A parameter value. std::monostate means "no value" (a required key's default).
using Value = std::variant<std::monostate, double, long long, bool, std::string, Eigen::Vector3d,
                           Eigen::Matrix4d>;

/// One condition on another key: `key` ("section.name") has one of `values`.
struct UseCondition {
  std::string key;
  std::vector<std::string> values;
};

/// One declared scene key.
struct ParamSpec {
  std::string section;  ///< e.g. "model"
  std::string name;     ///< e.g. "radius_mm"
  ParamType type = ParamType::kNumber;
  Value default_value;               ///< monostate: the key is required when its section is present
  std::string unit;                  ///< "mm", "s", "HU", "" when dimensionless
  std::optional<double> min, max;    ///< allowed range (numbers, integers, each vec3 component)
  bool min_exclusive = false;        ///< true: value must be > min (e.g. a radius)
  std::vector<std::string> choices;  ///< allowed values of an enum
  std::string doc;                   ///< one line
  /// When the run uses the key: any alternative whose conditions all hold. Empty: always.
  /// A key given in a scene where none holds is refused (the run would ignore it).
  std::vector<std::vector<UseCondition>> used_when;

  std::string key() const { return section + "." + name; }
  bool required() const { return std::holds_alternative<std::monostate>(default_value); }
  /// "points.source: file" or "points.source: generate, or ultrasound.source: simulate and
  /// ..." for messages and the listing; "" when always used.
  std::string used_when_text() const;
  /// "(0, inf)", "[0, 1]", "{paper, spread}" or "" for the schema listing.
  std::string range_text() const;
};

/// `v` within the key's declared range (a number or an integer key; a vec3's component).
bool number_in_range(const ParamSpec& s, double v);

struct SectionSpec {
  std::string name;  ///< "fit", or "fit.paper" for a sub-section of "fit"
  std::string doc;
  /// Its defaults apply even when the scene omits it (a sub-section: whenever its
  /// parent is there).
  bool always_present = false;
  /// The run uses the section's keys only when all of these hold (empty: always); a
  /// key of it given when one fails is refused.
  std::vector<UseCondition> used_when;

  /// "fit" for "fit.paper"; "" for a top-level section.
  std::string parent() const;
  /// "paper" for "fit.paper"; the name itself for a top-level section.
  std::string leaf() const;
  /// Depth below the top level: 0 for "fit", 1 for "fit.paper".
  int depth() const;
};

/// The declared keys, grouped by section, in declaration order.
class Schema {
 public:
  /// Declares a section; keys added after it belong to it. An `always_present`
  /// section (run-wide settings) takes its defaults when a scene does not name it.
  Schema& section(const std::string& name, const std::string& doc, bool always_present = false);
  /// Declares "parent.name", a sub-section of the last declared top-level section: its
  /// defaults apply whenever the parent is present, and its keys are used only when
  /// all of `used_when` hold (e.g. fit.paper only with fit.method: paper).
  Schema& subsection(const std::string& name, const std::string& doc,
                     std::vector<UseCondition> used_when = {});
  /// The last declared key is used only when all of `conditions` hold, or when another
  /// alternative given by a further call holds (e.g. `points.file` only with
  /// `points.source: file`).
  Schema& used_when(std::vector<UseCondition> conditions);
  /// Declares a key of the current section. Throws std::logic_error on a duplicate
  /// or a default outside the key's own range (a bug in the declaration).
  Schema& add(ParamSpec spec);

  // Shorthands for the common kinds of key.
  Schema& number(const std::string& name, std::optional<double> def, const std::string& unit,
                 std::optional<double> min, std::optional<double> max, const std::string& doc,
                 bool min_exclusive = false);
  Schema& integer(const std::string& name, std::optional<long long> def, std::optional<double> min,
                  std::optional<double> max, const std::string& doc);
  Schema& flag(const std::string& name, bool def, const std::string& doc);
  Schema& text(const std::string& name, std::optional<std::string> def, const std::string& doc);
  Schema& choice(const std::string& name, const std::string& def, std::vector<std::string> choices,
                 const std::string& doc);
  /// An input file or folder; optional ones default to "" (not given).
  Schema& input_path(const std::string& name, const std::string& doc, bool required = true);
  /// A 4x4 transform (identity by default), e.g. a calibration or registration in mm.
  Schema& matrix4(const std::string& name, const std::string& doc);
  Schema& vec3(const std::string& name, std::optional<Eigen::Vector3d> def, const std::string& unit,
               std::optional<double> min, const std::string& doc, bool min_exclusive = false);

  const std::vector<SectionSpec>& sections() const { return sections_; }
  const std::vector<ParamSpec>& params() const { return params_; }
  const SectionSpec* find_section(const std::string& name) const;
  /// The sub-sections of `name`, in declaration order.
  std::vector<const SectionSpec*> subsections_of(const std::string& name) const;
  /// The section and key of a dotted key ("fit.paper.alpha" -> {"fit.paper", "alpha"}),
  /// or nullptr when no declared key has that name.
  const ParamSpec* find_key(const std::string& dotted) const;
  const ParamSpec* find(const std::string& section, const std::string& name) const;
  std::vector<const ParamSpec*> params_of(const std::string& section) const;

  /// Human-readable listing: one line per key with type, default, unit, range and doc.
  std::string to_text() const;
  /// The same as JSON (for tools).
  nlohmann::json to_json() const;

 private:
  std::vector<SectionSpec> sections_;
  std::vector<ParamSpec> params_;
};

/// A value as it is written in YAML ("2.5", "[1, 2, 3]", "true", "paper").
std::string value_to_text(const Value& value);

}  // namespace organfit::config
