#pragma once
// The model stage: fill the organ with particles and relax them (physics core).
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>

#include "organfit/config/scene.h"
#include "organfit/fitting/organ_model.h"

namespace organfit::pipeline {

using fitting::ModelSettings;

/// The scene's `model` section as settings.
ModelSettings model_settings_from(const config::Scene& scene);
/// As JSON, with the scene's key names; and back (throws InputError naming `where` and
/// the key when one is missing or of the wrong type).
nlohmann::json to_json(const ModelSettings& s);
ModelSettings model_settings_from_json(const nlohmann::json& j, const std::string& where);

/// The model stage's result: the organ model, and what run.json's "model" says of it.
struct ModelStageResult : fitting::OrganModel {
  nlohmann::json summary;
};

/// The particles a model holds when its scene gives no radius (model.particles' default).
/// Chosen on organs apart from those the benchmarks report on (scripts/particle_count_sweep.sh
/// tune: an ellipsoid of 5 cm3, both kidneys, a vertebra, the liver, an ellipsoid of 3 L) as
/// the least of 1,000, 3,000, 10,000 and 30,000 at which every one of them is within 0.05 mm
/// MSD of its best count; its update is 0.5 to 1.2 s there (docs/benchmarks.md).
constexpr long long kDefaultParticleCount = 10000;
/// The most particles a model is built with (model.particles' range; a radius that would
/// fill the organ with more is refused before the fill).
constexpr long long kMostParticles = 20000000;

/// The model stage's settings: the model's, the particle count asked for, and the
/// analytic body to fill when there is no organ.
struct ModelStageOptions {
  ModelSettings settings;
  /// About this many particles (the radius follows the body's volume) when settings.radius_mm
  /// is 0; ignored otherwise.
  long long particles = kDefaultParticleCount;
  std::string body_shape;  ///< body.shape ("" without a body section)
  Eigen::Vector3d body_size_mm = Eigen::Vector3d::Ones(), body_centre_mm = Eigen::Vector3d::Zero();
  /// The keys a body too small for two particles is blamed on: an organ's model.radius_mm
  /// (or model.particles when the count sets the radius), an analytic body's body.size_mm.
  config::KeyRef radius_key, body_size_key;
};
ModelStageOptions model_stage_options_from(const config::Scene& scene);

/// Fills the organ (when given, e.g. imported from CT) or the options' analytic body with
/// particles at the relaxed fcc spacing and relaxes them.
ModelStageResult run_model_stage(const ModelStageOptions& options,
                                 const geometry::Shape* organ = nullptr);

}  // namespace organfit::pipeline
