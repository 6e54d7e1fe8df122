// organfit's own scene schema: cross-key rules and the model stage's summary.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include "organfit/pipeline/export_stage.h"
#include "organfit/pipeline/fit_stage.h"
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

TEST(SceneRules, ThePaperForcesInfluenceBoundIsNotBelowItsStart) {
  EXPECT_EQ(error_of("body:\nmodel:\npoints:\nfit:\n  method: paper\n  paper:\n"
                     "    influence_radius_max_r0: 1.0\n"),
            "/s.yaml:7: fit.paper.influence_radius_max_r0: the influence radius's bound (1 r0) "
            "is below its value at contact (1.2 r0)");
}

// Each output has a visible name of its own in --out: a model or mesh named as the run's
// own files, or as another output, would leave one of them (a model named run.json had been
// overwritten by the run's record, exit 0).
TEST(SceneRules, EachOutputHasAVisibleNameOfItsOwn) {
  EXPECT_EQ(error_of("body:\nmodel:\nexport:\n  model: run.json\n"),
            "/s.yaml:4: export.model: 'run.json' is already the run's record's name in --out");
  EXPECT_EQ(error_of("body:\nmodel:\npoints:\nfit:\nexport:\n  model: history.csv\n"),
            "/s.yaml:6: export.model: 'history.csv' is already the fit's history's name in --out");
  EXPECT_EQ(error_of("body:\nmodel:\nexport:\n  mesh: organ.stl\nreport:\n  file: organ.stl\n"),
            "/s.yaml:6: report.file: 'organ.stl' is already export.mesh's name in --out");
  EXPECT_EQ(error_of("body:\nmodel:\nexport:\n  mesh: .organ.stl\n"),
            "/s.yaml:4: export.mesh: a visible file name in --out (not starting with '.')");
  EXPECT_EQ(error_of("body:\nmodel:\nexport:\n  mesh: organ.stl\n  model: organ.json\n"),
            "no error");
}

// An output's format is its writer's, said when the scene is read: an upper-case mesh or
// image ending had been refused only when the file was written, after the fit.
TEST(SceneRules, EachOutputHasAFormatItsWriterKnows) {
  EXPECT_EQ(error_of("body:\nmodel:\nexport:\n  mesh: organ.STL\n"),
            "/s.yaml:4: export.mesh: organ.STL: unknown mesh format (use .stl, .vtp, .ply or "
            ".obj)");
  EXPECT_EQ(error_of("phantom:\norgan:\n  roi: Prostate\nmodel:\nexport:\n  labels: organ.png\n"),
            "/s.yaml:6: export.labels: organ.png: unknown image format (use .nrrd, .nhdr, .mha, "
            ".mhd, .nii or .nii.gz)");
  EXPECT_EQ(
      error_of("phantom:\norgan:\n  roi: Prostate\nmodel:\nexport:\n  labels: organ.nii.gz\n  "
               "mesh: organ.obj\n  rtstruct: organ.txt\n"),
      "no error");
}

// The exported ROI's name fits DICOM's ROI Name (LO, 64 characters): the default cuts the
// organ's name at a character, never within one; a name given that does not fit is refused.
TEST(RoiName, TheDefaultFitsALoAndAGivenOneThatDoesNotIsRefused) {
  EXPECT_EQ(fitted_roi_name("Prostate"), "Prostate_fit");
  EXPECT_EQ(fitted_roi_name(std::string(63, 'P')), std::string(60, 'P') + "_fit");
  std::string accented;
  for (int i = 0; i < 63; ++i)
    accented += "\xc3\xa9";  // e acute, 2 bytes
  std::string cut;
  for (int i = 0; i < 60; ++i)
    cut += "\xc3\xa9";
  EXPECT_EQ(fitted_roi_name(accented), cut + "_fit");
  EXPECT_EQ(roi_name_problem(cut + "_fit"), "");
  EXPECT_EQ(roi_name_problem(std::string(65, 'P')),
            "a ROI Name is at most 64 characters (DICOM's LO); this one has 65");
  EXPECT_EQ(roi_name_problem("GTV\\1"),
            "a ROI Name holds no backslash (DICOM's separator of values)");
  EXPECT_EQ(roi_name_problem("GTV\t1"), "a ROI Name holds no control characters");
  EXPECT_EQ(
      error_of("body:\nmodel:\nexport:\n  mesh: m.stl\n  roi_name: " + std::string(65, 'P') + "\n"),
      "/s.yaml:5: export.roi_name: a ROI Name is at most 64 characters (DICOM's LO); this "
      "one has 65");
}

