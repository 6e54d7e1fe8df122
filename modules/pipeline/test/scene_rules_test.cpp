// organfit's own scene schema: cross-key rules and the model stage's summary.
#include <gtest/gtest.h>

#include "organfit/pipeline/model_stage.h"
#include "organfit/pipeline/scene_schema.h"
#include "organfit/support/error.h"

namespace organfit::pipeline {
namespace {

config::Scene parse(const std::string& text) {
  config::Scene scene = config::parse_scene(text, "/s.yaml", scene_schema());
  check_scene_rules(scene);
  return scene;
}

std::string error_of(const std::string& text) {
  try {
    parse(text);
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

TEST(SceneRules, ExponentsMustSatisfyMBelowN) {
  EXPECT_EQ(error_of("body:\nmodel:\n  exponent_m: 8\n  exponent_n: 8\n"),
            "/s.yaml:4: model.exponent_n: the repulsive exponent n (8) must exceed the "
            "attractive m (8)");
}

TEST(SceneRules, CutoffMustExceedRMin) {
  EXPECT_EQ(error_of("body:\nmodel:\n  cutoff_r0: 1.05\n"),
            "/s.yaml:3: model.cutoff_r0: must exceed r_min = 1.1087 r0 for m=6, n=12, else "
            "nothing holds the body together");
}

TEST(SceneSchema, EveryKeyHasADocAndDefaultsPassTheirOwnRules) {
  for (const auto& p : scene_schema().params())
    EXPECT_FALSE(p.doc.empty()) << p.key();
  EXPECT_NO_THROW(parse("scene:\nbody:\nmodel:\n"));
}

TEST(ModelStage, FillsAndRelaxesTheBodyIntoOneComponent) {
  const config::Scene scene =
      parse("body:\n  shape: box\n  size_mm: [60, 48, 36]\nmodel:\n  radius_mm: 1.5\n");
  const ModelStageResult r = run_model_stage(scene);
  EXPECT_EQ(r.summary["particles"].get<int>(), r.state.size());
  EXPECT_GT(r.state.size(), 100);
  EXPECT_EQ(r.summary["components"].get<int>(), 1);
  EXPECT_TRUE(r.summary["relax_settled"].get<bool>());
  EXPECT_GE(r.summary["skeleton_nodes"].get<int>(), 2);
  EXPECT_EQ(r.model->terms().size(), 2u);  // cohesion and skeleton
  // Lattice volume (count x volume per fcc site) is close to the box volume for a body
  // many particles wide; it misses the partial cells at the faces (27% for a body only
  // 5 cells wide), so it is no substitute for a gap-closing volume measure.
  const double box = 60.0 * 48 * 36;
  EXPECT_NEAR(r.summary["lattice_volume_mm3"].get<double>(), box, 0.15 * box);
  EXPECT_NEAR(r.summary["lattice_spacing_mm"].get<double>() / r.summary["r0_mm"].get<double>(),
              0.9758, 5e-4);
}

TEST(ModelStage, ABodyTooSmallForOneParticleIsABadInputNamingTheKey) {
  const config::Scene scene = parse("body:\n  size_mm: [1, 1, 1]\nmodel:\n  radius_mm: 5\n");
  try {
    run_model_stage(scene);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/s.yaml:2: body.size_mm:"), std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace organfit::pipeline
