#include "organfit/pipeline/model_stage.h"

#include <spdlog/spdlog.h>

#include <cmath>

#include "organfit/evaluation/synthetic.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/geometry/topology.h"
#include "organfit/particles/cohesion_force.h"
#include "organfit/particles/diagnostics.h"
#include "organfit/particles/fire.h"
#include "organfit/particles/lattice_fill.h"
#include "organfit/particles/skeleton.h"
#include "organfit/pipeline/scene_schema.h"
#include "organfit/support/error.h"
#include "organfit/support/interrupt.h"
#include "organfit/support/progress.h"
#include "organfit/support/resources.h"

namespace organfit::pipeline {

ModelSettings model_settings_from(const config::Scene& scene) {
  ModelSettings s = keys::model().read(scene);
  s.seed = static_cast<std::uint64_t>(scene.integer("scene", "seed"));
  return s;
}

// One list of the settings' keys, for both directions of the JSON conversion.
template <class Settings, class Visit>
void visit_settings(Settings& s, Visit&& visit) {
  visit("radius_mm", s.radius_mm);
  visit("cohesion_energy", s.cohesion_energy);
  visit("exponent_m", s.exponent_m);
  visit("exponent_n", s.exponent_n);
  visit("cutoff_r0", s.cutoff_r0);
  visit("floor_r0", s.floor_r0);
  visit("mass", s.mass);
  visit("damping_ratio", s.damping_ratio);
  visit("pair_damping", s.pair_damping);
  visit("neighbour_skin_r0", s.neighbour_skin_r0);
  visit("time_step_fraction", s.time_step_fraction);
  visit("relax_steps", s.relax_steps);
  visit("relax_tolerance", s.relax_tolerance);
  visit("skeleton", s.skeleton);
  visit("skeleton_stiffness", s.skeleton_stiffness);
  visit("skeleton_node_spacing_r0", s.skeleton_node_spacing_r0);
  visit("skeleton_overlap_r0", s.skeleton_overlap_r0);
  visit("seed", s.seed);
}

nlohmann::json to_json(const ModelSettings& s) {
  nlohmann::json j = nlohmann::json::object();
  visit_settings(s, [&](const char* key, const auto& value) { j[key] = value; });
  return j;
}

ModelSettings model_settings_from_json(const nlohmann::json& j, const std::string& where) {
  ModelSettings s;
  visit_settings(s, [&](const char* key, auto& value) {
    using T = std::decay_t<decltype(value)>;
    const auto it = j.find(key);
    const bool ok = it != j.end() && (std::is_same_v<T, bool>       ? it->is_boolean()
                                      : std::is_floating_point_v<T> ? it->is_number()
                                                                    : it->is_number_integer());
    if (!ok)
      throw InputError(fmt::format("{}: model setting '{}' is missing or not a {}", where, key,
                                   std::is_same_v<T, bool> ? "true/false" : "number"));
    value = it->template get<T>();
    // Within the range the scene key of the same name declares (scene_schema.cpp).
    if constexpr (!std::is_same_v<T, bool>) {
      const config::ParamSpec* spec = keys::model().find(key);
      if (spec && !config::number_in_range(*spec, static_cast<double>(value)))
        throw InputError(fmt::format("{}: model setting '{}' is {}, out of range {}", where, key,
                                     it->dump(), spec->range_text()));
    }
  });
  return s;
}

ModelStageOptions model_stage_options_from(const config::Scene& scene) {
  ModelStageOptions o;
  o.settings = model_settings_from(scene);
  o.particles = scene.integer("model", "particles");
  if (scene.has_section("body")) {
    o.body_shape = scene.text("body", "shape");
    o.body_size_mm = scene.vec3("body", "size_mm");
    o.body_centre_mm = scene.vec3("body", "centre_mm");
  }
  o.radius_key = scene.key("model", o.settings.radius_mm > 0.0 ? "radius_mm" : "particles");
  o.body_size_key = scene.key("body", "size_mm");
  return o;
}

ModelStageResult run_model_stage(const ModelStageOptions& options, const geometry::Shape* organ) {
  ModelSettings settings = options.settings;
  const geometry::Shape shape =
      organ
          ? *organ
          : geometry::make_shape(options.body_shape, options.body_size_mm, options.body_centre_mm);
  if (settings.radius_mm == 0.0) {  // the radius follows the body's volume
    if (options.particles < 2)
      throw std::invalid_argument("model stage: no radius and fewer than 2 particles asked");
    settings.radius_mm = radius_for_count(settings, shape, options.particles);
    spdlog::info("model: radius {:.4f} mm for about {} particles", settings.radius_mm,
                 options.particles);
  }
  // A radius in the wrong unit (0.01 mm for 1 cm) fills a prostate with billions of
  // particles: the fill ran for minutes into gigabytes without a word.
  if (options.settings.radius_mm > 0.0)
    if (const double expected = fitting::particle_count_at(settings, shape);
        expected > static_cast<double>(kMostParticles))
      options.radius_key.fail(
          fmt::format("a radius of {:g} mm fills this organ with about {:.2g} particles, more "
                      "than a model holds ({:g}): choose a larger radius, or model.particles",
                      settings.radius_mm, expected, static_cast<double>(kMostParticles)));
  const particles::CohesionParams cp = cohesion_params_from(settings);
  const particles::LennardJones law(cp);
  const double spacing = particles::fcc_equilibrium_spacing(law);
  const Eigen::Vector3d centre = shape.centre_mm;
  particles::Positions x = particles::fcc_lattice_points(
      shape.bounds(), centre, spacing, [&](const Eigen::Vector3d& p) { return shape.inside(p); });
  if (x.cols() < 2) {
    (organ ? options.radius_key : options.body_size_key)
        .fail(fmt::format("the body holds {} particle(s) at radius {} mm: make it larger or the "
                          "particles smaller",
                          x.cols(), 0.5 * cp.r0_mm));
  }
  ModelStageResult result;
  result.settings = settings;
  result.shape = shape;
  result.reference =
      fitting::reference_body(shape, cp.r0_mm);  // what the particles stand for, for re-filling
  result.lattice_spacing_mm = spacing;
  result.state = particles::State(std::move(x));
  const int n = result.state.size();
  build_model_terms(result, nullptr);
  const particles::Positions filled = result.state.x;
  // The skeleton, tied to the lattice as filled, holds the organ's shape while the
  // relaxation relieves the lattice's surface; the relaxed body then becomes its rest
  // shape. Why before: the cohesion acts as a surface tension, and without the skeleton
  // the parts of a real organ a few particles thin flow (a liver grown on 5 mm slices,
  // 18,183 particles: 2,853 moved over 1 mm, one 27 mm, still moving after the 5,000 steps;
  // with it, settled in 300 steps, 0.08 mm on average).
  Stopwatch skeleton_clock;
  int skeleton_nodes = 0;
  std::string skeleton_source = "none";
  if (settings.skeleton) {
    // From the organ's mask when there is one (the CT stage's segmentation: the organ's
    // own medial axis), else from the particles.
    const double node_spacing_mm = settings.skeleton_node_spacing_r0 * cp.r0_mm;
    const bool from_mask = organ && organ->mask;
    skeleton_source = from_mask ? "organ mask" : "particles";
    const particles::Skeleton skeleton =
        from_mask ? particles::medial_skeleton(*organ->mask, node_spacing_mm)
                  : particles::medial_skeleton(result.state.x, spacing, node_spacing_mm);
    add_skeleton_term(result, skeleton);
    skeleton_nodes = result.skeleton->skeleton().node_count();
    spdlog::info("model: skeleton of {} nodes, {} edges (from the {})", skeleton_nodes,
                 result.skeleton->skeleton().edges.size(), skeleton_source);
  }
  const double skeleton_wall_s = skeleton_clock.elapsed_s();
  const particles::IntegratorOptions opt = integrator_options_from(settings, *result.model);

  spdlog::info("model: {} particles on an fcc lattice at {:.4f} mm ({:.4f} r0), relaxing", n,
               spacing, spacing / cp.r0_mm);
  const long long max_steps = settings.relax_steps;
  // Settled when the rms force per particle is at most the damping's force on a particle
  // moving with the kinetic energy relax_tolerance, K_a sqrt(2 tol / M): the rest damped
  // motion stops at, reached by FIRE in fewer steps (docs/decisions.md).
  const double force_tolerance =
      opt.damping * std::sqrt(2 * settings.relax_tolerance / result.model->mass());
  Stopwatch clock;
  const particles::Integrator integ(*result.model, opt);  // validates; its time step
  particles::FireOptions fire;
  fire.time_step_s = integ.time_step_s();
  fire.max_step_mm = integ.max_step_mm();
  Progress progress("relax", max_steps);
  // With relax_steps 0 nothing moves, its rms force is still measured, and it is settled
  // as asked.
  const particles::FireResult relaxed = particles::minimise_fire(
      *result.model, result.state, fire, max_steps, force_tolerance,
      [&](long long step, double rms_force) {
        throw_if_interrupted();
        if (step % 10 == 0)
          progress.update(step, fmt::format("rms force {:.2e} (settled at {:.2e})", rms_force,
                                            force_tolerance));
        return true;
      });
  const long long steps = relaxed.steps;
  const bool settled = max_steps == 0 || relaxed.settled;
  progress.finish();
  const double relax_wall_s = clock.elapsed_s();
  if (result.skeleton) result.skeleton->set_rest_shape(result.state.x);
  const double largest_move_mm = (result.state.x - filled).colwise().norm().maxCoeff();

  const Eigen::Vector3d extents = particles::principal_extents(result.state.x);
  // The particles' body (balls closed by rho, as in the fit) against what they stand for.
  const double body_volume = geometry::particle_body_volume_mm3(result.state.x, 0.5 * cp.r0_mm,
                                                                0.25 * cp.r0_mm, 0.5 * cp.r0_mm);
  const double reference_volume = result.reference.volume_mm3(1);
  const std::vector<long long> empty_parts =
      shape.mask ? geometry::pieces_holding_none(*shape.mask, result.state.x)
                 : std::vector<long long>{};
  double empty_parts_mm3 = 0;
  for (long long voxels : empty_parts)
    empty_parts_mm3 += static_cast<double>(voxels) * shape.mask->geometry.spacing_mm.prod();
  result.summary = {
      {"particles", n},
      {"radius_mm", 0.5 * cp.r0_mm},
      {"r0_mm", cp.r0_mm},
      {"lattice_spacing_mm", spacing},
      {"lattice_volume_mm3", n * particles::fcc_volume_per_particle(spacing)},
      {"r_min_mm", law.r_min()},
      {"f_max", law.f_max()},
      {"time_step_s", integ.time_step_s()},
      {"relax_steps", steps},
      {"relax_settled", settled},
      {"relax_wall_s", relax_wall_s},
      {"skeleton_wall_s", skeleton_wall_s},
      {"relax_largest_move_mm", largest_move_mm},
      {"relax_rms_force", relaxed.rms_force},
      {"relax_force_tolerance", force_tolerance},
      {"capped_moves", relaxed.capped_moves},
      {"components", particles::connected_components(result.state.x, 1.5 * cp.r0_mm)},
      // The organ's own pieces (26-connected voxels of its mask; an analytic body is one),
      // for the warning when the particles make more: parts of the organ thinner than
      // about two lattice spacings hold no particles, so what they joined falls apart.
      {"organ_components", shape.mask ? geometry::topology_of(*shape.mask).components : 1},
      // The organ's pieces no particle lies in (an island of a few voxels, or a piece
      // thinner than the lattice): moved by the deformation about them, not by points.
      {"organ_parts_without_particles", empty_parts.size()},
      {"organ_parts_without_particles_cm3", empty_parts_mm3 / 1000.0},
      {"skeleton_nodes", skeleton_nodes},
      {"skeleton_from", skeleton_source},
      {"body_volume_mm3", body_volume},
      {"reference_volume_mm3", reference_volume},
      {"volume_vs_reference_pct", 100.0 * (body_volume - reference_volume) / reference_volume},
      {"principal_extents_mm", {extents.x(), extents.y(), extents.z()}}};
  return result;
}

}  // namespace organfit::pipeline
