// Scene loading: every kind of config error names file:line and the key.
#include "organfit/config/scene.h"

#include <gtest/gtest.h>

#include "organfit/support/error.h"

namespace organfit::config {
namespace {

Schema test_schema() {
  Schema s;
  s.section("model", "the particle model")
      .number("radius_mm", 1.5, "mm", 0.0, std::nullopt, "particle radius", true)
      .integer("exponent_m", 6, 1, 60, "LJ attractive exponent")
      .flag("skeleton", true, "attach a skeleton")
      .choice("method", "spread", {"paper", "spread"}, "fit variant")
      .vec3("size_mm", Eigen::Vector3d(10, 20, 30), "mm", 0.0, "box size", true);
  s.section("points", "attractive points")
      .input_path("file", "points CSV")
      .text("label", "x", "a label");
  return s;
}

std::string error_of(const std::string& text) {
  const Schema schema = test_schema();
  try {
    parse_scene(text, "/scenes/s.yaml", schema);
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

TEST(SceneParse, DefaultsFillTheKeysOfAPresentSection) {
  const Schema schema = test_schema();
  const Scene scene = parse_scene("model:\n  radius_mm: 2\n", "/s.yaml", schema);
  EXPECT_DOUBLE_EQ(scene.number("model", "radius_mm"), 2.0);
  EXPECT_EQ(scene.integer("model", "exponent_m"), 6);
  EXPECT_TRUE(scene.flag("model", "skeleton"));
  EXPECT_EQ(scene.text("model", "method"), "spread");
  EXPECT_EQ(scene.vec3("model", "size_mm"), Eigen::Vector3d(10, 20, 30));
  EXPECT_TRUE(scene.is_given("model", "radius_mm"));
  EXPECT_FALSE(scene.is_given("model", "exponent_m"));
  EXPECT_FALSE(scene.has_section("points"));
  EXPECT_EQ(scene.line_of("model", "radius_mm"), 2);
}

TEST(SceneParse, MisspelledKeyNamesFileLineKeyAndSuggestion) {
  EXPECT_EQ(error_of("model:\n  radius_mm: 2\n  raduis_mm: 3\n"),
            "/scenes/s.yaml:3: model.raduis_mm: unknown key (did you mean 'radius_mm'?)");
}

TEST(SceneParse, UnknownSectionIsAnError) {
  EXPECT_EQ(error_of("modle:\n  radius_mm: 2\n"),
            "/scenes/s.yaml:1: modle: unknown section (did you mean 'model'?)");
}

TEST(SceneParse, StringWhereANumberBelongs) {
  EXPECT_EQ(error_of("model:\n  radius_mm: big\n"),
            "/scenes/s.yaml:2: model.radius_mm: expected a number, got 'big'");
}

TEST(SceneParse, NegativeRadiusIsOutOfRange) {
  EXPECT_EQ(error_of("model:\n\n  radius_mm: -1.5\n"),
            "/scenes/s.yaml:3: model.radius_mm: -1.5 is out of range (0, inf] mm");
}

TEST(SceneParse, IntegerKeyRejectsAFraction) {
  EXPECT_EQ(error_of("model:\n  exponent_m: 2.5\n"),
            "/scenes/s.yaml:2: model.exponent_m: expected an integer, got '2.5'");
}

TEST(SceneParse, NonFiniteNumbersAreRejected) {
  EXPECT_EQ(error_of("model:\n  radius_mm: .nan\n"),
            "/scenes/s.yaml:2: model.radius_mm: must be finite, got '.nan'");
}

TEST(SceneParse, BadBoolAndEnum) {
  EXPECT_EQ(error_of("model:\n  skeleton: maybe\n"),
            "/scenes/s.yaml:2: model.skeleton: expected true or false, got 'maybe'");
  EXPECT_EQ(error_of("model:\n  method: papr\n"),
            "/scenes/s.yaml:2: model.method: 'papr' is not one of {paper, spread} (did you mean "
            "'paper'?)");
}

TEST(SceneParse, Vec3NeedsThreeNumbersEachInRange) {
  EXPECT_EQ(error_of("model:\n  size_mm: [1, 2]\n"),
            "/scenes/s.yaml:2: model.size_mm: expected three numbers [x, y, z]");
  EXPECT_EQ(error_of("model:\n  size_mm: [1, 0, 2]\n"),
            "/scenes/s.yaml:2: model.size_mm: 0 is out of range (0, inf] mm");
}

TEST(SceneParse, MissingRequiredKeyAndMissingFile) {
  EXPECT_EQ(error_of("points:\n  label: a\n"),
            "/scenes/s.yaml:1: points.file: required key is missing");
  EXPECT_EQ(error_of("points:\n  file: nowhere.csv\n"),
            "/scenes/s.yaml:2: points.file: no such file or folder: /scenes/nowhere.csv");
}

TEST(SceneParse, APathTheSystemCannotLookUpIsTheKeysError) {
  // A name longer than the file system allows (found by fuzz_scene: it escaped as a
  // std::filesystem error, "internal error"), with bytes that are not UTF-8 in it.
  const std::string name = std::string(300, 'e') + "\xff\xfe";
  const std::string e = error_of("points:\n  file: /o" + name + "\n");
  EXPECT_EQ(e.rfind("/scenes/s.yaml:2: points.file: File name too long: /o", 0), 0u) << e;
  EXPECT_EQ(e.find('\xff'), std::string::npos) << "a byte that is not UTF-8 echoed as it is";
}

TEST(SceneParse, DuplicatesSyntaxAndShapeErrors) {
  EXPECT_EQ(error_of("model:\n  radius_mm: 1\n  radius_mm: 2\n"),
            "/scenes/s.yaml:3: model.radius_mm: key given twice");
  EXPECT_NE(error_of("model: [1, 2\n").find("/scenes/s.yaml:"), std::string::npos);
  EXPECT_NE(error_of("model: [1, 2\n").find("YAML syntax error"), std::string::npos);
  // A tab in the indentation is named at its line (yaml-cpp: "illegal map value").
  EXPECT_EQ(error_of("scene:\n  name: a\nmodel:\n\tradius_mm: 1\n"),
            "/scenes/s.yaml:4: YAML syntax error: this line is indented with a tab (YAML indents "
            "with spaces)");
  EXPECT_EQ(error_of("model:\n  radius_mm:\t2\n"), "no error");
  EXPECT_EQ(error_of(""), "/scenes/s.yaml:1: the scene is empty");
  EXPECT_EQ(error_of("- a\n- b\n"), "/scenes/s.yaml:1: a scene is a mapping of sections");
  EXPECT_EQ(error_of("model: 3\n"), "/scenes/s.yaml:1: model: a section is a mapping of keys");
  EXPECT_EQ(error_of("model:\n  radius_mm: [1]\n"),
            "/scenes/s.yaml:2: model.radius_mm: expected a number, got 'a list'");
  // A second document would be read by nobody (it had been dropped without a word); a
  // document's end marker, or a '---' with nothing after it, holds nothing to ignore.
  EXPECT_EQ(error_of("---\nmodel:\n  radius_mm: 1\n---\nmodel:\n  radius_mm: 2\n"),
            "/scenes/s.yaml:5: a second YAML document: a scene file holds one, and the run "
            "would ignore this one");
  EXPECT_EQ(error_of("model:\n  radius_mm: 1\n...\n"), "no error");
  EXPECT_EQ(error_of("model:\n  radius_mm: 1\n---\n"), "no error");
}

TEST(SceneParse, RelativePathsResolveAgainstTheSceneFolder) {
  const Schema schema = test_schema();
  const std::string dir = ORGANFIT_SOURCE_DIR;
  const Scene scene = parse_scene("points:\n  file: CMakeLists.txt\n", dir + "/scene.yaml", schema);
  EXPECT_EQ(scene.path("points", "file"), std::filesystem::path(dir + "/CMakeLists.txt"));
}

TEST(SceneParse, ResolvedYamlReparsesToTheSameValues) {
  const Schema schema = test_schema();
  const Scene a = parse_scene("model:\n  radius_mm: 2.25\n  method: paper\n", "/s.yaml", schema);
  const Scene b = parse_scene(a.resolved_yaml(), "/r.yaml", schema);
  EXPECT_EQ(a.to_json(), b.to_json());
  EXPECT_NE(a.resolved_yaml().find("radius_mm: 2.25  # mm; particle radius"), std::string::npos);
}

TEST(SceneParse, OptionalInputPathIsEmptyWhenNotGiven) {
  Schema schema = test_schema();
  schema.section("extra", "optional file").input_path("maybe", "an optional file", false);
  const Scene scene = parse_scene("extra:\n", "/s.yaml", schema);
  EXPECT_EQ(scene.path("extra", "maybe"), std::filesystem::path());
  EXPECT_FALSE(scene.is_given("extra", "maybe"));
}

TEST(SceneParse, AlwaysPresentSectionTakesItsDefaultsWhenOmitted) {
  Schema schema = test_schema();
  schema.section("run", "run-wide settings", true).integer("seed", 7, 0, std::nullopt, "seed");
  const Scene scene = parse_scene("model:\n  radius_mm: 2\n", "/s.yaml", schema);
  EXPECT_TRUE(scene.has_section("run"));
  EXPECT_EQ(scene.integer("run", "seed"), 7);
  EXPECT_FALSE(scene.has_section("points"));
}

TEST(Schema, RejectsDeclarationBugs) {
  Schema s;
  s.section("a", "doc").number("x", 1.0, "", 0.0, 2.0, "x");
  EXPECT_THROW(s.number("x", 1.0, "", 0.0, 2.0, "again"), std::logic_error);
  EXPECT_THROW(s.number("y", 5.0, "", 0.0, 2.0, "default out of range"), std::logic_error);
  EXPECT_THROW(s.section("a", "twice"), std::logic_error);
}

TEST(Schema, TextListsEveryKeyWithUnitAndRange) {
  const std::string t = test_schema().to_text();
  EXPECT_NE(t.find("radius_mm"), std::string::npos);
  EXPECT_NE(t.find("(0, inf]"), std::string::npos);
  EXPECT_NE(t.find("{paper, spread}"), std::string::npos);
  EXPECT_EQ(test_schema().to_json().size(), 2u);
}

}  // namespace
}  // namespace organfit::config

namespace organfit::config {
namespace {

Schema schema_with_modes() {
  Schema s;
  s.section("fit", "the fit")
      .choice("method", "spread", {"paper", "spread"}, "fit variant")
      .number("alpha", 2.0, "", 1.0, 20.0, "paper only")
      .used_when({{"fit.method", {"paper"}}})
      .number("stretch", 1.5, "", 1.0, 10.0, "spread only")
      .used_when({{"fit.method", {"spread"}}});
  return s;
}

std::string override_error(const std::string& text, const std::vector<std::string>& sets) {
  const Schema schema = schema_with_modes();
  try {
    parse_scene(text, "/scenes/s.yaml", schema, sets);
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

TEST(SceneParse, AKeyTheRunWouldIgnoreIsRefusedNamingTheKeyThatDecides) {
  EXPECT_EQ(override_error("fit:\n  method: spread\n  alpha: 3\n", {}),
            "/scenes/s.yaml:3: fit.alpha: not used when fit.method is 'spread': the run would "
            "ignore it (it is used with fit.method: paper)");
  EXPECT_EQ(override_error("fit:\n  method: paper\n  alpha: 3\n", {}), "no error");
  // A default that the mode does not use is not an error: only a given key is.
  EXPECT_EQ(override_error("fit:\n  method: paper\n", {}), "no error");
}

TEST(SceneParse, SetOnTheCommandLineIsValidatedAsTheFileIsAndNamed) {
  const Schema schema = schema_with_modes();
  const Scene scene = parse_scene("fit:\n  method: paper\n", "/s.yaml", schema,
                                  {"fit.method=spread", "fit.stretch=2.5"});
  EXPECT_EQ(scene.text("fit", "method"), "spread");
  EXPECT_DOUBLE_EQ(scene.number("fit", "stretch"), 2.5);
  EXPECT_TRUE(scene.is_given("fit", "stretch"));
  EXPECT_EQ(override_error("fit:\n", {"fit.stretch=20"}),
            "--set fit.stretch=20: 20 is out of range [1, 10]");
  EXPECT_EQ(override_error("fit:\n", {"fit.strech=2"}),
            "--set fit.strech=2: unknown key (did you mean 'stretch'?)");
  EXPECT_EQ(override_error("fit:\n", {"fit.alpha=3"}),
            "--set fit.alpha=3: not used when fit.method is 'spread': the run would ignore it (it "
            "is used with fit.method: paper)");
  EXPECT_EQ(override_error("fit:\n", {"fit"}), "--set fit: expected section.key=value");
  // A section may come from the command line alone.
  EXPECT_EQ(override_error("", {"fit.method=paper"}), "no error");
}

TEST(SceneResolved, CommentsOutWhatTheRunDoesNotUseAndRecordsTheCommandLine) {
  const Schema schema = schema_with_modes();
  const Scene scene = parse_scene("fit:\n  method: paper\n", "/s.yaml", schema, {"fit.alpha=4"});
  const std::string yaml = scene.resolved_yaml();
  EXPECT_NE(yaml.find("# Set on the command line: --set fit.alpha=4\n"), std::string::npos);
  EXPECT_NE(yaml.find("\n  alpha: 4  # "), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("\n  # stretch: 1.5  # default; not used by this run; "), std::string::npos)
      << yaml;
  // And it parses back to the same values.
  const Scene again = parse_scene(yaml, "/resolved.yaml", schema);
  EXPECT_DOUBLE_EQ(again.number("fit", "alpha"), 4.0);
  EXPECT_EQ(again.text("fit", "method"), "paper");
}

}  // namespace
}  // namespace organfit::config

// Sub-sections: one method's settings within its stage (fit.paper, fit.spread).
namespace organfit::config {
namespace {

Schema schema_with_subsections() {
  Schema s;
  s.section("fit", "the fit")
      .choice("method", "spread", {"paper", "spread"}, "fit variant")
      .number("tolerance_mm", 0.5, "mm", 0.0, 10.0, "either method");
  s.subsection("paper", "the paper's force", {{"fit.method", {"paper"}}})
      .number("alpha", 2.0, "", 1.0, 20.0, "fall-off exponent");
  s.subsection("spread", "ours", {{"fit.method", {"spread"}}})
      .number("stretch", 1.5, "", 1.0, 10.0, "largest stretch")
      .integer("iterations", 60, 1, 1000, "iterations");
  s.section("report", "the report").text("file", "report.html", "file name");
  return s;
}

std::string subsection_error(const std::string& text, const std::vector<std::string>& sets = {}) {
  const Schema schema = schema_with_subsections();
  try {
    parse_scene(text, "/scenes/s.yaml", schema, sets);
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

TEST(SceneSubsections, AreThereWithTheirDefaultsWheneverTheParentIs) {
  const Schema schema = schema_with_subsections();
  const Scene scene =
      parse_scene("fit:\n  method: spread\n  spread:\n    stretch: 2\n", "/s.yaml", schema);
  EXPECT_TRUE(scene.has_section("fit.paper"));
  EXPECT_TRUE(scene.has_section("fit.spread"));
  EXPECT_FALSE(scene.has_section("report"));
  EXPECT_DOUBLE_EQ(scene.number("fit.spread", "stretch"), 2.0);
  EXPECT_EQ(scene.line_of("fit.spread", "stretch"), 4);
  EXPECT_TRUE(scene.is_given("fit.spread", "stretch"));
  EXPECT_EQ(scene.integer("fit.spread", "iterations"), 60);
  EXPECT_DOUBLE_EQ(scene.number("fit.paper", "alpha"), 2.0);
  EXPECT_EQ(scene.given_sections(), (std::set<std::string>{"fit", "fit.spread"}));
  const nlohmann::json j = scene.to_json();
  EXPECT_DOUBLE_EQ(j["fit"]["spread"]["stretch"].get<double>(), 2.0);
  EXPECT_DOUBLE_EQ(j["fit"]["paper"]["alpha"].get<double>(), 2.0);
  EXPECT_EQ(j["fit"]["method"], "spread");
}

TEST(SceneSubsections, TheOtherMethodsSettingsAreRefusedNamingTheKeyThatDecides) {
  EXPECT_EQ(subsection_error("fit:\n  method: spread\n  paper:\n    alpha: 3\n"),
            "/scenes/s.yaml:4: fit.paper.alpha: not used when fit.method is 'spread': the run "
            "would ignore it (it is used with fit.method: paper)");
  // An empty sub-section of the other method too: it says the scene means another run.
  EXPECT_EQ(subsection_error("fit:\n  paper:\n"),
            "/scenes/s.yaml:2: fit.paper: not used when fit.method is 'spread': the run would "
            "ignore it (it is used with fit.method: paper)");
  EXPECT_EQ(subsection_error("fit:\n  method: paper\n  paper:\n    alpha: 3\n"), "no error");
  EXPECT_EQ(subsection_error("fit:\n  spread:\n    strech: 2\n"),
            "/scenes/s.yaml:3: fit.spread.strech: unknown key (did you mean 'stretch'?)");
  EXPECT_EQ(subsection_error("fit:\n  spread: 3\n"),
            "/scenes/s.yaml:2: fit.spread: a section is a mapping of keys");
  EXPECT_EQ(subsection_error("spread:\n  stretch: 2\n"),
            "/scenes/s.yaml:1: spread: unknown section");
}

TEST(SceneSubsections, AKeyOneLevelTooHighIsPointedToItsSubsection) {
  EXPECT_EQ(subsection_error("fit:\n  stretch: 2\n"),
            "/scenes/s.yaml:2: fit.stretch: unknown key (did you mean 'fit.spread.stretch'?)");
  EXPECT_EQ(subsection_error("fit:\n  spread:\n    tolerance_mm: 2\n"),
            "/scenes/s.yaml:3: fit.spread.tolerance_mm: unknown key (did you mean "
            "'fit.tolerance_mm'?)");
}

TEST(SceneSubsections, SetReachesThemAndIsValidatedAsTheFileIs) {
  const Schema schema = schema_with_subsections();
  const Scene scene =
      parse_scene("", "/s.yaml", schema, {"fit.method=paper", "fit.paper.alpha=4.5"});
  EXPECT_DOUBLE_EQ(scene.number("fit.paper", "alpha"), 4.5);
  EXPECT_EQ(subsection_error("fit:\n", {"fit.paper.alpha=4"}),
            "--set fit.paper.alpha=4: not used when fit.method is 'spread': the run would ignore "
            "it (it is used with fit.method: paper)");
  EXPECT_EQ(subsection_error("fit:\n", {"fit.spread.stretch=20"}),
            "--set fit.spread.stretch=20: 20 is out of range [1, 10]");
  EXPECT_EQ(subsection_error("fit:\n", {"fit.spread.iterations=x"}),
            "--set fit.spread.iterations=x: expected an integer, got 'x'");
  EXPECT_EQ(subsection_error("fit:\n", {"fit.stretch=2"}),
            "--set fit.stretch=2: unknown key (did you mean 'fit.spread.stretch'?)");
}

TEST(SceneSubsections, ResolvedYamlNestsThemAndParsesBackToTheSameValues) {
  const Schema schema = schema_with_subsections();
  const Scene scene = parse_scene("fit:\n  spread:\n    stretch: 2\n", "/s.yaml", schema,
                                  {"fit.spread.iterations=7"});
  const std::string yaml = scene.resolved_yaml();
  EXPECT_NE(yaml.find("\n  spread:  # ours\n    stretch: 2  # "), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("\n  # paper:  # not used by this run; the paper's force\n    # alpha: 2"),
            std::string::npos)
      << yaml;
  const Scene again = parse_scene(yaml, "/resolved.yaml", schema);
  EXPECT_EQ(again.to_json(), scene.to_json());
  EXPECT_EQ(again.integer("fit.spread", "iterations"), 7);
  // Every digit that ran, not six of them.
  const Scene precise = parse_scene("fit:\n  tolerance_mm: 0.123456789012345\n", "/s.yaml", schema);
  EXPECT_EQ(parse_scene(precise.resolved_yaml(), "/r.yaml", schema).number("fit", "tolerance_mm"),
            0.123456789012345);
}

TEST(SceneSubsections, SchemaRefusesDeclarationBugs) {
  Schema s;
  EXPECT_THROW(s.subsection("paper", "no parent"), std::logic_error);
  s.section("fit", "the fit").number("paper", 1.0, "", 0.0, 2.0, "a key");
  EXPECT_THROW(s.subsection("paper", "named as a key"), std::logic_error);
  EXPECT_THROW(s.section("fit.x", "a dot"), std::logic_error);
  s.subsection("spread", "ours");
  EXPECT_THROW(s.subsection("spread", "twice"), std::logic_error);
  EXPECT_NE(s.to_text().find("fit:  # the fit\n  paper "), std::string::npos) << s.to_text();
  EXPECT_NE(s.to_text().find("\n  spread:  # ours\n"), std::string::npos) << s.to_text();
}

}  // namespace
}  // namespace organfit::config