// Each method's settings are the scene's: a default scene gives the option structs'
// own defaults, and a key of fit.spread reaches the field it names.
TEST(SceneSchema, TheFitsOptionsAreTheStructsDefaultsAndTheScenesValues) {
  const config::Scene defaults = parse("body:\nmodel:\npoints:\nfit:\n");
  const fitting::SpreadFitOptions d = spread_fit_options_from(defaults);
  const fitting::SpreadFitOptions s0;
  EXPECT_EQ(d.fit.residual_tolerance_mm, s0.fit.residual_tolerance_mm);
  EXPECT_EQ(d.fit.max_steps, s0.fit.max_steps);
  EXPECT_EQ(d.fit.unseen_change_sd_mm, s0.fit.unseen_change_sd_mm);
  EXPECT_EQ(d.global.max_stretch, s0.global.max_stretch);
  EXPECT_EQ(d.global.regularisation_alternative, s0.global.regularisation_alternative);
  EXPECT_EQ(d.global.max_shear_mm, s0.global.max_shear_mm);
  EXPECT_EQ(d.local.patch_sigma_r0, s0.local.patch_sigma_r0);
  EXPECT_EQ(d.local.consistency_neighbours, s0.local.consistency_neighbours);
  EXPECT_EQ(d.local.hold_volume, s0.local.hold_volume);
  const config::Scene tuned = parse(
      "body:\nmodel:\npoints:\nfit:\n  max_wall_s: 20\n  spread:\n    global_iterations: 30\n"
      "    global_few_points_shear_stiffness: 5\n    local_patch_sigma_r0: 2.5\n"
      "    local_hold_volume: false\n    consistency_neighbours: 12\n");
  const fitting::SpreadFitOptions t = spread_fit_options_from(tuned);
  EXPECT_EQ(t.fit.max_wall_s, 20.0);
  EXPECT_EQ(t.global.iterations, 30);
  EXPECT_EQ(t.global.few_points_shear_stiffness, 5.0);
  EXPECT_EQ(t.local.patch_sigma_r0, 2.5);
  EXPECT_FALSE(t.local.hold_volume);
  EXPECT_EQ(t.local.consistency_neighbours, 12);
  // resolved.yaml holds them: it parses back to the same settings.
  const config::Scene again =
      config::parse_scene(tuned.resolved_yaml(), "/resolved.yaml", scene_schema());
  EXPECT_EQ(again.to_json(), tuned.to_json());
  EXPECT_EQ(spread_fit_options_from(again).local.patch_sigma_r0, 2.5);
  const fitting::PaperFitOptions p = paper_fit_options_from(
      parse("body:\nmodel:\npoints:\nfit:\n  method: paper\n  paper:\n    alpha: 3\n"));
  EXPECT_EQ(p.force.alpha, 3.0);
  EXPECT_EQ(p.force.first_shell_r0, fitting::PaperForceParams{}.first_shell_r0);
}

TEST(SceneSchema, EveryKeyHasADocAndDefaultsPassTheirOwnRules) {
  for (const auto& p : scene_schema().params())
    EXPECT_FALSE(p.doc.empty()) << p.key();
  EXPECT_NO_THROW(parse("scene:\nbody:\nmodel:\n"));
}

