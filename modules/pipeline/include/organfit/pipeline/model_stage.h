#pragma once
// The model stage: fill the organ with particles and relax them (physics core).
#include <nlohmann/json.hpp>

#include "organfit/config/scene.h"
#include "organfit/evaluation/synthetic.h"
#include "organfit/particles/skeleton.h"
#include "organfit/particles/integrator.h"
#include "organfit/particles/model.h"

namespace organfit::pipeline {

/// Cohesion law and integrator settings from the scene's `model` section.
particles::CohesionParams cohesion_params_from(const config::Scene& scene);
particles::IntegratorOptions integrator_options_from(const config::Scene& scene,
                                                     const particles::Model& model);

struct ModelStageResult {
  particles::State state;
  std::unique_ptr<particles::Model> model;
  evaluation::Shape shape;               ///< the body that was filled
  geometry::LabelVolume reference;       ///< the same body as a mask (voxels of rho/2)
  double lattice_spacing_mm = 0;         ///< relaxed fcc nearest-neighbour distance
  particles::CohesionParams cohesion;
  particles::SkeletonForce* skeleton = nullptr;  ///< owned by `model`; null without skeleton
  particles::SkeletonParams skeleton_params;
  nlohmann::json summary;  ///< run.json "model" block
};

/// Fills the organ (when given, e.g. imported from CT) or the scene's analytic body with
/// particles at the relaxed fcc spacing and relaxes them.
ModelStageResult run_model_stage(const config::Scene& scene, const evaluation::Shape* organ = nullptr);

}  // namespace organfit::pipeline
