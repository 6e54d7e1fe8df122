#include "organfit/geometry/signed_distance.h"

#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <climits>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <utility>

#include "organfit/geometry/counter_random.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/geometry/sample_grid.h"

namespace organfit::geometry {
namespace {
/// Physical offset (mm) -> index offset.
Eigen::Matrix3d index_map(const ImageGeometry& g) {
  return g.spacing_mm.cwiseInverse().asDiagonal() * g.direction.inverse();
}
}  // namespace

SignedDistance::SignedDistance(const LabelVolume& mask, bool smooth_it)
    : geometry_(mask.geometry), to_index_(index_map(mask.geometry)) {
  // One grid of doubles beside the mask (a million-particle body's reference has 80M
  // voxels, 640 MB a grid); the transform takes any nonzero label as inside.
  const long long total = static_cast<long long>(mask.labels.size());
  const std::vector<std::uint8_t>& inside = mask.labels;
  values_ = squared_distance_across(inside, geometry_);
  const double h = 0.5 * geometry_.spacing_mm.minCoeff();
  // An empty mask (or a full one) has no boundary: the transform's infinity stays.
#pragma omp parallel for schedule(static)
  for (long long v = 0; v < total; ++v)
    values_[v] = inside[v] != 0 ? -(std::sqrt(values_[v]) - h) : std::sqrt(values_[v]) - h;
  if (smooth_it) smooth();
}

namespace {
constexpr double kBinomial[5] = {1 / 16.0, 4 / 16.0, 6 / 16.0, 4 / 16.0, 1 / 16.0};

/// The binomial 1-4-6-4-1 of a line of n values `stride` apart in `in`, ends clamped, at
/// its place t.
inline double binomial_at(const double* in, long long stride, int n, int t) {
  double sum = 0;
  if (t >= 2 && t + 2 < n) {  // inside: no end to clamp at
    for (int o = -2; o <= 2; ++o)
      sum += kBinomial[o + 2] * in[(t + o) * stride];
  } else {
    for (int o = -2; o <= 2; ++o)
      sum += kBinomial[o + 2] * in[std::clamp(t + o, 0, n - 1) * stride];
  }
  return sum;
}

/// The passes x, y and (`across_slices`) z, from `in` into `out` (every voxel written;
/// `in` may be `out`'s own values). Each pass works a row, a slice or a plane at a time
/// copied aside: no grid besides `in` and `out`, and none at all in place.
void binomial_passes(const ImageGeometry& g, const double* in, GridBuffer<double>& out,
                     bool across_slices) {
  const int nx = g.size[0], ny = g.size[1], nz = g.size[2];
  const long long nxy = 1LL * nx * ny;
#pragma omp parallel
  {
    std::vector<double> line(static_cast<size_t>(nx));  // along x: a row at a time
#pragma omp for schedule(static) collapse(2)
    for (int k = 0; k < nz; ++k)
      for (int j = 0; j < ny; ++j) {
        const long long row = g.linear_index(0, j, k);
        std::copy(in + row, in + row + nx, line.begin());
        for (int i = 0; i < nx; ++i)
          out[static_cast<size_t>(row + i)] = binomial_at(line.data(), 1, nx, i);
      }
  }
#pragma omp parallel
  {
    std::vector<double> slice(static_cast<size_t>(nxy));  // along y: a slice at a time
#pragma omp for schedule(static)
    for (int k = 0; k < nz; ++k) {
      double* at = out.data() + nxy * k;
      std::copy(at, at + nxy, slice.begin());
      for (int j = 0; j < ny; ++j)
        for (int i = 0; i < nx; ++i)
          at[i + 1LL * nx * j] = binomial_at(slice.data() + i, nx, ny, j);
    }
  }
  if (!across_slices) return;
#pragma omp parallel
  {
    std::vector<double> plane(static_cast<size_t>(1LL * nx * nz));  // along z: an x-z plane
#pragma omp for schedule(static)
    for (int j = 0; j < ny; ++j) {
      for (int k = 0; k < nz; ++k) {
        const double* row = out.data() + 1LL * nx * j + nxy * k;
        std::copy(row, row + nx, plane.begin() + 1LL * nx * k);
      }
      for (int k = 0; k < nz; ++k) {
        double* row = out.data() + 1LL * nx * j + nxy * k;
        for (int i = 0; i < nx; ++i)
          row[i] = binomial_at(plane.data() + i, nx, nz, k);
      }
    }
  }
}
}  // namespace

SignedDistance SignedDistance::smoothed_by_passes(bool across_slices) const {
  SignedDistance out(geometry_, to_index_);  // its own gradient bound: other values
  if (!all_finite()) {                       // no boundary: nothing to smooth
    out.values_ = values_;
    return out;
  }
  // From this distance's values into one new buffer.
  out.values_ = GridBuffer<double>(values_.size());
  binomial_passes(geometry_, values_.data(), out.values_, across_slices);
  return out;
}

SignedDistance SignedDistance::smoothed() const {
  return smoothed_by_passes(true);
}

SignedDistance SignedDistance::smoothed_within_slices(double level_mm) const {
  SignedDistance out = smoothed_by_passes(false);
  const long long total = static_cast<long long>(out.values_.size());
#pragma omp parallel for schedule(static)
  for (long long v = 0; v < total; ++v)
    out.values_[static_cast<size_t>(v)] -= level_mm;
  return out;
}

bool SignedDistance::all_finite() const {
  const long long total = static_cast<long long>(values_.size());
  bool finite = true;
#pragma omp parallel for schedule(static) reduction(&& : finite)
  for (long long v = 0; v < total; ++v)
    finite = finite && std::isfinite(values_[static_cast<size_t>(v)]);
  return finite;
}

double SignedDistance::gradient_bound() const {
  std::call_once(gradient_bound_->found, [this] {
    // At a cell's corner the partials are the differences along the cell's three edges;
    // over the 8 cells of a voxel the largest is the largest difference along each axis,
    // either side.
    // Beyond the grid a voxel's neighbour is itself (at_voxel clamps): no difference.
    const ImageGeometry& g = geometry_;
    const long long stride[3] = {1, g.size[0], 1LL * g.size[0] * g.size[1]};
    gradient_bound_->largest_sq = BlockMaxima::of(g.size, [&](int i, int j, int k) {
      const double* v = values_.data() + g.linear_index(i, j, k);
      const int at[3] = {i, j, k};
      double sq = 0;
      for (int a = 0; a < 3; ++a) {
        const double below = at[a] > 0 ? std::abs(v[-stride[a]] - *v) : 0.0;
        const double above = at[a] + 1 < g.size[a] ? std::abs(v[stride[a]] - *v) : 0.0;
        const double d = std::max(below, above) / g.spacing_mm[a];
        sq += d * d;
      }
      return std::isfinite(sq) && std::isfinite(*v) ? sq : HUGE_VAL;
    });
    gradient_bound_->value = std::sqrt(gradient_bound_->largest_sq.largest());
  });
  return gradient_bound_->value;
}

double SignedDistance::gradient_bound(const Eigen::Vector3d& p_mm, double radius_mm) const {
  const ImageGeometry& g = geometry_;
  const Eigen::Vector3d idx = to_index_ * (p_mm - g.origin_mm);
  std::array<int, 3> lo, hi;
  for (int c = 0; c < 3; ++c) {
    const double reach = radius_mm / g.spacing_mm[c];
    if (!(idx[c] - reach >= 0) || !(idx[c] + reach <= g.size[c] - 1))
      return std::hypot(gradient_bound(), 1.0);
    // The voxels at the corners of the cells the box [idx - reach, idx + reach] touches.
    lo[c] = static_cast<int>(std::floor(idx[c] - reach));
    hi[c] = static_cast<int>(std::floor(idx[c] + reach)) + 1;
  }
  const double global = gradient_bound();  // the blocks found with it
  if (!std::isfinite(global)) return global;
  return std::sqrt(gradient_bound_->largest_sq.over(lo, hi));
}

void SignedDistance::smooth() {
  // Binomial 1-4-6-4-1 along each axis (a Gaussian of one voxel), ends clamped: it leaves
  // a linear field unchanged and takes the voxel steps out of a slanted boundary.
  if (!all_finite()) return;                                  // no boundary: nothing to smooth
  binomial_passes(geometry_, values_.data(), values_, true);  // in place: no new grid
}

double SignedDistance::at_voxel(int i, int j, int k) const {
  const ImageGeometry& g = geometry_;
  i = std::clamp(i, 0, g.size[0] - 1), j = std::clamp(j, 0, g.size[1] - 1),
  k = std::clamp(k, 0, g.size[2] - 1);
  return values_[static_cast<size_t>(g.linear_index(i, j, k))];
}

namespace {

/// The trilinear interpolant at index position `idx` (continuous voxel indices) of the
/// values `value(v)` at the grid's voxels (linear index v), as SignedDistance::at()
/// documents it; `gradient` as there (`to_index`: physical offset -> index offset).
template <class Value>
double interpolate_index(const ImageGeometry& g, const Eigen::Matrix3d& to_index,
                         const Eigen::Vector3d& idx, Value&& value, Eigen::Vector3d* gradient) {
  const Eigen::Vector3d hi(g.size[0] - 1, g.size[1] - 1, g.size[2] - 1);
  const Eigen::Vector3d inside = idx.cwiseMax(Eigen::Vector3d::Zero()).cwiseMin(hi);
  // Beyond the grid: the distance to the grid's nearest point is added (a lower bound
  // on the true distance, and continuous); 0 within it, where it is not worked out.
  Eigen::Vector3d beyond_mm = Eigen::Vector3d::Zero();
  double beyond = 0;
  if (!((idx.array() >= 0).all() && (idx.array() <= hi.array()).all())) {
    beyond_mm = g.direction * g.spacing_mm.cwiseProduct(idx - inside);
    beyond = beyond_mm.norm();
  }
  Eigen::Vector3i base;
  Eigen::Vector3d f;
  for (int c = 0; c < 3; ++c) {
    base[c] = std::min(static_cast<int>(std::floor(inside[c])), std::max(0, g.size[c] - 2));
    f[c] = inside[c] - base[c];
  }
  // The cell's corners: base + 0 or 1 along each axis, the same voxel along an axis of
  // one voxel (as at_voxel's clamping would give).
  const long long step[3] = {g.size[0] > 1 ? 1 : 0, g.size[1] > 1 ? g.size[0] : 0,
                             g.size[2] > 1 ? 1LL * g.size[0] * g.size[1] : 0};
  const long long corner0 = g.linear_index(base[0], base[1], base[2]);
  double sum = 0;
  Eigen::Vector3d d_index = Eigen::Vector3d::Zero();  // d value / d index, when asked
  for (int corner = 0; corner < 8; ++corner) {
    const int di = corner & 1, dj = (corner >> 1) & 1, dk = (corner >> 2) & 1;
    const double v = value(corner0 + di * step[0] + dj * step[1] + dk * step[2]);
    const double wx = di ? f[0] : 1 - f[0], wy = dj ? f[1] : 1 - f[1], wz = dk ? f[2] : 1 - f[2];
    sum += wx * wy * wz * v;
    if (gradient) {
      d_index[0] += (di ? 1 : -1) * wy * wz * v;
      d_index[1] += (dj ? 1 : -1) * wx * wz * v;
      d_index[2] += (dk ? 1 : -1) * wx * wy * v;
    }
  }
  if (gradient) {
    *gradient = to_index.transpose() * d_index;
    if (beyond > 0) *gradient = beyond_mm / beyond;  // outside the grid: straight away from it
  }
  return sum + beyond;
}

template <class Value>
double interpolate(const ImageGeometry& g, const Eigen::Matrix3d& to_index,
                   const Eigen::Vector3d& p_mm, Value&& value, Eigen::Vector3d* gradient) {
  return interpolate_index(g, to_index, to_index * (p_mm - g.origin_mm), std::forward<Value>(value),
                           gradient);
}

/// The voxels the interpolation at `p_mm` reads (linear indices), appended to `out`.
void corners_read(const ImageGeometry& g, const Eigen::Matrix3d& to_index,
                  const Eigen::Vector3d& p_mm, std::vector<long long>& out) {
  interpolate(
      g, to_index, p_mm,
      [&out](long long v) {
        out.push_back(v);
        return 0.0;
      },
      nullptr);
}

}  // namespace

double SignedDistance::at(const Eigen::Vector3d& p_mm, Eigen::Vector3d* gradient) const {
  const double* values = values_.data();
  return interpolate(
      geometry_, to_index_, p_mm, [values](long long v) { return values[v]; }, gradient);
}

namespace {
/// Each voxel's 27-neighbourhood (clamped to the grid) as two bits: 1, a value below zero
/// in it; 2, a value at or above zero. A box filter of OR along each axis in turn.
std::vector<std::uint8_t> sides_about(const ImageGeometry& g, const GridBuffer<double>& values) {
  const long long total = static_cast<long long>(values.size());
  std::vector<std::uint8_t> bits(values.size());
#pragma omp parallel for schedule(static)
  for (long long v = 0; v < total; ++v)
    bits[static_cast<size_t>(v)] = values[static_cast<size_t>(v)] < 0 ? 1 : 2;
  const long long stride[3] = {1, g.size[0], 1LL * g.size[0] * g.size[1]};
  for (int axis = 0; axis < 3; ++axis) {
    const int n = g.size[axis];
    const long long s = stride[axis];
    const int other[2] = {axis == 0 ? 1 : 0, axis == 2 ? 1 : 2};
#pragma omp parallel for schedule(static) collapse(2)
    for (int b = 0; b < g.size[other[1]]; ++b)
      for (int a = 0; a < g.size[other[0]]; ++a) {
        std::uint8_t* line = bits.data() + a * stride[other[0]] + b * stride[other[1]];
        std::uint8_t before = 0;  // the previous voxel's bits before this pass
        for (int t = 0; t < n; ++t) {
          const std::uint8_t here = line[t * s];
          const std::uint8_t after = t + 1 < n ? line[(t + 1) * s] : 0;
          line[t * s] = before | here | after;
          before = here;
        }
      }
  }
  return bits;
}
}  // namespace

double SignedDistance::volume_level() const {
  return found_levels().level_mm;
}

namespace {
constexpr double kQuarter = 0.125;  // slices: the width of a quarter of the half slice
constexpr int kQuarters = std::tuple_size_v<SignedDistance::LevelsBySlicePhase>;

/// The quarter of the half slice a sample lies in (VolumeLevels::by_slice_phase_mm): from
/// its offset u in [-1/2, 1/2) (slices) from its voxel's centre.
int slice_phase_quarter(double u) {
  return std::min(kQuarters - 1, static_cast<int>(std::abs(u) / kQuarter));
}
}  // namespace

const SignedDistance::VolumeLevels& SignedDistance::found_levels() const {
  std::call_once(volume_level_->found, [this] {
    const ImageGeometry& g = geometry_;
    const long long total = static_cast<long long>(values_.size());
    if (total == 0 || !all_finite()) return;  // no boundary: 0
    // The values' gap about zero, (below, above]: a level in it keeps every centre's side.
    double below = -HUGE_VAL, above = HUGE_VAL;
    long long inside = 0;
#pragma omp parallel for schedule(static) reduction(max : below) reduction(min : above) \
    reduction(+ : inside)
    for (long long v = 0; v < total; ++v) {
      const double x = values_[static_cast<size_t>(v)];
      if (x < 0)
        below = std::max(below, x), ++inside;
      else
        above = std::min(above, x);
    }
    if (inside == 0 || inside == total) return;
    const std::vector<std::uint8_t> sides = sides_about(g, values_);
    long long band = 0;  // voxels whose 27 neighbours are not all on one side
#pragma omp parallel for schedule(static) reduction(+ : band)
    for (long long v = 0; v < total; ++v)
      band += sides[static_cast<size_t>(v)] == 3;
    // One sample at a random place in each of s x s x s sub-cells of such a voxel (index
    // units; stratified and jittered: samples at the sub-cells' centres alone would see a
    // face of the organ at s depths, and the volume would rise by steps with the level).
    // s is the least (at most 4) that puts the estimate's standard error within 1e-4 of
    // the volume: each voxel's share inside has a variance of at most 1 / (4 s^3), so the
    // volume's (in voxels) is at most band / (4 s^3). A sample below the gap is inside at
    // any level in it, one above outside; those within it are counted in bins across it.
    // The samples are keyed by a voxel's place from the inside voxels' box grown by one
    // voxel (every voxel of the band lies in it), not by its index in the grid: the level
    // is the organ's, the same on a mask cropped about it (a model file's) as on the whole.
    int lo_i = INT_MAX, lo_j = INT_MAX, lo_k = INT_MAX, hi_i = INT_MIN, hi_j = INT_MIN;
#pragma omp parallel for collapse(2) reduction(min : lo_i, lo_j, lo_k) reduction(max : hi_i, hi_j)
    for (int k = 0; k < g.size[2]; ++k)
      for (int j = 0; j < g.size[1]; ++j)
        for (int i = 0; i < g.size[0]; ++i)
          if (values_[static_cast<size_t>(g.linear_index(i, j, k))] < 0) {
            lo_i = std::min(lo_i, i), hi_i = std::max(hi_i, i);
            lo_j = std::min(lo_j, j), hi_j = std::max(hi_j, j);
            lo_k = std::min(lo_k, k);
          }
    const long long box_x = hi_i - lo_i + 3, box_y = hi_j - lo_j + 3;
    auto key_of = [&](int i, int j, int k) {
      return (static_cast<std::uint64_t>(k - lo_k + 1) * box_y + (j - lo_j + 1)) * box_x +
             (i - lo_i + 1);
    };
    constexpr double kStandardError = 1e-4;  // of the volume, relative
    const double wanted_samples =
        band / (4 * kStandardError * kStandardError * static_cast<double>(inside) *
                static_cast<double>(inside));
    int sub = 1;
    constexpr int kMostSub = 4;  // 64 samples a voxel at most
    while (sub < kMostSub && sub * sub * sub < wanted_samples)
      ++sub;
    const int per_voxel = sub * sub * sub;
    // The samples counted apart by the quarter of the half slice they lie in (in each:
    // those within the gap by bins, those below it, those of an inside voxel); the whole's
    // are their sums.
    constexpr int kBins = 4096;
    const double width = (above - below) / kBins;
    std::vector<long long> bins(kQuarters * kBins, 0);
    std::array<long long, kQuarters> below_gap{}, of_inside{};
    long long fixed = 0;  // samples of voxels all of whose 27 neighbours are inside
    const double* values = values_.data();
#pragma omp parallel reduction(+ : fixed)
    {
      std::vector<long long> mine(kQuarters * kBins, 0);
      std::array<long long, kQuarters> my_below{}, my_inside{};
#pragma omp for schedule(dynamic, 1) collapse(2)
      for (int k = 0; k < g.size[2]; ++k)
        for (int j = 0; j < g.size[1]; ++j)
          for (int i = 0; i < g.size[0]; ++i) {
            const long long v = g.linear_index(i, j, k);
            if (sides[static_cast<size_t>(v)] != 3) {  // all 27 on one side
              fixed += sides[static_cast<size_t>(v)] == 1 ? per_voxel : 0;
              continue;
            }
            const bool voxel_inside = values[v] < 0;
            for (int sample = 0; sample < per_voxel; ++sample) {
              const std::uint64_t key =
                  3 * (key_of(i, j, k) * kMostSub * kMostSub * kMostSub + sample);
              const Eigen::Vector3d place(sample % sub + uniform01(key),
                                          (sample / sub) % sub + uniform01(key + 1),
                                          sample / (sub * sub) + uniform01(key + 2));
              const Eigen::Vector3d offset = place / sub - Eigen::Vector3d::Constant(0.5);
              const double d = interpolate_index(
                  g, to_index_, Eigen::Vector3d(i, j, k) + offset,
                  [values](long long at) { return values[at]; }, nullptr);
              const int quarter = slice_phase_quarter(offset.z());
              my_inside[quarter] += voxel_inside;
              if (d <= below)
                ++my_below[quarter];
              else if (d < above)
                ++mine[quarter * kBins +
                       std::min(kBins - 1, static_cast<int>((d - below) / width))];
            }
          }
#pragma omp critical
      {
        for (int b = 0; b < kQuarters * kBins; ++b)
          bins[b] += mine[b];
        for (int q = 0; q < kQuarters; ++q)
          below_gap[q] += my_below[q], of_inside[q] += my_inside[q];
      }
    }
    // The level below which `wanted` of the samples in `counts` (a histogram across the
    // gap) lie: within its bin, by the bin's count spread evenly; the gap's top if none.
    auto level_for = [&](const long long* counts, long long wanted) {
      double level = above;
      long long counted = 0;
      for (int b = 0; b < kBins; ++b) {
        if (counted + counts[b] >= wanted && counts[b] > 0) {
          level = below + width * (b + static_cast<double>(wanted - counted) / counts[b]);
          break;
        }
        counted += counts[b];
      }
      return std::clamp(level, std::nextafter(below, above), above);
    };
    // As many samples below the level as the inside voxels have (those of voxels inside
    // all about are below it at any level in the gap, and counted on both sides).
    std::vector<long long> all(kBins, 0);
    long long wanted = per_voxel * inside - fixed;
    for (int q = 0; q < kQuarters; ++q) {
      wanted -= below_gap[q];
      for (int b = 0; b < kBins; ++b)
        all[b] += bins[q * kBins + b];
      volume_level_->levels.by_slice_phase_mm[q] =
          level_for(bins.data() + q * kBins, of_inside[q] - below_gap[q]);
    }
    volume_level_->levels.level_mm = level_for(all.data(), wanted);
  });
  return volume_level_->levels;
}

namespace {
/// The level at t slices from the nearest plane of voxel centres (mm), and its slope along
/// t (mm per slice; 0 where it is clamped): linear on [t_q, t_q+1] between the quarters'
/// centres t_q, the first's and last's lines extended to 0 and 1/2, kept within half the
/// smallest spacing of 0.
struct LevelAtPhase {
  double level_mm, slope_mm;
};
LevelAtPhase level_by_phase(const SignedDistance::LevelsBySlicePhase& c, double t,
                            double half_spacing) {
  const int piece =
      std::clamp(static_cast<int>(std::floor((t - kQuarter / 2) / kQuarter)), 0, kQuarters - 2);
  const double f = (t - (piece + 0.5) * kQuarter) / kQuarter;
  const double level = c[piece] + f * (c[piece + 1] - c[piece]);
  const double lowest = std::nextafter(-half_spacing, 0.0);
  if (level <= lowest) return {lowest, 0.0};
  if (level >= half_spacing) return {half_spacing, 0.0};
  return {level, (c[piece + 1] - c[piece]) / kQuarter};
}
}  // namespace

double SignedDistance::slice_offset(const Eigen::Vector3d& p_mm) const {
  const double z = to_index_.row(2).dot(p_mm - geometry_.origin_mm);
  return z - std::round(z);
}

double SignedDistance::volume_level_at(const Eigen::Vector3d& p_mm) const {
  return level_by_phase(found_levels().by_slice_phase_mm, std::abs(slice_offset(p_mm)),
                        0.5 * geometry_.spacing_mm.minCoeff())
      .level_mm;
}

double SignedDistance::beyond_level(const Eigen::Vector3d& p_mm, Eigen::Vector3d* gradient) const {
  const double d = at(p_mm, gradient);
  const double u = slice_offset(p_mm);
  const LevelAtPhase level = level_by_phase(found_levels().by_slice_phase_mm, std::abs(u),
                                            0.5 * geometry_.spacing_mm.minCoeff());
  if (gradient) *gradient -= level.slope_mm * (u < 0 ? -1.0 : 1.0) * to_index_.row(2).transpose();
  return d - level.level_mm;
}

double SignedDistance::volume_level_slope() const {
  const LevelsBySlicePhase& c = found_levels().by_slice_phase_mm;
  double steepest = 0;
  for (size_t q = 0; q + 1 < c.size(); ++q)
    steepest = std::max(steepest, std::abs(c[q + 1] - c[q]) / kQuarter);
  return steepest * to_index_.row(2).norm();
}

double SignedDistance::highest_volume_level() const {
  const LevelsBySlicePhase& c = found_levels().by_slice_phase_mm;
  const double half_spacing = 0.5 * geometry_.spacing_mm.minCoeff();
  // The largest of a piecewise linear function: at a piece's end (0, a quarter's centre, 1/2).
  double highest = std::max(level_by_phase(c, 0.0, half_spacing).level_mm,
                            level_by_phase(c, 0.5, half_spacing).level_mm);
  for (size_t q = 0; q < c.size(); ++q)
    highest = std::max(highest, level_by_phase(c, (q + 0.5) * kQuarter, half_spacing).level_mm);
  return highest;
}

void SignedDistance::adopt_volume_levels(const VolumeLevels& levels) const {
  bool fits = could_be_volume_level(levels.level_mm, geometry_);
  for (double c : levels.by_slice_phase_mm)
    fits = fits && could_be_volume_level(c, geometry_);
  if (!fits)
    throw std::invalid_argument("signed distance: a volume level of " +
                                std::to_string(levels.level_mm) + " mm is not one of this grid's");
  std::call_once(volume_level_->found, [this, &levels] { volume_level_->levels = levels; });
}

bool could_be_volume_level(double level_mm, const ImageGeometry& grid) {
  return std::isfinite(level_mm) && std::abs(level_mm) <= grid.spacing_mm.maxCoeff();
}

std::vector<double> signed_distance_at(const LabelVolume& mask, const Eigen::Matrix3Xd& points_mm) {
  const ImageGeometry& g = mask.geometry;
  const Eigen::Matrix3d to_index = index_map(g);
  std::vector<long long> read;
  for (Eigen::Index c = 0; c < points_mm.cols(); ++c)
    corners_read(g, to_index, points_mm.col(c), read);
  std::sort(read.begin(), read.end());
  read.erase(std::unique(read.begin(), read.end()), read.end());
  // The voxels across the boundary from each side (a superset: the grid's faces count as
  // boundary too), in the transform's units: index times spacing along each axis.
  LabelVolume outside(g);
#pragma omp parallel for schedule(static)
  for (long long v = 0; v < static_cast<long long>(mask.labels.size()); ++v)
    outside.labels[static_cast<size_t>(v)] = mask.labels[static_cast<size_t>(v)] == 0;
  const std::vector<Eigen::Vector3i> side[2] = {surface_voxels(mask), surface_voxels(outside)};
  auto scaled = [&g](const Eigen::Vector3i& i) -> Eigen::Vector3d {
    return i.cast<double>().cwiseProduct(g.spacing_mm);
  };
  std::unique_ptr<SampleGrid> search[2];
  for (int s = 0; s < 2; ++s) {
    Eigen::Matrix3Xd at(3, static_cast<Eigen::Index>(side[s].size()));
    for (size_t k = 0; k < side[s].size(); ++k)
      at.col(static_cast<Eigen::Index>(k)) = scaled(side[s][k]);
    search[s] = std::make_unique<SampleGrid>(at, SampleGrid::surface_cell_mm(at));
  }
  const double h = 0.5 * g.spacing_mm.minCoeff();
  std::vector<double> value(read.size());
#pragma omp parallel for schedule(dynamic, 64)
  for (long long r = 0; r < static_cast<long long>(read.size()); ++r) {
    const long long v = read[static_cast<size_t>(r)];
    const Eigen::Vector3i at(static_cast<int>(v % g.size[0]),
                             static_cast<int>((v / g.size[0]) % g.size[1]),
                             static_cast<int>(v / (1LL * g.size[0] * g.size[1])));
    const bool in = mask.labels[static_cast<size_t>(v)] != 0;
    const int s = in ? 1 : 0;  // an inside voxel's distance is to the outside's voxels
    const int nearest = search[s]->nearest(scaled(at)).first;
    double d2 = std::numeric_limits<double>::infinity();
    if (nearest >= 0) {  // summed as the transform sums it: x, then y, then z
      const Eigen::Vector3i d = side[s][static_cast<size_t>(nearest)] - at;
      const double dx = d.x() * g.spacing_mm.x(), dy = d.y() * g.spacing_mm.y(),
                   dz = d.z() * g.spacing_mm.z();
      d2 = dz * dz + (dy * dy + dx * dx);
    }
    value[static_cast<size_t>(r)] = in ? -(std::sqrt(d2) - h) : std::sqrt(d2) - h;
  }
  std::vector<double> out(static_cast<size_t>(points_mm.cols()));
  for (Eigen::Index c = 0; c < points_mm.cols(); ++c)
    out[static_cast<size_t>(c)] = interpolate(
        g, to_index, points_mm.col(c),
        [&](long long v) {
          return value[static_cast<size_t>(std::lower_bound(read.begin(), read.end(), v) -
                                           read.begin())];
        },
        nullptr);
  return out;
}

}  // namespace organfit::geometry
