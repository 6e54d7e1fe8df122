#include "organfit/bench/cohesion_benchmark.h"

#include <omp.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <regex>
#include <sstream>

#include "organfit/particles/cohesion_force.h"
#include "organfit/particles/integrator.h"
#include "organfit/particles/lattice_fill.h"
#include "organfit/support/interrupt.h"
#include "organfit/support/resources.h"

namespace fs = std::filesystem;

namespace organfit::bench {
namespace {

constexpr double kDensity = 0.8442;
constexpr double kTemperature = 1.44;
constexpr double kCutoffSigma = 2.5;
constexpr double kSkinSigma = 0.3;
constexpr double kTimeStep = 0.005;

long long cells_for(long long particles) {
  return std::max<long long>(1, std::llround(std::cbrt(particles / 4.0)));
}

struct OursResult {
  long long particles;
  double loop_s;
  long long list_builds;
  double pairs_per_particle;  ///< listed pairs (within cutoff + skin) per particle, at the end
  double pair_s;              ///< in the pair loop, during the timed steps
  double neighbour_s;         ///< building neighbour lists, during the timed steps
};

OursResult run_ours(long long requested, long long steps, int threads) {
  using namespace organfit::particles;
  const long long c = cells_for(requested);
  const double a = std::cbrt(4.0 / kDensity);  // cubic cell of the fcc lattice, sigma
  const long long n = 4 * c * c * c;
  Positions x(3, n);
  long long idx = 0;
  for (long long k = 0; k < c; ++k)
    for (long long j = 0; j < c; ++j)
      for (long long i = 0; i < c; ++i)
        for (const auto& b : particles::kFccBasis)
          x.col(idx++) = a * Eigen::Vector3d(i + b[0], j + b[1], k + b[2]);
  State s(x);
  std::mt19937_64 rng(87287);
  std::normal_distribution<double> g(0.0, std::sqrt(kTemperature));
  for (long long i = 0; i < n; ++i)
    for (int d = 0; d < 3; ++d)
      s.v(d, i) = g(rng);
  s.v.colwise() -= s.v.rowwise().mean();

  CohesionParams p;  // LJ 12-6 in sigma units: r0 = 2^(1/6) sigma
  p.r0_mm = std::pow(2.0, 1.0 / 6.0);
  p.cutoff_r0 = kCutoffSigma / p.r0_mm;
  p.floor_r0 = 0.5;
  Model model(static_cast<int>(n), 1.0, 0.5 * p.r0_mm);
  auto& cohesion = model.add(std::make_unique<CohesionForce>(LennardJones(p), kSkinSigma));
  IntegratorOptions opt;
  opt.time_step_s = kTimeStep;
  opt.max_step_r0 = 0;  // plain NVE, as LAMMPS
  opt.length_scale_mm = p.r0_mm;
  omp_set_num_threads(threads);
  Integrator integ(model, opt);
  integ.refresh_forces(s);  // setup (LAMMPS's setup is also outside its loop time)
  const auto& list = cohesion.neighbour_list();
  const double pair0 = cohesion.pair_seconds(), neigh0 = list.build_seconds();
  Stopwatch clock;
  integ.run(s, steps);
  const double loop_s = clock.elapsed_s();
  return {n,
          loop_s,
          list.builds(),
          double(list.pair_count()) / double(n),
          cohesion.pair_seconds() - pair0,
          list.build_seconds() - neigh0};
}

struct LammpsResult {
  bool ran = false;
  double loop_s = 0;
  long long atoms = 0;
  std::string error;
};

/// `checked`: rebuild the list when an atom moved half the skin (`every 1 check yes`,
/// organfit's policy) instead of in.lj's unconditional `every 20 check no`.
LammpsResult run_lammps(const std::string& binary, long long requested, long long steps,
                        bool checked) {
  LammpsResult r;
  const fs::path dir =
      fs::temp_directory_path() / ("organfit-bench-lmp-" + std::to_string(getpid()));
  fs::create_directories(dir);
  const long long c = cells_for(requested);
  {
    std::ofstream in(dir / "in.lj");
    in << "# organfit bench cohesion: LAMMPS bench/in.lj with open boundaries\n"
       << "units lj\natom_style atomic\nboundary s s s\n"
       << "lattice fcc " << kDensity << "\n"
       << "region box block 0 " << c << " 0 " << c << " 0 " << c
       << "\n"
       // Atoms from a region a quarter cell inside the box: exactly 4 c^3 lattice sites
       // (with shrink-wrapped boundaries `create_atoms 1 box` also fills the far faces).
       << "create_box 1 box\n"
       << "region sites block -0.25 " << c - 0.25 << " -0.25 " << c - 0.25 << " -0.25 " << c - 0.25
       << "\n"
       << "create_atoms 1 region sites\nmass 1 1.0\n"
       << "velocity all create " << kTemperature << " 87287 loop geom\n"
       << "pair_style lj/cut " << kCutoffSigma << "\npair_coeff 1 1 1.0 1.0 " << kCutoffSigma
       << "\n"
       << "neighbor " << kSkinSigma << " bin\n"
       << (checked ? "neigh_modify delay 0 every 1 check yes\n"
                   : "neigh_modify delay 0 every 20 check no\n")
       << "fix 1 all nve\ntimestep " << kTimeStep << "\nthermo " << steps << "\n"
       << "run " << steps << "\n";
  }
  const std::string cmd = "cd '" + dir.string() + "' && OMP_NUM_THREADS=1 " + binary +
                          " -in in.lj -log log.lammps -screen none > /dev/null 2>&1";
  const PartialPath partial(dir);  // removed too if the process is stopped
  const int status = run_command(cmd);
  std::ifstream log(dir / "log.lammps");
  std::stringstream ss;
  ss << log.rdbuf();
  const std::string text = ss.str();
  std::smatch m;
  if (status == 0 &&
      std::regex_search(text, m,
                        std::regex(R"(Loop time of ([0-9.eE+-]+) on .* with ([0-9]+) atoms)"))) {
    r.ran = true;
    r.loop_s = std::stod(m[1]);
    r.atoms = std::stoll(m[2]);
  } else {
    r.error = "lmp did not run (exit status " + std::to_string(status) + ")";
  }
  std::error_code ec;
  fs::remove_all(dir, ec);
  return r;
}

bool on_path(const std::string& binary) {
  const char* path = std::getenv("PATH");
  if (!path) return false;
  std::stringstream ss(path);
  std::string dir;
  while (std::getline(ss, dir, ':')) {
    if (!dir.empty() && access((fs::path(dir) / binary).c_str(), X_OK) == 0) return true;
  }
  return false;
}

}  // namespace

nlohmann::json run_cohesion_benchmark(const CohesionBenchOptions& o) {
  const OursResult ours = run_ours(o.particles, o.steps, o.threads);
  const double us = ours.loop_s / (double(ours.particles) * o.steps) * 1e6;
  nlohmann::json j = {
      {"benchmark", "cohesion"},
      {"system", "LAMMPS bench/in.lj, open boundaries (boundary s s s)"},
      {"particles", ours.particles},
      {"steps", o.steps},
      {"threads", o.threads},
      {"wall_s", ours.loop_s},
      {"us_per_particle_step", us},
      {"neighbour_list_builds", ours.list_builds},
      {"pair_us_per_particle_step", ours.pair_s / (double(ours.particles) * o.steps) * 1e6},
      {"neighbour_us_per_particle_step",
       ours.neighbour_s / (double(ours.particles) * o.steps) * 1e6},
      {"lammps_us_per_particle_step", nullptr},
      {"ratio_vs_lammps", nullptr}};
  if (o.run_lammps) {
    if (!on_path(o.lammps_binary)) {
      j["lammps_note"] = o.lammps_binary + " not found on PATH (Debian package lammps)";
    } else {
      const LammpsResult l = run_lammps(o.lammps_binary, o.particles, o.steps, false);
      const LammpsResult lc = run_lammps(o.lammps_binary, o.particles, o.steps, true);
      if (l.ran && l.atoms != ours.particles) {
        j["lammps_note"] = "LAMMPS made " + std::to_string(l.atoms) + " atoms, organfit " +
                           std::to_string(ours.particles) + ": not the same system";
      } else if (l.ran) {
        const double lus = l.loop_s / (double(l.atoms) * o.steps) * 1e6;
        j["lammps_atoms"] = l.atoms;
        j["lammps_wall_s"] = l.loop_s;
        j["lammps_us_per_particle_step"] = lus;
        j["lammps_threads"] = 1;
        j["ratio_vs_lammps"] = us / lus;
        if (lc.ran && lc.atoms == ours.particles) {
          const double lcus = lc.loop_s / (double(lc.atoms) * o.steps) * 1e6;
          j["lammps_checked_us_per_particle_step"] = lcus;
          j["ratio_vs_lammps_checked"] = us / lcus;
        }
      } else {
        j["lammps_note"] = l.error;
      }
    }
  }
  return j;
}

nlohmann::json run_cohesion_scaling(int threads) {
  nlohmann::json rows = nlohmann::json::array();
  double lo = 1e300, hi = 0;
  for (long long n : {1000LL, 4000LL, 10000LL, 32000LL, 100000LL, 300000LL, 1000000LL}) {
    // The same steps at every size: the rebuild rate changes over the first steps (the
    // lattice melts), so unequal step counts would compare different work per step.
    const long long steps = 50;
    const OursResult r = run_ours(n, steps, threads);
    const double us = r.loop_s / (double(r.particles) * steps) * 1e6;
    // Pairs per particle show the surface effect: small open blocks have fewer.
    rows.push_back(
        {{"particles", r.particles},
         {"steps", steps},
         {"us_per_particle_step", us},
         {"pair_us_per_particle_step", r.pair_s / (double(r.particles) * steps) * 1e6},
         {"neighbour_us_per_particle_step", r.neighbour_s / (double(r.particles) * steps) * 1e6},
         {"neighbour_list_builds", r.list_builds},
         {"pairs_per_particle", r.pairs_per_particle}});
    if (r.particles >= 9000) lo = std::min(lo, us), hi = std::max(hi, us);
  }
  return {{"benchmark", "cohesion_scaling"},
          {"threads", threads},
          {"rows", rows},
          {"spread_10k_to_1M", hi / lo - 1.0}};
}

}  // namespace organfit::bench
