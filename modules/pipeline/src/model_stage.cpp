#include "organfit/pipeline/model_stage.h"

#include <spdlog/spdlog.h>

#include "organfit/evaluation/synthetic.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/particles/cohesion_force.h"
#include "organfit/particles/diagnostics.h"
#include "organfit/particles/lattice_fill.h"
#include "organfit/particles/skeleton.h"
#include "organfit/support/error.h"
#include "organfit/support/interrupt.h"
#include "organfit/support/progress.h"
#include "organfit/support/resources.h"

namespace organfit::pipeline {

particles::CohesionParams cohesion_params_from(const config::Scene& scene) {
  particles::CohesionParams p;
  p.E0 = scene.number("model", "cohesion_energy");
  p.r0_mm = 2.0 * scene.number("model", "radius_mm");
  p.m = static_cast<int>(scene.integer("model", "exponent_m"));
  p.n = static_cast<int>(scene.integer("model", "exponent_n"));
  p.cutoff_r0 = scene.number("model", "cutoff_r0");
  p.floor_r0 = scene.number("model", "floor_r0");
  return p;
}

particles::IntegratorOptions integrator_options_from(const config::Scene& scene,
                                                     const particles::Model& model) {
  particles::IntegratorOptions opt;
  opt.time_step_fraction = scene.number("model", "time_step_fraction");
  opt.damping = scene.number("model", "damping_ratio") * 2.0 *
                std::sqrt(model.stiffness() * model.mass());
  opt.length_scale_mm = 2.0 * model.radius_mm();
  // No particle may carry more than 5 well depths of kinetic energy (see IntegratorOptions).
  opt.max_speed_mm_s = std::sqrt(2.0 * 5.0 * scene.number("model", "cohesion_energy") / model.mass());
  opt.seed = static_cast<std::uint64_t>(scene.integer("scene", "seed"));
  return opt;
}

ModelStageResult run_model_stage(const config::Scene& scene, const evaluation::Shape* organ) {
  const particles::CohesionParams cp = cohesion_params_from(scene);
  const particles::LennardJones law(cp);
  const double spacing = particles::fcc_equilibrium_spacing(law);
  const evaluation::Shape shape =
      organ ? *organ
            : evaluation::make_shape(scene.text("body", "shape"), scene.vec3("body", "size_mm"),
                                     scene.vec3("body", "centre_mm"));
  const Eigen::Vector3d centre = shape.centre_mm;
  particles::Positions x = particles::fcc_lattice_points(
      shape.bounds(), centre, spacing, [&](const Eigen::Vector3d& p) { return shape.inside(p); });
  if (x.cols() < 2) {
    scene.fail(organ ? "model" : "body", organ ? "radius_mm" : "size_mm",
               fmt::format("the body holds {} particle(s) at radius {} mm: make it larger or the "
                           "particles smaller",
                           x.cols(), 0.5 * cp.r0_mm));
  }
  ModelStageResult result;
  result.shape = shape;
  {  // the reference body: what the particles stand for, kept for re-filling after a fit
    const geometry::ImageGeometry g = geometry::grid_covering(shape.bounds(), 0.25 * cp.r0_mm, 0.5 * cp.r0_mm);
    result.reference = geometry::LabelVolume(g);
    for (int k = 0; k < g.size[2]; ++k)
      for (int j = 0; j < g.size[1]; ++j)
        for (int i = 0; i < g.size[0]; ++i)
          result.reference.at(i, j, k) = shape.inside(g.index_to_physical(Eigen::Vector3d(i, j, k)));
  }
  result.lattice_spacing_mm = spacing;
  result.cohesion = cp;
  result.state = particles::State(std::move(x));
  const int n = result.state.size();
  result.model = std::make_unique<particles::Model>(n, scene.number("model", "mass"), 0.5 * cp.r0_mm);
  result.model->add(std::make_unique<particles::CohesionForce>(
      law, scene.number("model", "neighbour_skin_r0") * cp.r0_mm,
      scene.number("model", "pair_damping")));
  const particles::IntegratorOptions opt = integrator_options_from(scene, *result.model);

  spdlog::info("model: {} particles on an fcc lattice at {:.4f} mm ({:.4f} r0), relaxing", n,
               spacing, spacing / cp.r0_mm);
  const long long max_steps = scene.integer("model", "relax_steps");
  const double tol = scene.number("model", "relax_tolerance");
  Stopwatch clock;
  particles::Integrator integ(*result.model, opt);
  Progress progress("relax", max_steps);
  long long steps = 0;
  double ke = 0;
  bool settled = max_steps == 0;
  if (max_steps > 0) {
    integ.run(result.state, max_steps, [&](long long step) {
      throw_if_interrupted();
      steps = step;
      if (step % 10 != 0) return true;
      ke = integ.kinetic_energy(result.state) / n;
      progress.update(step, fmt::format("KE {:.2e} per particle", ke));
      settled = step >= 20 && ke < tol;
      return !settled;
    });
  }
  progress.finish();
  const double relax_wall_s = clock.elapsed_s();

  // The skeleton is built on the relaxed body, which becomes its rest shape.
  Stopwatch skeleton_clock;
  int skeleton_nodes = 0;
  std::string skeleton_source = "none";
  if (scene.flag("model", "skeleton")) {
    // From the organ's mask when there is one (the CT stage's segmentation: the organ's
    // own medial axis), else from the particles.
    const double node_spacing_mm = scene.number("model", "skeleton_node_spacing_r0") * cp.r0_mm;
    const bool from_mask = organ && organ->mask;
    skeleton_source = from_mask ? "organ mask" : "particles";
    const particles::Skeleton skeleton = from_mask
                                             ? particles::medial_skeleton(*organ->mask, node_spacing_mm)
                                             : particles::medial_skeleton(result.state.x, spacing, node_spacing_mm);
    particles::SkeletonParams sp;
    sp.stiffness = scene.number("model", "skeleton_stiffness") * law.stiffness();
    sp.overlap_mm = scene.number("model", "skeleton_overlap_r0") * cp.r0_mm;
    auto& term = result.model->add(
        std::make_unique<particles::SkeletonForce>(skeleton, result.state.x, sp));
    result.skeleton = &term;
    result.skeleton_params = sp;
    skeleton_nodes = term.skeleton().node_count();
    spdlog::info("model: skeleton of {} nodes, {} edges (from the {})", skeleton_nodes, term.skeleton().edges.size(),
                 skeleton_source);
  }
  const Eigen::Vector3d extents = particles::principal_extents(result.state.x);
  // The particles' body (balls closed by rho, as in the fit) against what they stand for.
  const double body_volume = geometry::particle_body_volume_mm3(result.state.x, 0.5 * cp.r0_mm, 0.25 * cp.r0_mm,
                                                                0.5 * cp.r0_mm);
  const double reference_volume = result.reference.volume_mm3(1);
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
      {"skeleton_wall_s", skeleton_clock.elapsed_s()},
      {"kinetic_energy_per_particle", ke},
      {"capped_moves", integ.stats().capped_moves},
      {"components", particles::connected_components(result.state.x, 1.5 * cp.r0_mm)},
      {"skeleton_nodes", skeleton_nodes},
      {"skeleton_from", skeleton_source},
      {"body_volume_mm3", body_volume},
      {"reference_volume_mm3", reference_volume},
      {"volume_vs_reference_pct", 100.0 * (body_volume - reference_volume) / reference_volume},
      {"principal_extents_mm", {extents.x(), extents.y(), extents.z()}}};
  return result;
}

}  // namespace organfit::pipeline
