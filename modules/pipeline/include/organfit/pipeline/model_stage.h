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

/// The model stage's settings: the model's, the particle count asked for, and the
/// analytic body to fill when there is no organ.
struct ModelStageOptions {
  ModelSettings settings;
  long long particles = 0;  ///< model.particles: about this many (the radius follows); 0: radius_mm
  std::string body_shape;   ///< body.shape ("" without a body section)
  Eigen::Vector3d body_size_mm = Eigen::Vector3d::Ones(), body_centre_mm = Eigen::Vector3d::Zero();
  /// The keys a body too small for two particles is blamed on: an organ's model.radius_mm,
  /// an analytic body's body.size_mm.
  config::KeyRef radius_key, body_size_key;
};
ModelStageOptions model_stage_options_from(const config::Scene& scene);

/// Fills the organ (when given, e.g. imported from CT) or the options' analytic body with
/// particles at the relaxed fcc spacing and relaxes them.
ModelStageResult run_model_stage(const ModelStageOptions& options,
                                 const geometry::Shape* organ = nullptr);

}  // namespace organfit::pipeline
