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

/// Fills the organ (when given, e.g. imported from CT) or the scene's analytic body with
/// particles at the relaxed fcc spacing and relaxes them.
ModelStageResult run_model_stage(const config::Scene& scene,
                                 const geometry::Shape* organ = nullptr);

}  // namespace organfit::pipeline
