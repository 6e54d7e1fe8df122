#include "organfit/bench/skeleton_benchmark.h"

#include <omp.h>

#include "organfit/geometry/mask_ops.h"
#include "organfit/particles/cohesion_force.h"
#include "organfit/particles/diagnostics.h"
#include "organfit/particles/integrator.h"
#include "organfit/particles/lattice_fill.h"
#include "organfit/particles/skeleton.h"
#include "organfit/support/resources.h"

namespace organfit::bench {

using namespace organfit::particles;

nlohmann::json run_skeleton_benchmark(const SkeletonBenchOptions& o) {
  omp_set_num_threads(o.threads);
  CohesionParams p;
  p.r0_mm = o.r0_mm;
  const LennardJones law(p);
  const double a = fcc_equilibrium_spacing(law);
  State start(fill_ellipsoid({o.size_x_mm, o.size_yz_mm, o.size_yz_mm}, {0, 0, 0}, a));
  const int n = start.size();
  {  // relax the free surface first (zero temperature)
    Model m(n, 1.0, 0.5 * p.r0_mm);
    m.add(std::make_unique<CohesionForce>(law, 0.3 * p.r0_mm));
    IntegratorOptions relax_opt;
    relax_opt.damping = 2.0;
    relax_opt.length_scale_mm = p.r0_mm;
    relax(m, start, relax_opt, 5000, 1e-8);
  }
  const Skeleton skeleton = medial_skeleton(start.x, a, o.node_spacing_r0 * p.r0_mm);
  nlohmann::json result = {{"benchmark", "skeleton"},
                           {"particles", n},
                           {"size_mm", {o.size_x_mm, o.size_yz_mm, o.size_yz_mm}},
                           {"r0_mm", p.r0_mm},
                           {"temperature_E0", o.temperature},
                           {"friction_per_s", o.friction},
                           {"steps", o.steps},
                           {"skeleton_nodes", skeleton.node_count()},
                           {"aspect_ratio_start", aspect_ratio(start.x)}};
  for (bool with_skeleton : {true, false}) {
    Model model(n, 1.0, 0.5 * p.r0_mm);
    model.add(std::make_unique<CohesionForce>(law, 0.3 * p.r0_mm));
    if (with_skeleton) {
      SkeletonParams sp;
      sp.stiffness = o.stiffness_fraction * law.stiffness();
      sp.overlap_mm = o.overlap_r0 * p.r0_mm;
      model.add(std::make_unique<SkeletonForce>(skeleton, start.x, sp));
    }
    IntegratorOptions opt;
    opt.damping = o.friction * model.mass();
    opt.temperature = o.temperature * p.E0;
    opt.length_scale_mm = p.r0_mm;
    opt.seed = 7;
    State s = start;
    Stopwatch clock;
    Integrator integ(model, opt);
    integ.run(s, o.steps);
    // The body is the largest component (evaporated particles are not the organ);
    // it is rigidly aligned, particle by particle, onto the same particles at the start.
    const std::vector<int> body = largest_component(s.x, 1.5 * p.r0_mm);
    Positions body_x(3, static_cast<Eigen::Index>(body.size())), body_start(3, body_x.cols());
    for (size_t b = 0; b < body.size(); ++b) {
      body_x.col(b) = s.x.col(body[b]);
      body_start.col(b) = start.x.col(body[b]);
    }
    const Positions aligned = rigid_align(body_x, body_start);
    const auto cmp = geometry::compare_particle_bodies(aligned, start.x, 0.5 * p.r0_mm,
                                                       0.125 * p.r0_mm, 0.5 * p.r0_mm);
    result[with_skeleton ? "with_skeleton" : "without_skeleton"] = {
        {"aspect_ratio_end", aspect_ratio(body_x)},  // of the largest component
        {"evaporated_fraction", 1.0 - double(body.size()) / n},
        {"msd_to_start_mm", cmp.msd_mm},
        {"msd_to_start_r0", cmp.msd_mm / p.r0_mm},
        {"hd95_to_start_mm", cmp.hd95_mm},
        {"dice_to_start", cmp.dice},
        {"components", connected_components(s.x, 1.5 * p.r0_mm)},
        {"time_step_s", integ.time_step_s()},
        {"time_step_halvings", integ.stats().time_step_halvings},
        {"capped_moves", integ.stats().capped_moves},
        {"wall_s", clock.elapsed_s()}};
  }
  return result;
}

}  // namespace organfit::bench
