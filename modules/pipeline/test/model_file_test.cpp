// The planning model file: what is saved is what is loaded, and bad files are refused
// with one line naming the file.
#include "organfit/pipeline/model_file.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <fstream>
#include <iterator>

#include "organfit/fitting/organ_model.h"
#include "organfit/geometry/signed_distance.h"
#include "organfit/pipeline/scene_schema.h"
#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::pipeline {
namespace {

class ModelFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("organfit_model_" + std::to_string(getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  ModelStageResult build(const std::string& body) {
    const config::Scene scene = config::parse_scene(
        "scene:\n  seed: 4\n" + body + "model:\n  radius_mm: 2.0\n  skeleton_stiffness: 0.3\n",
        dir_ / "s.yaml", scene_schema());
    check_scene_rules(scene);
    return run_model_stage(model_stage_options_from(scene));
  }
  std::string error_of(const std::string& content) {
    std::ofstream(dir_ / "bad.json") << content;
    try {
      load_model(dir_ / "bad.json");
    } catch (const InputError& e) {
      return e.what();
    }
    return "no error";
  }
  // A saved model as a test edits it: its checksum dropped, as a file written before
  // organfit kept one (read with a warning), so that what is refused is what the edit made
  // wrong rather than the edit itself.
  static nlohmann::json edited(const fs::path& file) {
    nlohmann::json j = nlohmann::json::parse(std::ifstream(file));
    j.erase("checksum");
    return j;
  }
  fs::path dir_;
};

TEST_F(ModelFile, SavedAndLoadedModelsAreTheSame) {
  ModelStageResult m = build("body:\n  shape: egg\n  size_mm: [30, 24, 20]\n");
  ASSERT_NE(m.skeleton, nullptr);
  const CtReference ct{"/data/ct", "1.2.3", "1.2.4", ""};
  save_model(dir_ / "m.json", m, "Prostate", OrganLook{{12, 34, 56}, "GTV"}, ct,
             {{"scene", "t"}, {"modelling_wall_s", 1.5}});
  SavedModel back = load_model(dir_ / "m.json");
  EXPECT_EQ(back.organ_name, "Prostate");
  EXPECT_EQ(back.organ_look.colour, (std::array<int, 3>{12, 34, 56}));  // the source ROI's look
  EXPECT_EQ(back.organ_look.interpreted_type, "GTV");
  ASSERT_TRUE(back.ct.has_value());
  EXPECT_EQ(back.ct->series_instance_uid, "1.2.3");
  EXPECT_EQ(back.provenance.value("modelling_wall_s", 0.0), 1.5);
  ASSERT_EQ(back.model.state.size(), m.state.size());
  EXPECT_EQ((back.model.state.x - m.state.x).cwiseAbs().maxCoeff(), 0.0);  // bit for bit
  EXPECT_EQ(back.model.lattice_spacing_mm, m.lattice_spacing_mm);
  EXPECT_EQ(back.model.settings.seed, 4u);
  EXPECT_EQ(back.model.settings.skeleton_stiffness, 0.3);
  ASSERT_NE(back.model.skeleton, nullptr);
  EXPECT_EQ(back.model.skeleton->skeleton().nodes_mm, m.skeleton->skeleton().nodes_mm);
  EXPECT_EQ(back.model.skeleton_params.stiffness, m.skeleton_params.stiffness);
  EXPECT_EQ(back.model.reference.labels, m.reference.labels);  // the same reference body
  EXPECT_EQ(back.model.model->terms().size(), m.model->terms().size());
  // The rebuilt force terms give the same forces.
  particles::Forces fa, fb;
  const double ea = m.model->compute_forces(m.state, fa, true);
  const double eb = back.model.model->compute_forces(back.model.state, fb, true);
  EXPECT_NEAR(ea, eb, 1e-9 * std::abs(ea));
  EXPECT_LT((fa - fb).cwiseAbs().maxCoeff(), 1e-9);
  // The volumes a fit starts from, measured at planning, kept to the bit and taken by a
  // session (the loaded model's fingerprint is the saved one's: its positions the same).
  const fitting::PlanningVolumes planned = fitting::planning_volumes(m);
  ASSERT_TRUE(back.model.saved_planning_volumes.has_value());
  const fitting::PlanningVolumes& kept = *back.model.saved_planning_volumes;
  EXPECT_EQ(kept.voxel_mm, planned.voxel_mm);
  EXPECT_EQ(kept.organ_mm3, planned.organ_mm3);
  EXPECT_EQ(kept.particle_body_mm3, planned.particle_body_mm3);
  EXPECT_EQ(kept.fingerprint, planned.fingerprint);
  EXPECT_EQ(fitting::planning_fingerprint(back.model), planned.fingerprint);
  // A file written before they were kept loads; its session measures them.
  nlohmann::json j = edited(dir_ / "m.json");
  j["organ"].erase("planning_volumes");
  std::ofstream(dir_ / "old.json") << j.dump();
  const SavedModel old = load_model(dir_ / "old.json");
  EXPECT_FALSE(old.model.saved_planning_volumes.has_value());
  EXPECT_EQ(fitting::planning_volumes(old.model).organ_mm3, planned.organ_mm3);
}

TEST_F(ModelFile, AFittedModelKeepsHowItsOrganFollowsTheParticles) {
  ModelStageResult m = build("body:\n  shape: ellipsoid\n  size_mm: [30, 24, 20]\n");
  // As a fit leaves it: a global map, particles placed by it, then moved locally.
  m.global_map.affine.a = Eigen::Vector3d(1.2, 1 / std::sqrt(1.2), 1 / std::sqrt(1.2)).asDiagonal();
  m.global_map.affine.t = Eigen::Vector3d(0.5, -1, 2);
  m.global_map.shears.c(3) = 0.003;
  m.global_map.shears.c(11) = -0.002;  // the second y shear (a twist's third)
  m.global_map.fields = fitting::ShearFields::over({-18, -15, -13}, {18, 15, 13}, 8.0);
  for (Eigen::Index i = 0; i < m.global_map.fields.weights.size(); ++i)
    m.global_map.fields.weights(i) = 0.5 * std::sin(0.7 * static_cast<double>(i));  // mm
  m.global_map.flow = fitting::IncompressibleFlow::over({-18, -15, -13}, {18, 15, 13}, 10.0);
  for (Eigen::Index i = 0; i < m.global_map.flow.potentials.size(); ++i)
    m.global_map.flow.potentials(i) = 0.8 * std::cos(0.3 * static_cast<double>(i));  // mm
  m.placed = m.state.x;
  for (Eigen::Index i = 0; i < m.placed.cols(); ++i)
    m.placed.col(i) = m.global_map.apply(m.state.x.col(i));
  m.state.x = m.placed;
  m.state.x.row(1).array() += 0.4;
  save_model(dir_ / "fitted.json", m, "Prostate", OrganLook{}, std::nullopt, {});
  SavedModel back = load_model(dir_ / "fitted.json");
  // A fitted organ's volumes are not a planning model's: its file keeps none.
  EXPECT_FALSE(back.model.saved_planning_volumes.has_value());
  EXPECT_EQ(back.model.global_map.fields.weights, m.global_map.fields.weights);
  EXPECT_EQ(back.model.global_map.flow.potentials, m.global_map.flow.potentials);
  EXPECT_EQ(back.model.global_map.flow.count, m.global_map.flow.count);
  EXPECT_EQ(back.model.global_map.shears.c, m.global_map.shears.c);
  const fitting::EmbeddedBody a = organ_body(m), b = organ_body(back.model);
  for (const Eigen::Vector3d& q :
       {Eigen::Vector3d(0, 0.4, 2), Eigen::Vector3d(16, -1, 1), Eigen::Vector3d(-3, 11, 2)})
    EXPECT_LT((a.pull_back(q) - b.pull_back(q)).norm(), 1e-12);
  // Not the planning organ any more: it moved 0.4 mm in y.
  EXPECT_NEAR(
      (a.pull_back(Eigen::Vector3d(0, 0.4, 2)) - m.global_map.inverse(Eigen::Vector3d(0, 0, 2)))
          .norm(),
      0, 1e-6);
  // Shear fields whose heights do not match their grid are refused, naming the key.
  nlohmann::json j = edited(dir_ / "fitted.json");
  j["embedding"]["global_shear_fields"]["weights_mm"].erase(0);
  EXPECT_NE(error_of(j.dump()).find("bad.json: embedding.global_shear_fields.weights_mm needs"),
            std::string::npos)
      << error_of(j.dump());
  // Likewise a flow's potentials.
  j = edited(dir_ / "fitted.json");
  j["embedding"]["global_flow"]["potentials_mm"].erase(0);
  EXPECT_NE(error_of(j.dump()).find("bad.json: embedding.global_flow.potentials_mm needs"),
            std::string::npos)
      << error_of(j.dump());
  // Models written before the last two shears have nine coefficients: they load, the
  // last two shears none; any other count is refused, naming the key.
  nlohmann::json old = edited(dir_ / "fitted.json");
  std::vector<double> nine = old["embedding"]["global_shears"];
  nine.resize(9);
  old["embedding"]["global_shears"] = nine;
  std::ofstream(dir_ / "old.json") << old.dump();
  const fitting::QuadraticShears loaded = load_model(dir_ / "old.json").model.global_map.shears;
  EXPECT_EQ(loaded.c(3), 0.003);
  EXPECT_TRUE(loaded.c.tail<6>().isZero(0));
  old["embedding"]["global_shears"].push_back(0.0);
  EXPECT_NE(error_of(old.dump()).find("bad.json: embedding.global_shears needs 15 numbers"),
            std::string::npos)
      << error_of(old.dump());
  // A model saved at rest has no embedding.
  ModelStageResult rest = build("body:\n  shape: ellipsoid\n  size_mm: [30, 24, 20]\n");
  save_model(dir_ / "rest.json", rest, "Prostate", OrganLook{}, std::nullopt, {});
  EXPECT_EQ(load_model(dir_ / "rest.json").model.placed.cols(), 0);
}

// A fitted model keeps what its uncertainty is given, so that an export from the file
// writes the run's sigma: the loaded one is the same function, bit for bit.
TEST_F(ModelFile, AFittedModelKeepsItsUncertainty) {
  ModelStageResult m = build("body:\n  shape: ellipsoid\n  size_mm: [30, 24, 20]\n");
  std::vector<Eigen::Vector3d> points;
  std::vector<double> residuals;
  for (int k = 0; k < 12; ++k) {
    const double a = 0.5 * k;
    points.emplace_back(15 * std::cos(a), 12 * std::sin(a), 0.3 * k);  // mm
    residuals.push_back(0.2 * std::sin(1.3 * k));                      // mm
  }
  fitting::SurfaceUncertaintyOptions o;
  o.prior_sd_mm = 1.7, o.length_mm = 7.5, o.resolution_sd_mm = 0.52;
  fitting::PriorVarianceField extra;
  extra.at_mm = Eigen::Matrix3Xd::Random(3, 30) * 15;
  extra.variance_mm2 = Eigen::VectorXd::LinSpaced(30, 0.0, 2.0);  // mm^2
  const fitting::SurfaceUncertainty u(points, o, residuals, extra);
  save_model(dir_ / "fitted.json", m, "Prostate", OrganLook{}, std::nullopt, {}, &u);
  const SavedModel back = load_model(dir_ / "fitted.json");
  ASSERT_NE(back.uncertainty, nullptr);
  EXPECT_EQ(back.uncertainty->points_mm(), u.points_mm());
  EXPECT_EQ(back.uncertainty->residuals_mm(), u.residuals_mm());
  EXPECT_EQ(back.uncertainty->options().length_mm, 7.5);
  for (int i = 0; i < 50; ++i) {
    const Eigen::Vector3d x(-20 + 0.8 * i, 10 * std::sin(0.4 * i), 5 * std::cos(0.3 * i));
    EXPECT_EQ(back.uncertainty->sd_mm(x), u.sd_mm(x)) << "at " << x.transpose();
  }
  EXPECT_EQ(back.uncertainty->far_sd_mm(), u.far_sd_mm());
  // A model saved without one (a planning model) has none.
  save_model(dir_ / "plain.json", m, "Prostate", OrganLook{}, std::nullopt, {});
  EXPECT_EQ(load_model(dir_ / "plain.json").uncertainty, nullptr);
  // Residuals that are not one per point are refused, naming the file and the key.
  nlohmann::json j = edited(dir_ / "fitted.json");
  j["uncertainty"]["residuals_mm"].erase(0);
  EXPECT_NE(error_of(j.dump()).find("bad.json: invalid model: uncertainty: "), std::string::npos)
      << error_of(j.dump());
  j = edited(dir_ / "fitted.json");
  j["uncertainty"]["points_mm"].erase(0);
  EXPECT_NE(error_of(j.dump()).find("uncertainty.points_mm needs x, y, z per point"),
            std::string::npos)
      << error_of(j.dump());
}

TEST_F(ModelFile, AMaskShapeRoundTripsThroughItsRunLengths) {
  geometry::ImageGeometry g;
  g.size = {30, 26, 12};
  g.spacing_mm = Eigen::Vector3d(1.0, 1.0, 2.5);
  g.origin_mm = Eigen::Vector3d(-15, -13, -14);
  auto mask = std::make_shared<geometry::LabelVolume>(g);
  for (int k = 2; k < 10; ++k)
    for (int j = 4; j < 22; ++j)
      for (int i = 5; i < 25; ++i)
        mask->at(i, j, k) = (i - 15) * (i - 15) + (j - 13) * (j - 13) < 64 ? 1 : 0;
  const geometry::Shape organ = geometry::make_mask_shape(mask);
  std::ofstream(dir_ / "rt.dcm") << "";  // the organ's input file must exist; it is not read here
  const config::Scene scene =
      config::parse_scene("organ:\n  roi: X\n  rtstruct: rt.dcm\nmodel:\n  radius_mm: 2.0\n",
                          dir_ / "s.yaml", scene_schema());
  const ModelStageResult m = run_model_stage(model_stage_options_from(scene), &organ);
  save_model(dir_ / "m.json", m, "X", OrganLook{}, std::nullopt, nlohmann::json::object());
  const SavedModel back = load_model(dir_ / "m.json");
  ASSERT_TRUE(back.model.shape.mask);
  EXPECT_FALSE(back.ct.has_value());
  EXPECT_EQ(back.model.shape.mask->count(1), mask->count(1));
  EXPECT_EQ(back.model.reference.labels, m.reference.labels);
  // The organ's volume levels are saved as a session would find them on the organ it
  // loads, and as the planning run finds them on the uncropped mask, to the bit; adopted,
  // not found.
  ASSERT_TRUE(back.model.saved_planning_levels.has_value());
  const geometry::SignedDistance::VolumeLevels found =
      geometry::SignedDistance(*back.model.shape.mask, false).volume_levels();
  auto same = [](const geometry::SignedDistance::VolumeLevels& a,
                 const geometry::SignedDistance::VolumeLevels& b) {
    return a.level_mm == b.level_mm && a.by_slice_phase_mm == b.by_slice_phase_mm;
  };
  EXPECT_TRUE(same(*back.model.saved_planning_levels, found));
  EXPECT_TRUE(same(fitting::planning_volume_levels(m), found));
  EXPECT_GT(std::abs(found.level_mm), 0.01);  // this organ's is not 0: the check means something
  EXPECT_TRUE(same(fitting::planning_volume_levels(back.model), found));
  // The organ a session loads is the organ planned: the same levels, the same inside test
  // (its distance made on the saved crop, the planning one's on the whole grid).
  EXPECT_EQ(organ.distance->volume_level(), found.level_mm);
  EXPECT_EQ(back.model.shape.distance->volume_level(), found.level_mm);
  int inside = 0, tried = 0;
  for (double x = -10; x <= 10; x += 0.37)
    for (const double z : {-10.2, -9.0, -7.4, -3.3, 0.0, 2.9, 4.6}) {
      ASSERT_EQ(back.model.shape.inside({x, 0.4, z}), organ.inside({x, 0.4, z})) << x << " " << z;
      inside += organ.inside({x, 0.4, z}), ++tried;
    }
  EXPECT_GT(inside, tried / 2);  // both sides of the surface asked
  EXPECT_LT(inside, tried);
  // Saved again (a fitted model is), the levels are kept, not found again.
  save_model(dir_ / "m2.json", back.model, "X", OrganLook{}, std::nullopt,
             nlohmann::json::object());
  EXPECT_TRUE(same(*load_model(dir_ / "m2.json").model.saved_planning_levels, found));
  // Files written before the levels by slice phase were kept (the single level alone) or
  // before any level was: the session finds the same levels itself, and measures the
  // planning volumes again (they were measured on the organ at its single level).
  nlohmann::json j = edited(dir_ / "m.json");
  ASSERT_TRUE(j["organ"].contains("planning_volumes"));
  j["organ"].erase("volume_level_by_slice_phase_mm");
  std::ofstream(dir_ / "single.json") << j.dump();
  j["organ"].erase("volume_level_mm");
  std::ofstream(dir_ / "old.json") << j.dump();
  for (const char* file : {"single.json", "old.json"}) {
    const SavedModel old = load_model(dir_ / file);
    EXPECT_FALSE(old.model.saved_planning_levels.has_value()) << file;
    EXPECT_FALSE(old.model.saved_planning_volumes.has_value()) << file;
    EXPECT_TRUE(same(fitting::planning_volume_levels(old.model), found)) << file;
  }
}

// The file's checksum covers every byte before it: an edit that leaves a valid, plausible
// model (a position's digit, the mask moved 3 mm) is refused, as is the file rewritten by
// another JSON writer; a file without a checksum is read, and said to be unchecked.
TEST_F(ModelFile, AFileChangedAfterItWasWrittenIsRefused) {
  const ModelStageResult m = build("body:\n  shape: egg\n  size_mm: [30, 24, 20]\n");
  save_model(dir_ / "m.json", m, "X", OrganLook{}, std::nullopt, nlohmann::json::object());
  const SavedModel as_written = load_model(dir_ / "m.json");
  EXPECT_TRUE(as_written.checksum_verified);
  EXPECT_EQ(unchecked_model_warning(dir_ / "m.json", as_written), "");
  std::ifstream in(dir_ / "m.json", std::ios::binary);
  const std::string text{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  ASSERT_EQ(text.substr(text.size() - 32, 13), ",\"checksum\":\"");  // last, as documented
  const std::string f = (dir_ / "bad.json").string();
  const std::string changed = f +
                              ": the file was changed or damaged after organfit wrote it (its "
                              "checksum does not match its content): use the file as written, "
                              "or plan again";
  // One digit of the first position, the file still valid JSON.
  const size_t at = text.find("\"positions_mm\":[") + 16;
  ASSERT_TRUE(std::isdigit(static_cast<unsigned char>(text[at + 1])));
  std::string digit = text;
  digit[at + 1] = digit[at + 1] == '1' ? '2' : '1';
  ASSERT_TRUE(nlohmann::json::accept(digit));
  EXPECT_EQ(error_of(digit), changed);
  // A byte after the checksum is not covered by it, and is not there to change: the text
  // ends with the checksum's object and a line end.
  EXPECT_EQ(text.back(), '\n');
  // Rewritten by another writer (keys sorted, spaces): its checksum is not where organfit
  // writes it.
  const nlohmann::json j = nlohmann::json::parse(text);
  EXPECT_NE(error_of(j.dump(2)).find(": checksum: not 16 hexadecimal digits as organfit writes"),
            std::string::npos)
      << error_of(j.dump(2));
  // Without a checksum: read as it is, and said to be.
  std::ofstream(dir_ / "old.json") << edited(dir_ / "m.json").dump();
  const SavedModel old = load_model(dir_ / "old.json");
  EXPECT_FALSE(old.checksum_verified);
  EXPECT_EQ((old.model.state.x - m.state.x).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_NE(unchecked_model_warning(dir_ / "old.json", old)
                .find("old.json: the model file has no checksum"),
            std::string::npos);
}

TEST_F(ModelFile, BadFilesAreRefusedNamingTheFile) {
  const std::string f = (dir_ / "bad.json").string();
  EXPECT_EQ(error_of("not json"), f + ": not an organfit model (not JSON)");
  EXPECT_EQ(error_of("{\"format\": \"x\"}"),
            f + ": not an organfit model (no 'format: organfit-model')");
  EXPECT_EQ(error_of("{\"format\": \"organfit-model\", \"format_version\": 9}"),
            f + ": model format version 9 is not 1 (made by another organfit version)");
  const ModelStageResult m = build("body:\n");
  save_model(dir_ / "m.json", m, "X", OrganLook{}, std::nullopt, nlohmann::json::object());
  nlohmann::json j = edited(dir_ / "m.json");
  j["particles"] = j["particles"].get<int>() + 1;
  EXPECT_NE(error_of(j.dump()).find("particles but"), std::string::npos);
  j = edited(dir_ / "m.json");
  j["settings"].erase("mass");
  EXPECT_EQ(error_of(j.dump()), f + ": model setting 'mass' is missing or not a number");
  j = edited(dir_ / "m.json");
  j["settings"]["radius_mm"] = -1;  // within the range the scene key declares
  EXPECT_EQ(error_of(j.dump()), f + ": model setting 'radius_mm' is -1, out of range [0, 100]");
  j = edited(dir_ / "m.json");
  j["settings"]["time_step_fraction"] = 1e-300;
  EXPECT_EQ(error_of(j.dump()), "no error");
  j["settings"]["time_step_fraction"] = 0.95;
  EXPECT_EQ(error_of(j.dump()),
            f + ": model setting 'time_step_fraction' is 0.95, out of range (0, 0.9]");
  j = edited(dir_ / "m.json");
  j["format"] = 1e-300;
  EXPECT_EQ(error_of(j.dump()), f + ": not an organfit model (no 'format: organfit-model')");
  j = edited(dir_ / "m.json");
  j["organ"]["colour"] = {255, 0, 3.5};
  EXPECT_EQ(error_of(j.dump()), f + ": organ.colour: three integers from 0 to 255");
  j = edited(dir_ / "m.json");
  j["shape"]["kind"] = "mask";  // this model's shape is an analytic body: no mask in the file
  EXPECT_EQ(error_of(j.dump()), f + ": shape: a mask is given exactly when shape.kind is 'mask'");
  j["shape"]["kind"] = 1e308;
  EXPECT_EQ(error_of(j.dump()), f + ": shape.kind: the organ's kind of shape, a text");
  j = edited(dir_ / "m.json");
  j["format_version"] = nullptr;
  EXPECT_EQ(error_of(j.dump()),
            f + ": model format version null is not 1 (made by another organfit version)");
  j = edited(dir_ / "m.json");
  j["provenance"] = 3.5;
  EXPECT_EQ(error_of(j.dump()),
            f + ": provenance: an object whose modelling_wall_s is a number and scene a text");
  j["provenance"] = {{"modelling_wall_s", "1 s"}};
  EXPECT_EQ(error_of(j.dump()),
            f + ": provenance: an object whose modelling_wall_s is a number and scene a text");
  j = edited(dir_ / "m.json");
  j["organ"]["volume_level_mm"] = 40.0;  // farther than a voxel: not this organ's level
  EXPECT_EQ(error_of(j.dump()),
            f + ": organ.volume_level_mm: not finite, or farther from 0 than a voxel");
  j = edited(dir_ / "m.json");
  j["organ"]["volume_level_by_slice_phase_mm"][2] = -40.0;
  EXPECT_EQ(error_of(j.dump()), f + ": organ.volume_level_by_slice_phase_mm: not finite, or "
                                    "farther from 0 than a voxel");
  j["organ"]["volume_level_by_slice_phase_mm"] = {0.01, 0.02, 0.03};
  EXPECT_EQ(error_of(j.dump()), f + ": organ.volume_level_by_slice_phase_mm needs 4 numbers");
  j["organ"]["volume_level_by_slice_phase_mm"] = {0.01, 0.02, 0.03, "0.04"};
  EXPECT_EQ(error_of(j.dump()), f + ": organ.volume_level_by_slice_phase_mm needs 4 numbers");
  j["organ"]["volume_level_by_slice_phase_mm"] = {0.01, 0.02, 0.03, 0.04};
  j["organ"].erase("volume_level_mm");
  EXPECT_EQ(error_of(j.dump()), f + ": organ.volume_level_by_slice_phase_mm is given without "
                                    "organ.volume_level_mm");
  j = edited(dir_ / "m.json");
  j["organ"]["planning_volumes"]["organ_mm3"] = -5.0;
  EXPECT_EQ(error_of(j.dump()), f + ": organ.planning_volumes: voxel_mm, organ_mm3 and "
                                    "particle_body_mm3 must be > 0");
  j = edited(dir_ / "m.json");
  j["organ"]["planning_volumes"]["fingerprint"] = "-00000000000001f";
  EXPECT_EQ(error_of(j.dump()),
            f + ": organ.planning_volumes.fingerprint needs 16 hexadecimal digits");
  // The organ's box and the reference's volume, written for the reader, are read too: a
  // file with them broken or not matching its shape is refused.
  j = edited(dir_ / "m.json");
  j["shape"]["size_mm"] = {1.0, 2.0};
  EXPECT_EQ(error_of(j.dump()), f + ": shape.size_mm needs 3 numbers");
  j["shape"]["size_mm"] = {1.0, 2.0, -1e308};
  EXPECT_EQ(error_of(j.dump()), f + ": shape.size_mm must be > 0 along each axis");
  j = edited(dir_ / "m.json");
  j["shape"]["centre_mm"] = {0.0, "x", 1.0};
  EXPECT_EQ(error_of(j.dump()), f + ": shape.centre_mm needs 3 numbers");
  j = edited(dir_ / "m.json");
  const double volume = j["organ"]["reference_volume_mm3"].get<double>();
  j["organ"]["reference_volume_mm3"] = nlohmann::json::object();
  EXPECT_NE(error_of(j.dump()).find(f + ": organ.reference_volume_mm3: {} in the file, but its "
                                        "shape gives "),
            std::string::npos);
  j["organ"]["reference_volume_mm3"] = volume * 1.001;
  EXPECT_NE(error_of(j.dump()).find("(the file was changed, or made by an organfit that built "
                                    "the reference otherwise: plan again)"),
            std::string::npos);
  j["organ"]["reference_volume_mm3"] = volume;
  EXPECT_EQ(error_of(j.dump()), "no error");
  EXPECT_NE(error_of("").find(f + ": not an organfit model"), std::string::npos);
}

}  // namespace
}  // namespace organfit::pipeline
