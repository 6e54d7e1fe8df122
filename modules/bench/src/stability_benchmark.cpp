#include "organfit/bench/stability_benchmark.h"

#include <fmt/format.h>
#include <omp.h>

#include <cmath>
#include <fstream>
#include <random>
#include <sstream>

#include "organfit/pipeline/runner.h"
#include "organfit/pipeline/scene_schema.h"
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

struct Case {
  std::string name;
  std::string body = "body:\n  shape: egg\n  size_mm: [50, 40, 34]\n";
  std::string model = "model:\n  radius_mm: 1.92\n";
  std::string points;  ///< the points section's body
};

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

  const std::string generated = "  count: 87\n  noise_mm: 0.5\n  stretch: 1.15\n  bend_mm: 2\n";
  std::vector<Case> cases = {
      {"exponents_20_40", Case{}.body,
       "model:\n  radius_mm: 1.92\n  exponent_m: 20\n  exponent_n: 40\n", generated},
      {"time_step_at_limit", Case{}.body, "model:\n  radius_mm: 1.92\n  time_step_fraction: 0.9\n",
       generated},
      {"time_step_beyond_limit", Case{}.body,
       "model:\n  radius_mm: 1.92\n  time_step_fraction: 1.5\n", generated},
      {"points_10x_organ_away", Case{}.body, Case{}.model, "  source: file\n  file: far.csv\n"},
      {"points_deep_inside", Case{}.body, Case{}.model,
       "  source: file\n  file: deep_inside.csv\n"},
      {"point_on_particle_centre", Case{}.body, Case{}.model,
       "  source: file\n  file: on_particle_centre.csv\n"},
      {"points_duplicated", Case{}.body, Case{}.model, "  source: file\n  file: duplicates.csv\n"},
      {"one_point", Case{}.body, Case{}.model, "  source: file\n  file: single.csv\n"},
      {"points_10000", Case{}.body, Case{}.model,
       "  count: 10000\n  noise_mm: 0.5\n  stretch: 1.1\n"},
      {"tiny_radius", "body:\n  shape: egg\n  size_mm: [10, 8, 6]\n", "model:\n  radius_mm: 0.3\n",
       generated},
      {"huge_radius", Case{}.body, "model:\n  radius_mm: 40\n", generated},
  };
  std::string csv =
      "case,method,outcome,reason,finite,components,max_kinetic_energy_per_particle,volume_change_"
      "pct,wall_s,pass\n";
  std::string md =
      "# organfit bench stability\n\nEach row a scene run in full (`organfit run`), both fitting "
      "methods.\n"
      "Outcomes: converged (exit 0), stopped (exit 3: the fit did not meet its target and says "
      "why),\n"
      "refused (exit 2: bad input, named). A row passes when it ends in one of those and any model "
      "it\n"
      "produced is finite, in one piece, and its kinetic energy per particle stayed below 5 E0.\n\n"
      "| case | method | outcome | finite | components | max KE/particle (E0) | volume change (%) "
      "| wall (s) | pass |\n"
      "|---|---|---|---|---|---|---|---|---|\n";
  bool all_pass = true;
  int rows = 0;
  for (const auto& c : cases)
    for (const char* method : {"spread", "paper"}) {
      throw_if_interrupted();
      const std::string text = fmt::format(
          "scene:\n  name: {}-{}\n{}{}points:\n{}fit:\n  method: {}\n  max_wall_s: 20\n", c.name,
          method, c.body, c.model, c.points, method);
      const fs::path run_dir = dir / fmt::format("{}-{}", c.name, method);
      std::string outcome, reason;
      Stopwatch clock;
      nlohmann::json run;
      try {
        const config::Scene scene =
            config::parse_scene(text, dir / "case.yaml", pipeline::scene_schema());
        pipeline::check_scene_rules(scene);
        run = pipeline::run_scene(scene, run_dir);
        outcome = "converged";
      } catch (const TargetNotMetError& e) {
        outcome = "stopped", reason = e.what();
      } catch (const InputError& e) {
        outcome = "refused", reason = e.what();
      } catch (const std::invalid_argument& e) {
        outcome = "refused", reason = e.what();
      }
      const double wall = clock.elapsed_s();
      if (run.is_null() && fs::exists(run_dir / "run.json")) {
        std::ifstream in(run_dir / "run.json");
        run = nlohmann::json::parse(in);
      }
      bool finite = true;
      int components = 1;
      double max_ke = 0, volume = 0;
      if (run.contains("fit")) {
        finite = run["fit"].value("finite", true);
        components = run["fit"].value("components", 1);
        volume = run["fit"].value("volume_change_pct", 0.0);
        std::ifstream h(run_dir / "history.csv");
        std::string line;
        std::getline(h, line);
        while (std::getline(h, line)) {
          const auto comma = line.rfind(',');
          if (comma != std::string::npos)
            max_ke = std::max(max_ke, std::atof(line.c_str() + comma + 1));
        }
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
