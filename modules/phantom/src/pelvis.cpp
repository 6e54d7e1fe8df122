#include "organfit/phantom/pelvis.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "organfit/geometry/counter_random.h"

namespace organfit::phantom {
namespace {

constexpr double kPi = 3.14159265358979323846;

struct Tissue {
  std::uint8_t label;
  float hu;
};

// Tissue values (HU) as in a pelvic planning CT.
constexpr float kHuAir = -1000, kHuFat = -95, kHuMuscle = 55, kHuCortical = 1100,
                kHuCancellous = 260, kHuFemurCancellous = 300, kHuProstate = 42, kHuUrine = 12,
                kHuRectalWall = 38, kHuGas = -880, kHuFaeces = 15;

/// Distance (mm) outside an axis-aligned ellipse of semi-axes (a, b) centred at c,
/// measured along the ray from c (negative inside).
double radial_excess(double x, double y, double cx, double cy, double a, double b) {
  const double dx = x - cx, dy = y - cy, r = std::hypot(dx, dy);
  if (r == 0) return -std::min(a, b);
  const double c = dx / r, s = dy / r;
  const double boundary = a * b / std::hypot(b * c, a * s);
  return r - boundary;
}

double sq(double v) {
  return v * v;
}

// --- the anatomy, one function per structure -------------------------------------------

/// radial_excess(...) < 0, without its two hypot calls away from the ellipse: there the
/// ellipse's own equation, 2% from 1, has the same answer (radial_excess errs by parts in
/// 1e15).
bool inside_ellipse(double x, double y, double cx, double cy, double a, double b) {
  if (!(a > 0 && b > 0)) return radial_excess(x, y, cx, cy, a, b) < 0;  // far along z
  const double q = sq((x - cx) / a) + sq((y - cy) / b);
  if (q < 0.98) return true;
  if (q > 1.02) return false;
  return radial_excess(x, y, cx, cy, a, b) < 0;
}

bool in_body(const Eigen::Vector3d& p) {
  return inside_ellipse(p.x(), p.y(), 0, 5, 175 + 0.2 * p.z(), 115);
}

bool in_muscle_layer(const Eigen::Vector3d& p) {  // inside the subcutaneous fat
  return inside_ellipse(p.x(), p.y(), 0, 5, 157 + 0.2 * p.z(), 97);
}

/// The pelvic cavity's wall: an ellipse narrowing downwards.
double cavity_excess(const Eigen::Vector3d& p) {
  const double narrowing = std::clamp(-p.z() * 0.15, 0.0, 12.0);
  return radial_excess(p.x(), p.y(), 0, 8, 62 - narrowing, 52 - 0.5 * narrowing);
}

/// Pelvic bone: a 10 mm ring around the cavity, present laterally (ilium, ischium),
/// in front only at the pubis's level, behind only above the coccyx's tip; open at the
/// sciatic notches. Returns the HU (cortical 2.5 mm shells, cancellous inside) or NaN.
double pelvic_bone_hu(const Eigen::Vector3d& p) {
  const double d = cavity_excess(p);
  if (d < 0 || d >= 10) return std::nan("");
  const double angle =
      std::atan2(std::abs(p.x()), p.y() - 8) * 180 / kPi;  // 0 = posterior, 180 = anterior
  bool present = false;
  if (angle >= 75 && angle <= 150) present = p.z() > -45;  // ischium and ilium
  if (angle > 150) present = p.z() > -30 && p.z() < 10;    // pubis and symphysis
  if (angle < 30) present = p.z() > -20;                   // sacrum and coccyx
  if (!present) return std::nan("");
  return (d < 2.5 || d > 7.5) ? kHuCortical : kHuCancellous;
}

/// A femur (head and neck), side = +1 left, -1 right. HU or NaN.
double femur_hu(const Eigen::Vector3d& p, double side) {
  const Eigen::Vector3d head(side * 98, 8, -5), neck_end(side * 150, 10, -55);
  const double head_r = 24, neck_r = 14;
  // Beyond the box that holds the head's ball and the neck's capsule, by 1 mm (far more
  // than the tests below can round by): not in the femur, without them (most of the body).
  const Eigen::Vector3d lo = (head.array() - head_r).min(head.cwiseMin(neck_end).array() - neck_r),
                        hi = (head.array() + head_r).max(head.cwiseMax(neck_end).array() + neck_r);
  if (((p.array() < lo.array() - 1) || (p.array() > hi.array() + 1)).any()) return std::nan("");
  const double dh = (p - head).norm();
  const Eigen::Vector3d axis = (neck_end - head).normalized();
  const double t = std::clamp((p - head).dot(axis), 0.0, (neck_end - head).norm());
  const double dn = (p - (head + t * axis)).norm();
  const double depth = std::max(head_r - dh, neck_r - dn);  // > 0 inside
  if (depth <= 0) return std::nan("");
  return depth < 2.5 ? kHuCortical : kHuFemurCancellous;
}

/// Prostate: an ellipsoid (25 x 18 x 18.6 mm semi-axes) wider at its base (superior),
/// its posterior face flattened against the rectum.
bool in_prostate(const Eigen::Vector3d& p) {
  const double c = 18.6, t = p.z() / c;
  const double a = 25 * (1 + 0.12 * t);
  const double b = p.y() > 0 ? 16.5 : 19.5;
  return sq(p.x() / a) + sq(p.y() / b) + sq(t) < 1;
}

/// Bladder: an ellipsoid whose base rests on the prostate.
bool in_bladder(const Eigen::Vector3d& p) {
  return sq(p.x() / 42) + sq((p.y() + 10) / 32) + sq((p.z() - 47) / 30) < 1;
}

/// Rectum: a tube along z, curving backwards above the prostate; outer radius 15 mm,
/// wall 4 mm. Returns the HU (wall, gas in the anterior lumen, faeces) or NaN.
double rectum_hu(const Eigen::Vector3d& p) {
  const double cy = 38 + 0.12 * std::max(0.0, p.z()), outer_r = 15;
  // r >= outer_r wherever either side is (hypot is never below the larger): no hypot needed.
  if (std::abs(p.x()) >= outer_r || std::abs(p.y() - cy) >= outer_r) return std::nan("");
  const double r = std::hypot(p.x(), p.y() - cy);
  if (r >= outer_r || p.z() < -75) return std::nan("");
  if (r >= 11) return kHuRectalWall;
  const bool gas = p.z() > -30 && p.z() < 40 && p.y() < cy + 2;  // gas rises anteriorly (supine)
  return gas ? kHuGas : kHuFaeces;
}

Tissue tissue_at(const Eigen::Vector3d& p) {
  if (!in_body(p)) return {kAir, kHuAir};
  if (in_prostate(p)) return {kProstate, kHuProstate};
  if (const double hu = rectum_hu(p); !std::isnan(hu)) return {kRectum, static_cast<float>(hu)};
  if (in_bladder(p)) return {kBladder, kHuUrine};
  if (const double hu = femur_hu(p, +1); !std::isnan(hu))
    return {kFemurLeft, static_cast<float>(hu)};
  if (const double hu = femur_hu(p, -1); !std::isnan(hu))
    return {kFemurRight, static_cast<float>(hu)};
  if (const double hu = pelvic_bone_hu(p); !std::isnan(hu))
    return {kPelvicBone, static_cast<float>(hu)};
  if (cavity_excess(p) < 0) return {kSoftTissue, kHuFat};  // pelvic fat around the organs
  if (in_muscle_layer(p)) return {kMuscle, kHuMuscle};
  return {kSoftTissue, kHuFat};  // subcutaneous fat
}

/// A standard normal deviate from (seed, index): splitmix64 then Box-Muller, so every
/// voxel's noise is fixed whatever the thread count or order.
double gaussian(std::uint64_t seed, std::uint64_t index) {
  using geometry::splitmix64;
  const std::uint64_t a = splitmix64(seed * 0x100000001b3ULL ^ splitmix64(2 * index)),
                      b = splitmix64(a ^ splitmix64(2 * index + 1));
  const double u1 = (static_cast<double>(a >> 11) + 0.5) * 0x1.0p-53,
               u2 = static_cast<double>(b >> 11) * 0x1.0p-53;
  return std::sqrt(-2 * std::log(u1)) * std::cos(2 * kPi * u2);
}

bool in_structure(const Eigen::Vector3d& p, std::uint8_t label) {
  if (label == kAir) return in_body(p);  // the body: all that tissue_at does not call air
  return tissue_at(p).label == label;
}

}  // namespace

const std::vector<PelvisStructure>& pelvis_structures() {
  static const std::vector<PelvisStructure> structures = {
      {kAir, "Body", {0, 255, 0}, "EXTERNAL"},
      {kBladder, "Bladder", {255, 255, 0}, "ORGAN"},
      {kRectum, "Rectum", {150, 75, 0}, "ORGAN"},
      {kProstate, "Prostate", {255, 0, 0}, "ORGAN"},
      {kFemurLeft, "Femur_L", {200, 200, 255}, "ORGAN"},
      {kFemurRight, "Femur_R", {200, 200, 255}, "ORGAN"},
      {kPelvicBone, "PelvicBone", {255, 255, 255}, "ORGAN"},
  };
  return structures;
}

std::uint8_t pelvis_label_at(const Eigen::Vector3d& p_mm) {
  return tissue_at(p_mm).label;
}

PelvisPhantom make_pelvis_phantom(const PelvisOptions& o) {
  if (o.columns < 8 || o.rows < 8 || o.slices < 8)
    throw std::invalid_argument("phantom: at least 8 voxels per axis");
  if (!(o.pixel_mm > 0) || !(o.slice_mm > 0) || !(o.noise_hu >= 0))
    throw std::invalid_argument("phantom: spacing must be positive and noise non-negative");
  PelvisPhantom ph;
  geometry::ImageGeometry& g = ph.geometry;
  g.size = {o.columns, o.rows, o.slices};
  g.spacing_mm = Eigen::Vector3d(o.pixel_mm, o.pixel_mm, o.slice_mm);
  // Field of view centred on (0, 5) in-plane (the body's centre), slices on the prostate.
  g.origin_mm =
      Eigen::Vector3d(-0.5 * (o.columns - 1) * o.pixel_mm, 5 - 0.5 * (o.rows - 1) * o.pixel_mm,
                      -0.5 * (o.slices - 1) * o.slice_mm);
  ph.labels = geometry::LabelVolume(g);
  ph.hu.assign(static_cast<size_t>(g.voxel_count()), 0.0f);
  std::vector<float> centre_hu(ph.hu.size());

  // Pass 1: the tissue at every voxel centre.
#pragma omp parallel for schedule(dynamic, 1)
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        const auto v = static_cast<size_t>(g.linear_index(i, j, k));
        const Tissue t = tissue_at(g.index_to_physical(Eigen::Vector3d(i, j, k)));
        ph.labels.labels[v] = t.label;
        centre_hu[v] = t.hu;
      }
      // Pass 2: partial volume where a face neighbour's tissue differs, then noise.
#pragma omp parallel for schedule(dynamic, 1)
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        const auto v = static_cast<size_t>(g.linear_index(i, j, k));
        bool boundary = false;
        const int di[6] = {1, -1, 0, 0, 0, 0}, dj[6] = {0, 0, 1, -1, 0, 0},
                  dk[6] = {0, 0, 0, 0, 1, -1};
        for (int n = 0; n < 6 && !boundary; ++n) {
          const int a = i + di[n], b = j + dj[n], c = k + dk[n];
          if (a < 0 || b < 0 || c < 0 || a >= g.size[0] || b >= g.size[1] || c >= g.size[2])
            continue;
          boundary = centre_hu[static_cast<size_t>(g.linear_index(a, b, c))] != centre_hu[v];
        }
        double value = centre_hu[v];
        if (boundary) {
          double sum = 0;
          for (int c = -1; c <= 1; ++c)
            for (int b = -1; b <= 1; ++b)
              for (int a = -1; a <= 1; ++a)
                sum += tissue_at(g.index_to_physical(
                                     Eigen::Vector3d(i + a / 3.0, j + b / 3.0, k + c / 3.0)))
                           .hu;
          value = sum / 27;
        }
        if (o.noise_hu > 0 && ph.labels.labels[v] != kAir)
          value += o.noise_hu * gaussian(o.seed, v);
        ph.hu[v] = static_cast<float>(value);
      }
  return ph;
}

