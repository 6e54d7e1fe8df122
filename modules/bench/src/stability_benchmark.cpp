#include "organfit/bench/stability_benchmark.h"

#include <fmt/format.h>
#include <omp.h>

#include <cmath>
#include <fstream>
#include <random>
#include <sstream>

#include "organfit/particles/integrator.h"
#include "organfit/pipeline/fit_stage.h"
#include "organfit/pipeline/model_stage.h"
#include "organfit/pipeline/points_stage.h"
#include "organfit/support/atomic_file.h"
#include "organfit/support/error.h"
#include "organfit/support/interrupt.h"
#include "organfit/support/output_folder.h"
#include "organfit/support/resources.h"

namespace fs = std::filesystem;

namespace organfit::bench {
namespace {

/// Points on the egg body's surface (50 x 40 x 34 mm, apex at -x), seeded.
std::vector<Eigen::Vector3d> egg_surface(int n, std::mt19937_64& rng) {
  std::normal_distribution<double> g(0, 1);
  std::vector<Eigen::Vector3d> pts;
  while (static_cast<int>(pts.size()) < n) {
    Eigen::Vector3d v(g(rng), g(rng), g(rng));
    v.normalize();
    const double taper = v.x() < 0 ? 1 + 0.3 * v.x() : 1.0;
    pts.emplace_back(25 * v.x(), 20 * v.y() * taper, 17 * v.z() * taper);
  }
  return pts;
}

void write_points(const fs::path& file, const std::vector<Eigen::Vector3d>& pts) {
  std::string csv = "x,y,z\n";
  for (const auto& p : pts)
    csv += fmt::format("{:.4f},{:.4f},{:.4f}\n", p.x(), p.y(), p.z());
  write_file_atomically(file, csv);
}

/// A case: the model's options (the egg body of 50 x 40 x 34 mm at radius 1.92 mm unless
/// it says otherwise) and where its points come from.
struct Case {
  std::string name;
  pipeline::ModelStageOptions model;
  pipeline::PointsOptions points;
};

pipeline::ModelStageOptions egg_model(double radius_mm = 1.92,
                                      const Eigen::Vector3d& size_mm = {50, 40, 34}) {
  pipeline::ModelStageOptions o;
  o.settings.radius_mm = radius_mm;
  o.body_shape = "egg";
  o.body_size_mm = size_mm;
  return o;
}

/// 87 points (0.5 mm noise) on the body stretched 1.15 and bent 2 mm, or `count` on it
/// stretched `stretch` alone.
pipeline::PointsOptions generated(int count = 87, double stretch = 1.15, double bend_mm = 2) {
  pipeline::PointsOptions o;
  o.deformation.stretch = stretch;
  o.deformation.bend_mm = bend_mm;
  o.sampling.count = count;
  o.sampling.noise_mm = 0.5;
  return o;
}

pipeline::PointsOptions from_file(const fs::path& file) {
  pipeline::PointsOptions o;
  o.source = "file";
  o.file = file;
  return o;
}

}  // namespace

nlohmann::json run_stability_benchmark(const StabilityBenchOptions& o) {
  if (o.out.empty()) throw InputError("bench stability: --out DIR is required");
  check_output_location(o.out, {}, "--out");
  // What this command makes goes again if it is stopped or fails: the folder, or its runs/.
  CreatedFolders folders(o.out / "runs", /*with_contents=*/true);
  if (o.threads > 0) omp_set_num_threads(o.threads);
  Stopwatch total;
  std::mt19937_64 rng(3);
  const fs::path dir = o.out / "runs";
  auto far = egg_surface(40, rng);
  far.insert(far.end(),
             {Eigen::Vector3d(500, 0, 0), Eigen::Vector3d(0, -480, 0), Eigen::Vector3d(0, 0, 520)});
  std::vector<Eigen::Vector3d> inside;
  std::uniform_real_distribution<double> u(-3, 3);
  for (int i = 0; i < 30; ++i)
    inside.emplace_back(u(rng), u(rng), u(rng));
  auto centre = egg_surface(30, rng);
  centre.emplace_back(0, 0, 0);  // the body's centre is a lattice site
  std::vector<Eigen::Vector3d> dup(25, Eigen::Vector3d(27, 0, 0));
  const auto more = egg_surface(20, rng);
  dup.insert(dup.end(), more.begin(), more.end());
  write_points(dir / "far.csv", far);
  write_points(dir / "deep_inside.csv", inside);
  write_points(dir / "on_particle_centre.csv", centre);
  write_points(dir / "duplicates.csv", dup);
  write_points(dir / "single.csv", {Eigen::Vector3d(28, 0, 0)});

  auto with = [](pipeline::ModelStageOptions m, auto&& change) {
    change(m.settings);
    return m;
  };
  const std::vector<Case> cases = {
      {"exponents_20_40", with(egg_model(), [](auto& s) { s.exponent_m = 20, s.exponent_n = 40; }),
       generated()},
      {"time_step_at_limit", with(egg_model(), [](auto& s) { s.time_step_fraction = 0.9; }),
       generated()},
      {"time_step_beyond_limit", with(egg_model(), [](auto& s) { s.time_step_fraction = 1.5; }),
       generated()},
      {"points_10x_organ_away", egg_model(), from_file(dir / "far.csv")},
      {"points_deep_inside", egg_model(), from_file(dir / "deep_inside.csv")},
      {"point_on_particle_centre", egg_model(), from_file(dir / "on_particle_centre.csv")},
      {"points_duplicated", egg_model(), from_file(dir / "duplicates.csv")},
      {"one_point", egg_model(), from_file(dir / "single.csv")},
      {"points_10000", egg_model(), generated(10000, 1.1, 0)},
      {"tiny_radius", egg_model(0.3, {10, 8, 6}), generated()},
      {"huge_radius", egg_model(40), generated()},
  };
  std::string csv =
      "case,method,outcome,reason,finite,components,max_kinetic_energy_per_particle,volume_change_"
      "pct,wall_s,pass\n";
  std::string md =
      "# organfit bench stability\n\nEach row a case's model, points and fit stages called in "
      "turn, both fitting methods.\n"
      "Outcomes: converged, stopped (the fit did not meet its target and says why; `organfit run` "
      "exits 3),\n"
      "refused (bad input, named; exit 2). A row passes when it ends in one of those and any "
      "model it\n"
      "produced is finite, in one piece, and its kinetic energy per particle stayed below 5 E0.\n\n"
      "| case | method | outcome | finite | components | max KE/particle (E0) | volume change (%) "
      "| wall (s) | pass |\n"
      "|---|---|---|---|---|---|---|---|---|\n";
  bool all_pass = true;
  int rows = 0;
  for (const auto& c : cases)
    for (const char* method : {"spread", "paper"}) {
      throw_if_interrupted();
      std::string outcome, reason;
      Stopwatch clock;
      std::optional<pipeline::FitStageResult> fit;
      try {
        pipeline::ModelStageResult model = pipeline::run_model_stage(c.model);
        const pipeline::PointsStageResult points = pipeline::run_points_stage(c.points, model);
        pipeline::FitStageOptions options;
        options.method = method;
        options.paper.fit.max_wall_s = options.spread.fit.max_wall_s = 20;
        options.measure_truth = false;  // how the run ends, not how close it comes
        fit = pipeline::run_fit_stage(options, std::move(model), points);
        outcome = fit->not_converged_message.empty() ? "converged" : "stopped";
        reason = fit->not_converged_message;
        // Converged on the global stage's organ: why the local stage was undone.
        if (reason.empty() && fit->report.local_stage_undone())
          reason = fit->report.fit.stop_reason;
      } catch (const particles::StabilityError& e) {
        outcome = "stopped", reason = e.what();
      } catch (const TargetNotMetError& e) {
        outcome = "stopped", reason = e.what();
      } catch (const InputError& e) {
        outcome = "refused", reason = e.what();
      } catch (const std::invalid_argument& e) {
        outcome = "refused", reason = e.what();
      }
      const double wall = clock.elapsed_s();
      bool finite = true;
      int components = 1;
      double max_ke = 0, volume = 0;
      if (fit) {
        finite = fit->report.finite;
        components = fit->report.components;
        volume = fit->fit_summary["volume_change_pct"].get<double>();
        for (const fitting::HistoryRow& h : fit->report.fit.history)
          max_ke = std::max(max_ke, h.kinetic_energy_per_particle);
      }
      const bool pass = finite && components == 1 && max_ke < 5.0 && std::isfinite(volume);
      all_pass = all_pass && pass;
      ++rows;
      std::string short_reason = reason.substr(0, std::min<size_t>(reason.size(), 160));
      for (auto& ch : short_reason)
        if (ch == ',' || ch == '|' || ch == '\n') ch = ';';
      csv += fmt::format("{},{},{},{},{},{},{:.3g},{:.3f},{:.2f},{}\n", c.name, method, outcome,
                         short_reason, finite, components, max_ke, volume, wall, pass);
      md += fmt::format("| {} | {} | {}{} | {} | {} | {:.3g} | {:+.2f} | {:.2f} | {} |\n", c.name,
                        method, outcome, reason.empty() ? "" : ": " + short_reason,
                        finite ? "yes" : "NO", components, max_ke, volume, wall,
                        pass ? "yes" : "**NO**");
    }
  write_file_atomically(o.out / "stability.csv", csv);
  write_file_atomically(o.out / "STABILITY.md", md);
  folders.keep();
  return {{"benchmark", "stability"},
          {"rows", rows},
          {"all_pass", all_pass},
          {"wall_s", total.elapsed_s()},
          {"out", o.out.string()}};
}

}  // namespace organfit::bench
