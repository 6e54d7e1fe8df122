// Keys bound to an option struct: the schema's defaults are the struct's, and the same
// list reads a scene back into the struct.
#include "organfit/config/binding.h"

#include <gtest/gtest.h>

#include "organfit/support/error.h"

namespace organfit::config {
namespace {

struct Options {
  double radius_mm = 1.85;
  int count = 87;
  long long steps = 20000;
  bool hold = true;
  Eigen::Vector3d seed_mm = Eigen::Vector3d(1, 2, 3);
  double untouched = 42;  // not bound: read() leaves it as given
};

const Binding<Options>& keys() {
  static const auto b =
      Binding<Options>("model")
          .number("radius_mm", &Options::radius_mm, "mm", 0.0, 10.0, "radius", true)
          .integer("count", &Options::count, 1, 1000, "count")
          .used_when({{"model.hold", {"true"}}})
          .integer("steps", &Options::steps, 0, std::nullopt, "steps")
          .flag("hold", &Options::hold, "hold")
          .vec3("seed_mm", &Options::seed_mm, "mm", std::nullopt, "seed");
  return b;
}

Schema schema() {
  Schema s;
  s.section("model", "the model");
  keys().declare(s);
  return s;
}

TEST(Binding, TheSchemasDefaultsAreTheStructsOwn) {
  const Schema s = schema();
  ASSERT_EQ(s.params_of("model").size(), 5u);
  EXPECT_EQ(std::get<double>(s.find("model", "radius_mm")->default_value), 1.85);
  EXPECT_TRUE(s.find("model", "radius_mm")->min_exclusive);
  EXPECT_EQ(s.find("model", "radius_mm")->unit, "mm");
  EXPECT_EQ(std::get<long long>(s.find("model", "count")->default_value), 87);
  EXPECT_EQ(s.find("model", "count")->used_when_text(), "model.hold: true");
  EXPECT_EQ(std::get<long long>(s.find("model", "steps")->default_value), 20000);
  EXPECT_EQ(std::get<bool>(s.find("model", "hold")->default_value), true);
  EXPECT_EQ(std::get<Eigen::Vector3d>(s.find("model", "seed_mm")->default_value),
            Eigen::Vector3d(1, 2, 3));
  // Other defaults (a variant of the struct) declare other defaults.
  Options other;
  other.count = 5;
  Schema t;
  t.section("model", "the model");
  keys().declare(t, other);
  EXPECT_EQ(std::get<long long>(t.find("model", "count")->default_value), 5);
}

TEST(Binding, ReadsTheScenesValuesAndDefaultsIntoTheStruct) {
  const Schema s = schema();
  const Scene scene =
      parse_scene("model:\n  radius_mm: 2.5\n  steps: 7\n  seed_mm: [0, 0, 1]\n", "/s.yaml", s);
  Options start;
  start.untouched = -1;
  const Options o = keys().read(scene, start);
  EXPECT_EQ(o.radius_mm, 2.5);
  EXPECT_EQ(o.count, 87);
  EXPECT_EQ(o.steps, 7);
  EXPECT_TRUE(o.hold);
  EXPECT_EQ(o.seed_mm, Eigen::Vector3d(0, 0, 1));
  EXPECT_EQ(o.untouched, -1);
  // A default scene reads back as the struct's defaults.
  const Options d = keys().read(parse_scene("model:\n", "/s.yaml", s));
  EXPECT_EQ(d.radius_mm, Options{}.radius_mm);
  EXPECT_EQ(d.count, Options{}.count);
  EXPECT_EQ(d.steps, Options{}.steps);
  EXPECT_EQ(d.seed_mm, Options{}.seed_mm);
}

TEST(Binding, DeclaredOutsideItsSectionIsADeclarationBug) {
  Schema s;
  s.section("fit", "the fit");
  EXPECT_THROW(keys().declare(s), std::logic_error);
  Schema empty;
  EXPECT_THROW(keys().declare(empty), std::logic_error);
}

}  // namespace
}  // namespace organfit::config