std::vector<geometry::SliceContour> pelvis_true_contours(const geometry::LabelVolume& labels,
                                                         const PelvisStructure& structure,
                                                         int supersample) {
  const geometry::ImageGeometry& g = labels.geometry;
  supersample = std::max(1, supersample);
  std::vector<geometry::SliceContour> contours;
  const double fine = 1.0 / supersample;
  for (int k = 0; k < g.size[2]; ++k) {
    // The structure's extent on this slice, from its voxel centres, grown by 2 voxels.
    int i0 = g.size[0], i1 = -1, j0 = g.size[1], j1 = -1;
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i)
        if (structure.label == kAir ? labels.at(i, j, k) != kAir
                                    : labels.at(i, j, k) == structure.label) {
          i0 = std::min(i0, i), i1 = std::max(i1, i), j0 = std::min(j0, j), j1 = std::max(j1, j);
        }
    if (i1 < 0) continue;
    i0 = std::max(0, i0 - 2), j0 = std::max(0, j0 - 2);
    i1 = std::min(g.size[0] - 1, i1 + 2), j1 = std::min(g.size[1] - 1, j1 + 2);
    // A fine grid over that extent, on the slice plane (one voxel thick).
    geometry::ImageGeometry fg;
    fg.size = {(i1 - i0) * supersample + 1, (j1 - j0) * supersample + 1, 1};
    fg.spacing_mm =
        Eigen::Vector3d(g.spacing_mm[0] * fine, g.spacing_mm[1] * fine, g.spacing_mm[2]);
    fg.direction = g.direction;
    fg.origin_mm = g.index_to_physical(Eigen::Vector3d(i0, j0, k));
    geometry::LabelVolume mask(fg);
#pragma omp parallel for schedule(static)
    for (int b = 0; b < fg.size[1]; ++b)
      for (int a = 0; a < fg.size[0]; ++a)
        mask.at(a, b, 0) =
            in_structure(fg.index_to_physical(Eigen::Vector3d(a, b, 0)), structure.label) ? 1 : 0;
    for (auto& c : geometry::slice_contours(mask, 1)) {
      c.k = k;
      contours.push_back(std::move(c));
    }
  }
  return contours;
}

}  // namespace organfit::phantom
