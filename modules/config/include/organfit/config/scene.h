#pragma once
// A loaded, validated scene: every key of each present section has a value (given or
// default), checked against the schema, with the line it came from for later errors.
#include <Eigen/Core>
#include <filesystem>
#include <functional>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "organfit/config/schema.h"

namespace organfit::config {

/// Where a key's value came from, kept with an option read from it so that an error found
/// later (a file that cannot be read, a value the data cannot take) names the key as a
/// scene error does: "file:line: section.name: reason", or "--set section.name=value:
/// reason". Default: no key (the reason alone).
class KeyRef {
 public:
  KeyRef() = default;
  explicit KeyRef(std::string prefix) : prefix_(std::move(prefix)) {}
  /// Throws InputError "<where>: reason".
  [[noreturn]] void fail(const std::string& reason) const;

 private:
  std::string prefix_;
};

class Scene {
 public:
  /// The scene file (for messages and for resolving relative paths).
  const std::filesystem::path& file() const { return file_; }
  const Schema& schema() const { return *schema_; }

  /// A sub-section ("fit.paper") is there whenever its parent is.
  bool has_section(const std::string& section) const { return sections_.count(section) > 0; }
  const std::set<std::string>& sections() const { return sections_; }
  /// The sections written in the scene (or by --set), sub-sections included.
  const std::set<std::string>& given_sections() const { return given_sections_; }
  /// True when the key was written in the scene (not defaulted).
  bool is_given(const std::string& section, const std::string& name) const;

  // Typed access; the key must be declared with that type (else std::logic_error).
  double number(const std::string& section, const std::string& name) const;
  long long integer(const std::string& section, const std::string& name) const;
  bool flag(const std::string& section, const std::string& name) const;
  const std::string& text(const std::string& section, const std::string& name) const;
  /// Input path, already resolved against the scene's folder.
  std::filesystem::path path(const std::string& section, const std::string& name) const;
  Eigen::Vector3d vec3(const std::string& section, const std::string& name) const;
  Eigen::Matrix4d matrix4(const std::string& section, const std::string& name) const;

  /// The first condition of the key's section (and its parents) or of `spec.used_when`
  /// this scene does not meet (nullptr: the run uses the key).
  const UseCondition* unmet_condition(const ParamSpec& spec) const;
  /// The first condition of a section or its parents this scene does not meet.
  const UseCondition* unmet_section_condition(const std::string& section) const;
  /// When the run uses a section's keys, or a key: "fit.method: paper", for messages.
  std::string used_when_text(const SectionSpec& section) const;
  std::string used_when_text(const ParamSpec& spec) const;
  /// Line (1-based) where the key was given, or where its section starts when defaulted.
  int line_of(const std::string& section, const std::string& name) const;
  /// Throws InputError "file:line: section.name: reason" (for cross-key rules).
  [[noreturn]] void fail(const std::string& section, const std::string& name,
                         const std::string& reason) const;
  /// The key, to fail on later as fail() does.
  KeyRef key(const std::string& section, const std::string& name) const;

  /// The fully resolved scene as YAML: every key of each present section, with
  /// defaults filled in and the unit and doc as comments.
  std::string resolved_yaml() const;
  /// The same values as JSON {section: {key: value, subsection: {key: value}}}.
  nlohmann::json to_json() const;

 private:
  friend Scene parse_scene(const std::string&, const std::filesystem::path&, const Schema&,
                           const std::vector<std::string>&);
  struct Entry {
    Value value;
    int line = 0;
    bool given = false;
    std::string set_on_command_line;  ///< "section.key=value" when --set gave it
  };
  const Entry& entry(const std::string& section, const std::string& name, ParamType type) const;
  bool holds(const UseCondition& c) const;

  std::filesystem::path file_;
  const Schema* schema_ = nullptr;
  std::set<std::string> sections_;
  std::set<std::string> given_sections_;
  std::map<std::string, int> section_lines_;
  std::map<std::string, Entry> entries_;  // by "section.name"
};

/// Parses scene text against the schema. `file` names the scene in messages and
/// anchors relative paths. Throws InputError "file:line: key: reason" on the first
/// problem: YAML syntax, an unknown section or key (with the nearest declared name),
/// a duplicate key, a wrong type, a value out of range, a missing required key or
/// a missing input file. The schema must outlive the scene.
///
/// `overrides` ("section.key=value", from `organfit run --set`) replace or add keys (and
/// their sections) before the same validation; the value is YAML ("[1, 2, 3]" a list); a
/// relative path is taken from the current folder. Their errors read "--set
/// section.key=value: reason".
Scene parse_scene(const std::string& text, const std::filesystem::path& file, const Schema& schema,
                  const std::vector<std::string>& overrides = {});

/// Reads and parses a scene file (InputError when it cannot be read), with `overrides`.
Scene load_scene(const std::filesystem::path& file, const Schema& schema,
                 const std::vector<std::string>& overrides = {});

}  // namespace organfit::config
