#pragma once
// The organ model (METHOD.md s.2): particles filling the organ at the relaxed fcc spacing
// of their Lennard-Jones law, the force terms that hold them together (cohesion, and a
// skeleton inside), and the organ they stand for: its shape, the same body as a mask
// (the reference), and how that reference follows the particles once a fit moved them
// (a global map, then where the particles were placed; fitting/embedded_body.h).
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "organfit/fitting/embedded_body.h"
#include "organfit/fitting/global_fit.h"
#include "organfit/geometry/shape.h"
#include "organfit/geometry/signed_distance.h"
#include "organfit/particles/integrator.h"
#include "organfit/particles/model.h"
#include "organfit/particles/skeleton.h"

namespace organfit::fitting {

/// What a model is built with (the scene's `model` section: its keys, units and docs in
/// pipeline/scene_schema.cpp, their defaults these), kept with the model so that a saved
/// model rebuilds the same terms.
struct ModelSettings {
  /// Particle radius rho (mm); r0 = 2 rho. 0: not chosen yet, set from a particle count
  /// (radius_for_count) before a model is built.
  double radius_mm = 0.0;
  double cohesion_energy = 1.0;
  int exponent_m = 6, exponent_n = 12;
  double cutoff_r0 = 2.5, floor_r0 = 0.5, mass = 1.0, damping_ratio = 0.5, pair_damping = 0.0;
  double neighbour_skin_r0 = 0.3, time_step_fraction = 0.1;
  long long relax_steps = 5000;
  double relax_tolerance = 1e-6;
  bool skeleton = true;
  double skeleton_stiffness = 0.2, skeleton_node_spacing_r0 = 3.0, skeleton_overlap_r0 = 0.5;
  std::uint64_t seed = 1;  ///< thermostat noise
};

/// A planning model's volumes as a fit measures them before it starts (mm3, on grids of
/// `voxel_mm`, volume_voxel_mm): the organ's (organ_body) and its particles' body
/// (geometry::particle_body_volume_mm3, closed by rho). Constants of the model, measured
/// once at planning and kept in its file rather than at every session (0.07 to 0.09 s of a
/// liver's update at 54,000 particles). `fingerprint` (planning_fingerprint) is of what they
/// were measured on, so that a model they no longer describe is measured again.
struct PlanningVolumes {
  double voxel_mm = 0, organ_mm3 = 0, particle_body_mm3 = 0;
  std::uint64_t fingerprint = 0;
};

struct OrganModel {
  ModelSettings settings;
  particles::State state;
  std::unique_ptr<particles::Model> model;
  geometry::Shape shape;            ///< the body that was filled
  geometry::LabelVolume reference;  ///< the same body as a mask (voxels of r0/4)
  double lattice_spacing_mm = 0;    ///< relaxed fcc nearest-neighbour distance
  particles::CohesionParams cohesion;
  particles::SkeletonForce* skeleton = nullptr;  ///< owned by `model`; null without skeleton
  particles::SkeletonParams skeleton_params;
  double skeleton_node_spacing_mm = 0;
  /// How the reference follows the particles (fitting/embedded_body.h): the fit's global
  /// map and where it placed the particles (empty: they are where the model put them).
  GlobalMap global_map;
  particles::Positions placed;
  /// The planning organ as organ_body tests it (the shape's mask, or `reference` for an
  /// analytic body) and its unsmoothed signed distance: made on first use, then shared by
  /// every organ_body of this model (a cache, hence mutable; copies share it).
  mutable std::shared_ptr<const geometry::LabelVolume> planning_mask;
  mutable std::shared_ptr<const geometry::SignedDistance> planning_distance;
  /// The planning organ's volume levels (mm, geometry::SignedDistance::volume_levels) as a
  /// saved model recorded them: its distance takes them rather than finding them again.
  std::optional<geometry::SignedDistance::VolumeLevels> saved_planning_levels;
  /// The planning volumes as a saved model recorded them: planning_volumes takes them while
  /// they still describe the model.
  std::optional<PlanningVolumes> saved_planning_volumes;
};

/// The particle radius (mm) that fills `shape` with about `count` particles at the law's
/// relaxed fcc spacing (model.particles), from the body's volume: within 5% for rounded
/// bodies; a box whose faces lie on lattice planes gets 10 to 18% more.
double radius_for_count(const ModelSettings& settings, const geometry::Shape& shape,
                        long long count);

/// About how many particles an fcc lattice at `settings.radius_mm` puts in `shape` (its
/// volume over a lattice site's, a^3 / sqrt(2)): radius_for_count's inverse, to refuse a
/// radius that would fill an organ with billions before the fill starts.
double particle_count_at(const ModelSettings& settings, const geometry::Shape& shape);

/// Cohesion law and integrator settings of a model.
particles::CohesionParams cohesion_params_from(const ModelSettings& s);
particles::IntegratorOptions integrator_options_from(const ModelSettings& s,
                                                     const particles::Model& model);

/// Voxel (mm) of the organ's grids made from its particles' size (the reference body, the
/// volume measures made in every fit): half the particle radius, but coarse enough that
/// the organ holds at most about 8 million voxels (a voxel count's error is about its
/// surface voxels over its volume: 0.1% there), so that a model of small particles in a
/// large organ is not held on a grid of 10^8 voxels.
double volume_voxel_mm(double rho_mm, double organ_volume_mm3);

/// The reference body of a shape: a mask covering it on a grid of volume_voxel_mm (r0/4
/// below 8e6 (r0/4)^3 of organ).
geometry::LabelVolume reference_body(const geometry::Shape& shape, double r0_mm);

/// The model's force terms (cohesion, and the skeleton when `skeleton` has nodes) around
/// given positions: what the model stage builds, and what loading a saved model rebuilds.
/// Fills model.model, model.skeleton, model.skeleton_params and
/// model.skeleton_node_spacing_mm from model.settings and model.state.
void build_model_terms(OrganModel& model, const particles::Skeleton* skeleton);
/// Ties model.state's current positions (the rest shape) to `skeleton`.
void add_skeleton_term(OrganModel& model, const particles::Skeleton& skeleton);

/// A model of its own with the same particles, shape, reference and skeleton (the terms
/// rebuilt; the planning organ's cache shared): what a fit may move without moving this.
OrganModel copy_model(const OrganModel& model);

/// Whether the model carries a fit: its particles were placed by a global map (`placed`,
/// one per particle) and its reference follows them (embedded_body.h).
bool carries_fit(const OrganModel& model);

/// The organ as the model carries it now: the reference body moved with the particles
/// (at rest, the reference itself). What is exported, reported and measured.
EmbeddedBody organ_body(const OrganModel& model);
/// The same through a deformation already made (the fit's), not made again.
EmbeddedBody organ_body(const OrganModel& model, std::shared_ptr<const Deformation> deformation);

/// The planning organ's volume levels (mm): where its exported organ is cut
/// (geometry::SignedDistance::volume_levels); the saved ones when a model file gave them,
/// else found once per planning organ.
geometry::SignedDistance::VolumeLevels planning_volume_levels(const OrganModel& model);

/// A 64-bit hash of what the planning volumes are measured on: the particles' positions,
/// their radius and the reference body (its grid and voxels). About 5 ms on a 9M-voxel
/// reference.
std::uint64_t planning_fingerprint(const OrganModel& model);

/// The model's volumes before a fit: the saved ones when their fingerprint is the model's
/// and it carries no fit (no embedding), else measured (a fitted organ's measure differs by
/// its deformation's pull-backs, and the fit measures it after).
PlanningVolumes planning_volumes(const OrganModel& model);

/// The unsigned distance (mm) of each column of `points_mm` (3 x n, patient mm) to the
/// planning organ's surface: |beyond_level(p)| of its signed distance at its volume level (the
/// surface organ_body exports at phi = identity). Beyond the distance's grid, its value at
/// the grid's nearest point plus the way there.
std::vector<double> planning_surface_distance_mm(const OrganModel& model,
                                                 const Eigen::Matrix3Xd& points_mm);

}  // namespace organfit::fitting
