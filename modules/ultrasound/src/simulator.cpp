#include "organfit/ultrasound/simulator.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace organfit::ultrasound {
namespace {

constexpr double kPi = 3.14159265358979323846;

std::uint64_t mix(std::uint64_t z) {
  z += 0x9e3779b97f4a7c15ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

/// Unit-mean Rayleigh deviate from (seed, index).
double rayleigh(std::uint64_t seed, std::uint64_t index) {
  const double u =
      (static_cast<double>(mix(seed * 0x100000001b3ULL ^ mix(index)) >> 11) + 0.5) * 0x1.0p-53;
  return std::sqrt(-2.0 * std::log(u)) / std::sqrt(kPi / 2.0);
}

}  // namespace

SimulatedUltrasound simulate_bmode(const geometry::LabelVolume& labels,
                                   const std::vector<float>& hu, const ProbePose& probe,
                                   const SimulatorOptions& o) {
  const auto& g = labels.geometry;
  if (hu.size() != labels.labels.size())
    throw std::invalid_argument("simulate_bmode: HU and labels differ in size");
  return simulate_bmode(
      [&](const Eigen::Vector3d& p) {
        const Eigen::Vector3d idx = g.physical_to_index(p);
        const int i = static_cast<int>(std::lround(idx.x())),
                  j = static_cast<int>(std::lround(idx.y())),
                  k = static_cast<int>(std::lround(idx.z()));
        if (i < 0 || j < 0 || k < 0 || i >= g.size[0] || j >= g.size[1] || k >= g.size[2])
          return TissueSample{};
        const auto v = static_cast<size_t>(g.linear_index(i, j, k));
        return TissueSample{labels.labels[v], hu[v]};
      },
      probe, o);
}

SimulatedUltrasound simulate_bmode(const TissueAt& tissue_at, const ProbePose& probe,
                                   const SimulatorOptions& o) {
  const Eigen::Vector3d axis = probe.axis.normalized(), lateral = probe.lateral.normalized();
  if (std::abs(axis.dot(lateral)) > 1e-6 || !axis.allFinite() || !lateral.allFinite())
    throw std::invalid_argument(
        "simulate_bmode: the probe's axis and lateral direction must be perpendicular");
  if (!(o.max_depth_mm > o.probe_radius_mm) || o.lateral_rays < 2 || o.elevation_rays < 2 ||
      !(o.ray_step_mm > 0) || !(o.voxel_mm > 0))
    throw std::invalid_argument("simulate_bmode: bad field of view or sampling");
  const Eigen::Vector3d elevation = axis.cross(lateral);
  const double tl = std::tan(o.lateral_half_angle_deg * kPi / 180),
               te = std::tan(o.elevation_half_angle_deg * kPi / 180);
  const int nl = o.lateral_rays, ne = o.elevation_rays;
  const int nr =
      static_cast<int>(std::floor((o.max_depth_mm - o.probe_radius_mm) / o.ray_step_mm)) + 1;

  // Ray directions: uniform in the tangents of the two angles (a pyramid).
  auto direction = [&](int a, int b) {
    const double u = -tl + 2 * tl * a / (nl - 1), v = -te + 2 * te * b / (ne - 1);
    return (axis + u * lateral + v * elevation).normalized();
  };

  // Echo amplitude along every ray (linear), then log compression.
  std::vector<float> echo(static_cast<size_t>(nl) * ne * nr, 0.0f);
  std::vector<std::vector<Eigen::Vector3d>> truth(static_cast<size_t>(nl) * ne);
  const double alpha =
      o.attenuation_db_per_mm / 20.0 * std::log(10.0);  // amplitude, per mm of depth
#pragma omp parallel for schedule(dynamic, 4)
  for (int b = 0; b < ne; ++b)
    for (int a = 0; a < nl; ++a) {
      const Eigen::Vector3d d = direction(a, b);
      const size_t ray = static_cast<size_t>(b) * nl + a;
      int previous = -2;
      bool shadow = false;
      int bright = 0;  // samples left of the current specular line
      const int line_samples =
          std::max(1, static_cast<int>(std::lround(o.specular_mm / o.ray_step_mm)));
      const int half_line = line_samples / 2;
      for (int s = 0; s < nr; ++s) {
        const double r = o.probe_radius_mm + s * o.ray_step_mm;
        const Eigen::Vector3d p = probe.position_mm + r * d;
        const TissueSample here = tissue_at(p);
        const int label = std::clamp(here.label, -1, 255);
        const float value = here.hu;
        double e = 0;
        if (label >= 0 && !shadow) {
          const double sp =
              o.speckle > 0 ? (1 - o.speckle) + o.speckle * rayleigh(o.seed, ray * nr + s) : 1.0;
          e = o.echogenicity[static_cast<size_t>(label)] * sp;
          if (previous >= 0 && label != previous) {
            // A bright line centred on the interface (the pulse's axial extent): its first
            // half goes onto the samples already made.
            for (int q = std::max(0, s - half_line); q < s; ++q)
              echo[ray * nr + q] +=
                  static_cast<float>(o.specular * std::exp(-alpha * q * o.ray_step_mm));
            bright = line_samples - half_line;
            if (o.organ_label != 0 && (label == o.organ_label) != (previous == o.organ_label))
              truth[ray].push_back(p - 0.5 * o.ray_step_mm * d);
          }
          if (bright > 0) e += o.specular, --bright;
          if (value < -400 || value > 400) {  // gas or bone: a strong echo, then nothing
            e += 2.0 * o.specular;
            shadow = true;
          }
          e *= std::exp(-alpha * (r - o.probe_radius_mm));
        }
        previous = label;
        echo[ray * nr + s] = static_cast<float>(e);
      }
    }

  // Cartesian output grid covering the field of view, aligned with the CT's axes.
  Eigen::Vector3d lo = probe.position_mm, hi = probe.position_mm;
  for (int a : {0, nl - 1})
    for (int b : {0, ne - 1})
      for (double r : {o.probe_radius_mm, o.max_depth_mm}) {
        const Eigen::Vector3d p = probe.position_mm + r * direction(a, b);
        lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
      }
  const Eigen::Vector3d tip = probe.position_mm + o.max_depth_mm * axis;
  lo = lo.cwiseMin(tip), hi = hi.cwiseMax(tip);
  SimulatedUltrasound out;
  auto& og = out.geometry;
  for (int d = 0; d < 3; ++d)
    og.size[d] = static_cast<int>(std::ceil((hi[d] - lo[d]) / o.voxel_mm)) + 1;
  og.spacing_mm = Eigen::Vector3d::Constant(o.voxel_mm);
  og.origin_mm = lo;  // identity direction: the CT's patient axes
  out.bmode.assign(static_cast<size_t>(og.voxel_count()), 0);
  out.in_view.assign(out.bmode.size(), 0);
  const double floor_db = -o.dynamic_range_db;
#pragma omp parallel for schedule(dynamic, 1)
  for (int k = 0; k < og.size[2]; ++k)
    for (int j = 0; j < og.size[1]; ++j)
      for (int i = 0; i < og.size[0]; ++i) {
        const Eigen::Vector3d v =
            og.index_to_physical(Eigen::Vector3d(i, j, k)) - probe.position_mm;
        const double along = v.dot(axis);
        if (along <= 0) continue;
        const double u = v.dot(lateral) / along, w = v.dot(elevation) / along, r = v.norm();
        if (std::abs(u) > tl || std::abs(w) > te || r < o.probe_radius_mm || r > o.max_depth_mm)
          continue;
        const double fa = (u + tl) / (2 * tl) * (nl - 1), fb = (w + te) / (2 * te) * (ne - 1);
        const double fr = (r - o.probe_radius_mm) / o.ray_step_mm;
        const int a = std::min(nl - 1, static_cast<int>(std::lround(fa))),
                  b = std::min(ne - 1, static_cast<int>(std::lround(fb)));
        const int s = std::min(nr - 1, static_cast<int>(std::lround(fr)));
        const double e = echo[(static_cast<size_t>(b) * nl + a) * nr + s];
        const double db = e > 0 ? 20 * std::log10(e) : floor_db;
        const auto at = static_cast<size_t>(og.linear_index(i, j, k));
        out.bmode[at] = static_cast<std::uint8_t>(
            std::clamp((db - floor_db) / o.dynamic_range_db * 255.0, 1.0, 255.0));
        out.in_view[at] = 1;
      }
  for (auto& t : truth)
    out.true_boundary_mm.insert(out.true_boundary_mm.end(), t.begin(), t.end());
  return out;
}

}  // namespace organfit::ultrasound