// model.particles sets the radius from the body's volume: rounded bodies of different
// sizes get the count asked for within 5%; without either key a model holds the default
// count; particles beside a radius_mm is a key the run would ignore.
TEST(ModelStage, ParticlesSetTheRadiusFromTheBodysVolume) {
  for (const char* body :
       {"  shape: ellipsoid\n  size_mm: [60, 40, 30]\n", "  shape: egg\n  size_mm: [90, 50, 40]\n"})
    for (int count : {800, 6000}) {
      const config::Scene scene =
          parse(fmt::format("body:\n{}model:\n  particles: {}\n  skeleton: false\n", body, count));
      const ModelStageResult r = run_model_stage(model_stage_options_from(scene));
      EXPECT_NEAR(r.state.size(), count, 0.05 * count) << body << count;
      EXPECT_NEAR(r.summary["radius_mm"].get<double>(), r.settings.radius_mm, 1e-12);
    }
  const ModelStageResult by_default = run_model_stage(model_stage_options_from(
      parse("body:\n  size_mm: [40, 30, 20]\nmodel:\n  skeleton: false\n")));
  EXPECT_NEAR(by_default.state.size(), kDefaultParticleCount, 0.05 * kDefaultParticleCount);
  const ModelStageResult by_radius = run_model_stage(model_stage_options_from(
      parse("body:\n  size_mm: [40, 30, 20]\nmodel:\n  radius_mm: 2\n  skeleton: false\n")));
  EXPECT_EQ(by_radius.settings.radius_mm, 2.0);
  EXPECT_LT(by_radius.state.size(), 1000);  // 12.6 cm3 at r0 = 4 mm: about 300
  // The count a radius gives, foretold from the volume as the radius for a count is.
  EXPECT_NEAR(fitting::particle_count_at(by_radius.settings, by_radius.shape),
              by_radius.state.size(), 0.1 * by_radius.state.size());
  EXPECT_EQ(error_of("body:\nmodel:\n  particles: 5000\n  radius_mm: 2\n"),
            "/s.yaml:3: model.particles: not used when model.radius_mm is '2': the run would "
            "ignore it (it is used with model.radius_mm: 0)");
  const config::Scene resolved_again =
      parse(parse("body:\nmodel:\n  particles: 5000\n").resolved_yaml());
  EXPECT_EQ(resolved_again.integer("model", "particles"), 5000);
  EXPECT_EQ(resolved_again.number("model", "radius_mm"), 0.0);  // 0: the count sets it
  const config::Scene resolved_radius =
      parse(parse("body:\nmodel:\n  radius_mm: 2\n").resolved_yaml());  // particles commented out
  EXPECT_EQ(resolved_radius.number("model", "radius_mm"), 2.0);
  EXPECT_FALSE(resolved_radius.is_given("model", "particles"));
}

