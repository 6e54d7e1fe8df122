#pragma once
// The model stage: fill the organ with particles and relax them (physics core).
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>

#include "organfit/config/scene.h"
#include "organfit/evaluation/synthetic.h"
#include "organfit/fitting/embedded_body.h"
#include "organfit/particles/integrator.h"
#include "organfit/particles/model.h"
#include "organfit/particles/skeleton.h"

namespace organfit::pipeline {

/// The scene's `model` section as plain values (keys and meanings: scene_schema.cpp),
/// so that a saved planning model carries the settings it was built with.
struct ModelSettings {
  double radius_mm = 0, cohesion_energy = 0;
  int exponent_m = 0, exponent_n = 0;
  double cutoff_r0 = 0, floor_r0 = 0, mass = 0, damping_ratio = 0, pair_damping = 0;
  double neighbour_skin_r0 = 0, time_step_fraction = 0;
  long long relax_steps = 0;
  double relax_tolerance = 0;
  bool skeleton = false;
  double skeleton_stiffness = 0, skeleton_node_spacing_r0 = 0, skeleton_overlap_r0 = 0;
  std::uint64_t seed = 0;  ///< the scene's seed (thermostat noise)
};
ModelSettings model_settings_from(const config::Scene& scene);
/// The particle radius (mm) that fills `shape` with about `count` particles at the law's
/// relaxed fcc spacing (model.particles), from the body's volume: within 5% for rounded
/// bodies; a box whose faces lie on lattice planes gets 10 to 18% more.
double radius_for_count(const ModelSettings& settings, const evaluation::Shape& shape,
                        long long count);
/// As JSON, with the scene's key names; and back (throws InputError naming `where` and
/// the key when one is missing or of the wrong type).
nlohmann::json to_json(const ModelSettings& s);
ModelSettings model_settings_from_json(const nlohmann::json& j, const std::string& where);

/// Cohesion law and integrator settings of a model.
particles::CohesionParams cohesion_params_from(const ModelSettings& s);
particles::IntegratorOptions integrator_options_from(const ModelSettings& s,
                                                     const particles::Model& model);

struct ModelStageResult {
  ModelSettings settings;
  particles::State state;
  std::unique_ptr<particles::Model> model;
  evaluation::Shape shape;          ///< the body that was filled
  geometry::LabelVolume reference;  ///< the same body as a mask (voxels of rho/2)
  double lattice_spacing_mm = 0;    ///< relaxed fcc nearest-neighbour distance
  particles::CohesionParams cohesion;
  particles::SkeletonForce* skeleton = nullptr;  ///< owned by `model`; null without skeleton
  particles::SkeletonParams skeleton_params;
  double skeleton_node_spacing_mm = 0;
  nlohmann::json summary;  ///< run.json "model" block
  /// How the reference follows the particles (fitting/embedded_body.h): the fit's global
  /// map and where it placed the particles (empty: they are where the model put them).
  fitting::GlobalMap global_map;
  particles::Positions placed;
  /// The planning organ as organ_body tests it (the shape's mask, or `reference` for an
  /// analytic body) and its unsmoothed signed distance: made on first use, then shared by
  /// every organ_body of this model (a cache, hence mutable; copies share it).
  mutable std::shared_ptr<const geometry::LabelVolume> planning_mask;
  mutable std::shared_ptr<const geometry::SignedDistance> planning_distance;
};

/// The organ as the model carries it now: the reference body moved with the particles
/// (at rest, the reference itself). What is exported, reported and measured.
fitting::EmbeddedBody organ_body(const ModelStageResult& model);
/// The same through a deformation already made (the fit's), not made again.
fitting::EmbeddedBody organ_body(const ModelStageResult& model,
                                 std::shared_ptr<const fitting::Deformation> deformation);

/// Fills the organ (when given, e.g. imported from CT) or the scene's analytic body with
/// particles at the relaxed fcc spacing and relaxes them.
ModelStageResult run_model_stage(const config::Scene& scene,
                                 const evaluation::Shape* organ = nullptr);

/// The model's force terms (cohesion, and the skeleton when `skeleton` has nodes) around
/// given positions: what run_model_stage builds, and what loading a saved model rebuilds.
/// Fills result.model, result.skeleton, result.skeleton_params and
/// result.skeleton_node_spacing_mm from result.settings and result.state.
void build_model_terms(ModelStageResult& result, const particles::Skeleton* skeleton);
/// Ties result.state's current positions (the rest shape) to `skeleton`.
void add_skeleton_term(ModelStageResult& result, const particles::Skeleton& skeleton);

/// The reference body of a shape: a mask on a grid of r0/4 covering it.
geometry::LabelVolume reference_body(const evaluation::Shape& shape, double r0_mm);

}  // namespace organfit::pipeline
