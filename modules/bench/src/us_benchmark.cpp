#include "organfit/bench/us_benchmark.h"

#include <omp.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "organfit/support/resources.h"
#include "organfit/ultrasound/boundary_points.h"
#include "organfit/ultrasound/sequence_metafile.h"

namespace organfit::bench {
namespace {

constexpr double kRadius = 30.0;

/// Log-compressed B-mode grey of a sphere: 0.3 inside, 0.9 outside, Rayleigh speckle.
float grey_at(const Eigen::Vector3d& p, std::uint64_t index) {
  std::uint64_t z = index * 0x9e3779b97f4a7c15ULL + 0x632be59bd9b4e019ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  z ^= z >> 31;
  const double u = (static_cast<double>(z >> 11) + 0.5) * 0x1.0p-53;
  const double speckle = std::sqrt(-2.0 * std::log(u)) / std::sqrt(M_PI / 2.0);
  const double r = p.norm();
  double echo = (r < kRadius ? 0.3 : 0.9) * speckle;
  if (std::abs(r - kRadius) < 0.5) echo += 0.8;  // the capsule's bright line
  const double db = echo > 0 ? 20 * std::log10(echo) : -50;
  return static_cast<float>(std::clamp((db + 50) / 50 * 255, 1.0, 255.0));
}

std::pair<double, double> errors(const std::vector<ultrasound::BoundaryPoint>& points) {
  std::vector<double> e;
  for (const auto& p : points)
    e.push_back(std::abs(p.p_mm.norm() - kRadius));
  std::sort(e.begin(), e.end());
  if (e.empty()) return {-1, -1};
  return {e[e.size() / 2],
          static_cast<double>(std::upper_bound(e.begin(), e.end(), 1.5) - e.begin()) / e.size()};
}

}  // namespace

nlohmann::json run_us_benchmark(const UsBenchOptions& o) {
  if (o.threads > 0) omp_set_num_threads(o.threads);
  // The volume.
  geometry::ImageGeometry g;
  g.size = {o.volume_size, o.volume_size, o.volume_size};
  g.spacing_mm = Eigen::Vector3d::Constant(0.4);
  g.origin_mm = Eigen::Vector3d::Constant(-0.2 * (o.volume_size - 1));
  std::vector<float> volume(static_cast<size_t>(g.voxel_count()));
#pragma omp parallel for schedule(static)
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        const long long v = g.linear_index(i, j, k);
        volume[static_cast<size_t>(v)] =
            grey_at(g.index_to_physical(Eigen::Vector3d(i, j, k)), static_cast<std::uint64_t>(v));
      }
  ultrasound::BoundaryOptions bo;
  bo.centre_mm = Eigen::Vector3d(2, -1, 1);
  bo.r_max_mm = 40;
  Stopwatch volume_clock;
  const auto vr = ultrasound::boundary_points(g, volume, nullptr, bo);
  const double volume_s = volume_clock.elapsed_s();
  volume.clear();
  volume.shrink_to_fit();

  // The sweep: frames 640 x 480 at 0.2 mm, planes tilted by +-40 degrees about x.
  ultrasound::TrackedSweep sweep;
  for (int f = 0; f < o.frames; ++f) {
    const double tilt = (-40.0 + 80.0 * f / std::max(1, o.frames - 1)) * M_PI / 180;
    ultrasound::TrackedFrame frame;
    frame.index = f;
    frame.width = 640, frame.height = 480;
    frame.pixel_to_ct_mm.setIdentity();
    const Eigen::Vector3d beam(0, -std::cos(tilt), std::sin(tilt));
    frame.pixel_to_ct_mm.block<3, 1>(0, 0) = 0.2 * Eigen::Vector3d::UnitX();
    frame.pixel_to_ct_mm.block<3, 1>(0, 1) = 0.2 * beam;
    frame.pixel_to_ct_mm.block<3, 1>(0, 2) = Eigen::Vector3d::UnitX().cross(beam);
    frame.pixel_to_ct_mm.block<3, 1>(0, 3) =
        Eigen::Vector3d(-64, 45, 0);  // probe 45 mm behind the centre
    frame.pixels.resize(640 * 480);
    for (int r = 0; r < 480; ++r)
      for (int c = 0; c < 640; ++c)
        frame.pixels[static_cast<size_t>(r) * 640 + c] = grey_at(
            (frame.pixel_to_ct_mm * Eigen::Vector4d(c, r, 0, 1)).head<3>(),
            static_cast<std::uint64_t>(f) * 640 * 480 + static_cast<std::uint64_t>(r) * 640 + c);
    sweep.frames.push_back(std::move(frame));
  }
  Stopwatch sweep_clock;
  const auto sr = ultrasound::sweep_boundary_points(sweep, bo);
  const double sweep_s = sweep_clock.elapsed_s();
  const auto [vmed, vwithin] = errors(vr.points);
  const auto [smed, swithin] = errors(sr.points);
  return {{"benchmark", "us"},
          {"threads", omp_get_max_threads()},
          {"volume",
           {{"size", o.volume_size},
            {"wall_s", volume_s},
            {"target_s", 2.0},
            {"meets_target", volume_s <= 2.0},
            {"points", vr.points.size()},
            {"median_error_mm", vmed},
            {"within_1_5_mm", vwithin}}},
          {"sweep",
           {{"frames", o.frames},
            {"frame_size", {640, 480}},
            {"wall_s", sweep_s},
            {"target_s", 2.0},
            {"meets_target", sweep_s <= 2.0},
            {"points", sr.points.size()},
            {"median_error_mm", smed},
            {"within_1_5_mm", swithin}}},
          {"peak_memory_mib", peak_memory_mib()}};
}

}  // namespace organfit::bench