TEST(ModelStage, FillsAndRelaxesTheBodyIntoOneComponent) {
  const config::Scene scene =
      parse("body:\n  shape: box\n  size_mm: [60, 48, 36]\nmodel:\n  radius_mm: 1.5\n");
  const ModelStageResult r = run_model_stage(model_stage_options_from(scene));
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

// An organ given as a mask of 1 mm voxels over `size` from `origin_mm`, label 1 where
// `inside` (a point in mm) holds.
template <class Inside>
geometry::Shape organ_of(const std::array<int, 3>& size, const Eigen::Vector3d& origin_mm,
                         Inside&& inside) {
  geometry::ImageGeometry g;
  g.size = size;
  g.spacing_mm = Eigen::Vector3d::Ones();
  g.origin_mm = origin_mm;
  auto mask = std::make_shared<geometry::LabelVolume>(g);
  for (int k = 0; k < size[2]; ++k)
    for (int j = 0; j < size[1]; ++j)
      for (int i = 0; i < size[0]; ++i)
        mask->at(i, j, k) = inside(g.index_to_physical(Eigen::Vector3d(i, j, k)));
  return geometry::make_mask_shape(mask);
}

// An organ with a part only two particles across (a ball and a rod 5 mm thick, as a
// region grown along a vessel has): relaxed with the skeleton in place it settles with
// every particle near its lattice site; the cohesion alone, a surface tension, makes the
// rod flow.
TEST(ModelStage, ARodTwoParticlesThickKeepsItsShapeWhileTheSkeletonHoldsIt) {
  const geometry::Shape organ =
      organ_of({90, 40, 40}, Eigen::Vector3d(-20, -20, -20), [](const Eigen::Vector3d& p) {
        return p.norm() <= 14 || (p.x() > 0 && p.x() < 66 && p.tail<2>().norm() <= 2.5);
      });
  auto relaxed = [&](bool skeleton) {
    ModelStageOptions o = model_stage_options_from(
        parse(fmt::format("body:\nmodel:\n  radius_mm: 1.25\n  skeleton: {}\n", skeleton)));
    return run_model_stage(o, &organ).summary;
  };
  const nlohmann::json held = relaxed(true), free = relaxed(false);
  const double spacing_mm = held["lattice_spacing_mm"].get<double>();  // 2.44
  EXPECT_TRUE(held["relax_settled"].get<bool>());
  EXPECT_LT(held["relax_steps"].get<int>(), 1000);
  EXPECT_LT(held["relax_largest_move_mm"].get<double>(), 0.5 * spacing_mm);
  EXPECT_GT(free["relax_largest_move_mm"].get<double>(), spacing_mm);
}

// Two balls joined by a bridge one voxel thick (as a grown organ joins what it leaked
// into): the mask is one piece, the particles at least two, and the summary says both
// (the run warns of it).
TEST(ModelStage, ABridgeThinnerThanTheParticlesLeavesTwoPiecesAndSaysSo) {
  const geometry::Shape organ =
      organ_of({60, 24, 24}, Eigen::Vector3d(-30, -12, -12), [](const Eigen::Vector3d& p) {
        // The bridge: one row of voxels between the lattice's rows (y = -0.5 + 1.725 n mm).
        return (p - Eigen::Vector3d(-17, 0, 0)).norm() <= 9 ||
               (p - Eigen::Vector3d(17, 0, 0)).norm() <= 9 ||
               (std::abs(p.y() - 2) < 0.5 && std::abs(p.z()) < 0.5);
      });
  const ModelStageResult r = run_model_stage(
      model_stage_options_from(parse("body:\nmodel:\n  radius_mm: 1.25\n")), &organ);
  EXPECT_EQ(r.summary["organ_components"].get<int>(), 1);
  EXPECT_GE(r.summary["components"].get<int>(), 2);  // the balls, and what the rim leaves
}

/// The model stage's refusal of a scene (an InputError's text), or "no error".
std::string model_stage_error(const std::string& text) {
  try {
    run_model_stage(model_stage_options_from(parse(text)));
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

// A radius in the wrong unit (0.01 mm): sqrt(2) V / a^3 = 2.4e9 particles in 12.6 cm3 (a =
// 0.9758 r0), refused before the fill, naming the key.
TEST(ModelStage, ARadiusFillingTheBodyWithMoreThanAModelHoldsIsRefusedBeforeTheFill) {
  const std::string e =
      model_stage_error("body:\n  size_mm: [40, 30, 20]\nmodel:\n  radius_mm: 0.01\n");
  EXPECT_NE(e.find("/s.yaml:4: model.radius_mm: a radius of 0.01 mm fills this organ with about "
                   "2.4e+09 particles"),
            std::string::npos)
      << e;
}

TEST(ModelStage, ABodyTooSmallForOneParticleIsABadInputNamingTheKey) {
  const std::string e = model_stage_error("body:\n  size_mm: [1, 1, 1]\nmodel:\n  radius_mm: 5\n");
  EXPECT_NE(e.find("/s.yaml:2: body.size_mm:"), std::string::npos) << e;
}

}  // namespace
}  // namespace organfit::pipeline
