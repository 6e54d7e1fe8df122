#include "organfit/fitting/organ_model.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <optional>
#include <stdexcept>

#include "organfit/geometry/counter_random.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/particles/cohesion_force.h"
#include "organfit/particles/lattice_fill.h"

namespace organfit::fitting {

particles::CohesionParams cohesion_params_from(const ModelSettings& s) {
  if (!(s.radius_mm > 0.0))
    throw std::invalid_argument(
        "model settings: radius_mm must be positive (0 is set from a "
        "particle count, radius_for_count, before a model is built)");
  particles::CohesionParams p;
  p.E0 = s.cohesion_energy;
  p.r0_mm = 2.0 * s.radius_mm;
  p.m = s.exponent_m;
  p.n = s.exponent_n;
  p.cutoff_r0 = s.cutoff_r0;
  p.floor_r0 = s.floor_r0;
  return p;
}

particles::IntegratorOptions integrator_options_from(const ModelSettings& s,
                                                     const particles::Model& model) {
  particles::IntegratorOptions opt;
  opt.time_step_fraction = s.time_step_fraction;
  opt.damping = s.damping_ratio * 2.0 * std::sqrt(model.stiffness() * model.mass());
  opt.length_scale_mm = 2.0 * model.radius_mm();
  // No particle may carry more than 5 well depths of kinetic energy (see IntegratorOptions).
  opt.max_speed_mm_s = std::sqrt(2.0 * 5.0 * s.cohesion_energy / model.mass());
  opt.seed = s.seed;
  return opt;
}

namespace {
/// A shape's volume (mm^3): a mask's own voxels, or an analytic shape sampled with
/// `samples` voxels along its largest extent.
double shape_volume(const geometry::Shape& shape, double samples) {
  const Eigen::Vector3d extent = shape.bounds().max_mm - shape.bounds().min_mm;
  return shape.mask
             ? shape.mask->volume_mm3(1)
             : geometry::shape_volume_mm3(shape, std::max(0.05, extent.maxCoeff() / samples));
}
}  // namespace

double volume_voxel_mm(double rho, double organ_volume_mm3) {
  return std::max(0.5 * rho, std::cbrt(organ_volume_mm3 / 8e6));
}

geometry::LabelVolume reference_body(const geometry::Shape& shape, double r0_mm) {
  // The volume to within a few percent is enough (its cube root sets the voxel).
  const geometry::ImageGeometry g = geometry::grid_covering(
      shape.bounds(), volume_voxel_mm(0.5 * r0_mm, shape_volume(shape, 100)), 0.5 * r0_mm);
  // By blocks (15M voxels for a million-particle body's reference).
  return geometry::shape_on_grid(shape, g, geometry::whole_range(g));
}

void build_model_terms(OrganModel& model, const particles::Skeleton* skeleton) {
  const ModelSettings& s = model.settings;
  const particles::CohesionParams cp = cohesion_params_from(s);
  const particles::LennardJones law(cp);
  model.cohesion = cp;
  model.model = std::make_unique<particles::Model>(model.state.size(), s.mass, 0.5 * cp.r0_mm);
  model.model->add(std::make_unique<particles::CohesionForce>(law, s.neighbour_skin_r0 * cp.r0_mm,
                                                              s.pair_damping));
  model.skeleton_node_spacing_mm = s.skeleton_node_spacing_r0 * cp.r0_mm;
  model.skeleton_params.stiffness = s.skeleton_stiffness * law.stiffness();
  model.skeleton_params.overlap_mm = s.skeleton_overlap_r0 * cp.r0_mm;
  model.skeleton = nullptr;
  if (skeleton && skeleton->node_count() > 0) add_skeleton_term(model, *skeleton);
}

namespace {
/// The planning organ itself when it is a mask (on the CT's grid: phi = identity gives it
/// voxel for voxel); an analytic body as its reference mask. Made once per model.
void make_planning_organ(const OrganModel& m) {
  if (m.planning_mask) return;
  if (m.shape.mask) {  // the shape's own organ: its distance at its level
    m.planning_mask = m.shape.mask;
    m.planning_distance = m.shape.distance;
    return;
  }
  m.planning_mask = std::make_shared<const geometry::LabelVolume>(m.reference);
  m.planning_distance = std::make_shared<const geometry::SignedDistance>(*m.planning_mask, false);
  if (m.saved_planning_levels) m.planning_distance->adopt_volume_levels(*m.saved_planning_levels);
}
}  // namespace

bool carries_fit(const OrganModel& m) {
  return m.placed.cols() == m.state.x.cols() && m.placed.cols() > 0;
}

EmbeddedBody organ_body(const OrganModel& m) {
  make_planning_organ(m);
  return EmbeddedBody(
      m.planning_mask, m.planning_distance,
      std::make_shared<const Deformation>(m.global_map, carries_fit(m) ? m.placed : m.state.x,
                                          m.state.x, embedding_support_mm(m.lattice_spacing_mm)));
}

EmbeddedBody organ_body(const OrganModel& m, std::shared_ptr<const Deformation> deformation) {
  make_planning_organ(m);
  return EmbeddedBody(m.planning_mask, m.planning_distance, std::move(deformation));
}

geometry::SignedDistance::VolumeLevels planning_volume_levels(const OrganModel& m) {
  if (m.saved_planning_levels) return *m.saved_planning_levels;
  make_planning_organ(m);
  return m.planning_distance->volume_levels();
}

std::uint64_t planning_fingerprint(const OrganModel& m) {
  const geometry::ImageGeometry& g = m.reference.geometry;
  const double radius = m.model->radius_mm();
  std::uint64_t h = 0;
  h = geometry::hash_bytes(h, m.state.x.data(),
                           sizeof(double) * static_cast<size_t>(m.state.x.size()));
  h = geometry::hash_bytes(h, &radius, sizeof radius);
  h = geometry::hash_bytes(h, g.size.data(), sizeof(g.size[0]) * 3);
  h = geometry::hash_bytes(h, g.spacing_mm.data(), sizeof(double) * 3);
  h = geometry::hash_bytes(h, g.origin_mm.data(), sizeof(double) * 3);
  h = geometry::hash_bytes(h, g.direction.data(), sizeof(double) * 9);
  return geometry::hash_bytes(h, m.reference.labels.data(), m.reference.labels.size());
}

PlanningVolumes planning_volumes(const OrganModel& m) {
  const std::uint64_t fingerprint = planning_fingerprint(m);
  if (!carries_fit(m) && m.saved_planning_volumes &&
      m.saved_planning_volumes->fingerprint == fingerprint)
    return *m.saved_planning_volumes;
  PlanningVolumes v;
  const double rho = m.model->radius_mm();
  v.voxel_mm = volume_voxel_mm(rho, m.reference.volume_mm3(1));
  v.organ_mm3 = organ_body(m).volume_mm3(v.voxel_mm);
  v.particle_body_mm3 = geometry::particle_body_volume_mm3(m.state.x, rho, v.voxel_mm, rho);
  v.fingerprint = fingerprint;
  return v;
}

std::vector<double> planning_surface_distance_mm(const OrganModel& m,
                                                 const Eigen::Matrix3Xd& points_mm) {
  make_planning_organ(m);
  std::vector<double> d(static_cast<size_t>(points_mm.cols()));
  for (Eigen::Index k = 0; k < points_mm.cols(); ++k)
    d[static_cast<size_t>(k)] = std::abs(m.planning_distance->beyond_level(points_mm.col(k)));
  return d;
}

void add_skeleton_term(OrganModel& model, const particles::Skeleton& skeleton) {
  model.skeleton = &model.model->add(
      std::make_unique<particles::SkeletonForce>(skeleton, model.state.x, model.skeleton_params));
}

namespace {
/// The fcc spacing as a multiple of r0: fixed for a law's exponents, cutoff and floor (in
/// r0). An fcc lattice of spacing a holds sqrt(2) / a^3 particles per mm^3.
double spacing_per_r0(const ModelSettings& s) {
  ModelSettings unit = s;
  unit.radius_mm = 0.5;  // r0 = 1 mm
  return particles::fcc_equilibrium_spacing(particles::LennardJones(cohesion_params_from(unit)));
}
}  // namespace

double radius_for_count(const ModelSettings& s, const geometry::Shape& shape, long long count) {
  const double volume_mm3 = shape_volume(shape, 200);
  // The surface's partial cells make the count differ a little from the volume's; a box
  // whose faces lie on lattice planes gains whole face layers (+10% at 6,000 particles).
  const double a = std::cbrt(std::sqrt(2.0) * volume_mm3 / static_cast<double>(count));
  return 0.5 * a / spacing_per_r0(s);
}

double particle_count_at(const ModelSettings& s, const geometry::Shape& shape) {
  const double a = 2.0 * s.radius_mm * spacing_per_r0(s);
  return std::sqrt(2.0) * shape_volume(shape, 200) / (a * a * a);
}

OrganModel copy_model(const OrganModel& m) {
  OrganModel c;
  c.settings = m.settings;
  c.state = particles::State(m.state.x);
  c.shape = m.shape;
  c.reference = m.reference;
  c.lattice_spacing_mm = m.lattice_spacing_mm;
  c.global_map = m.global_map;
  c.placed = m.placed;
  c.planning_mask = m.planning_mask;  // the same shape and reference: the same cache
  c.planning_distance = m.planning_distance;
  c.saved_planning_levels = m.saved_planning_levels;
  c.saved_planning_volumes = m.saved_planning_volumes;
  std::optional<particles::Skeleton> skeleton;
  if (m.skeleton) skeleton = m.skeleton->skeleton();
  build_model_terms(c, skeleton ? &*skeleton : nullptr);
  return c;
}

}  // namespace organfit::fitting
