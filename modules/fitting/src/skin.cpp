#include "organfit/fitting/skin.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <stdexcept>

#include "organfit/particles/neighbour_list.h"

namespace organfit::fitting {

SkinDetector::SkinDetector(double voxel_mm, double radius_mm, double recompute_fraction)
    : voxel_mm_(voxel_mm), radius_mm_(radius_mm), recompute_fraction_(recompute_fraction) {
  if (!(voxel_mm > 0) || !std::isfinite(voxel_mm))
    throw std::invalid_argument("skin: voxel size must be > 0 mm");
  if (!(radius_mm > 0)) throw std::invalid_argument("skin: particle radius must be > 0 mm");
  if (!(recompute_fraction > 0 && recompute_fraction <= 1))
    throw std::invalid_argument("skin: recompute fraction must be in (0, 1]");
}

bool SkinDetector::update(const Eigen::Matrix3Xd& x) {
  if (valid_ && x.cols() == x_at_compute_.cols()) {
    const double limit = recompute_fraction_ * voxel_mm_;
    const long n = static_cast<long>(x.cols());
    double largest2 = 0;  // the largest squared move since the last computation (mm^2)
#pragma omp parallel for reduction(max : largest2) if (n >= particles::kParallelMinParticles)
    for (long i = 0; i < n; ++i)
      largest2 = std::max(largest2, (x.col(i) - x_at_compute_.col(i)).squaredNorm());
    if (largest2 <= limit * limit) return false;
  }
  compute(x);
  return true;
}

void SkinDetector::compute(const Eigen::Matrix3Xd& x) {
  ++computations_;
  valid_ = true;
  x_at_compute_ = x;
  const int n = static_cast<int>(x.cols());
  skin_.clear();
  is_skin_.assign(n, 0);
  if (n == 0) {
    grid_ = {};
    closed_.clear();
    return;
  }
  // 1. The bounding box of the balls, one free voxel of margin all round.
  const double h = voxel_mm_;
  const Eigen::Vector3d lo = x.rowwise().minCoeff().array() - radius_mm_ - 1.5 * h;
  const Eigen::Vector3d hi = x.rowwise().maxCoeff().array() + radius_mm_ + 1.5 * h;
  grid_ = {};
  grid_.spacing_mm = Eigen::Vector3d::Constant(h);
  grid_.origin_mm = lo.array() + 0.5 * h;  // voxel centres
  for (int d = 0; d < 3; ++d)
    grid_.size[d] = static_cast<int>(std::ceil((hi[d] - lo[d]) / h));
  const int nx = grid_.size[0], ny = grid_.size[1], nz = grid_.size[2];
  const size_t total = static_cast<size_t>(grid_.voxel_count());
  std::vector<std::uint8_t> kept(total, 0);

  // 2. Voxels intersecting a ball: the box-to-centre distance is at most rho.
  const double r2 = radius_mm_ * radius_mm_;
  auto for_each_voxel_of = [&](int i, auto&& visit) {
    const Eigen::Vector3d c = x.col(i);
    int a[3], b[3];
    for (int d = 0; d < 3; ++d) {
      a[d] = std::max(0, static_cast<int>(std::floor((c[d] - radius_mm_ - lo[d]) / h)));
      b[d] = std::min(grid_.size[d] - 1,
                      static_cast<int>(std::floor((c[d] + radius_mm_ - lo[d]) / h)));
    }
    for (int k = a[2]; k <= b[2]; ++k)
      for (int j = a[1]; j <= b[1]; ++j)
        for (int v = a[0]; v <= b[0]; ++v) {
          double d2 = 0;
          const int idx[3] = {v, j, k};
          for (int d = 0; d < 3; ++d) {
            const double vlo = lo[d] + idx[d] * h;
            const double g = std::max({0.0, vlo - c[d], c[d] - (vlo + h)});
            d2 += g * g;
          }
          if (d2 <= r2) visit(grid_.linear_index(v, j, k));
        }
  };
  const bool parallel = n >= particles::kParallelMinParticles;
#pragma omp parallel for schedule(static) if (parallel)
  for (int i = 0; i < n; ++i)
    for_each_voxel_of(i, [&](long long v) {
#pragma omp atomic write
      kept[v] = 1;  // balls overlap: several threads may set one voxel
    });

  // 3. Boundary voxels: kept, with at least one of the 26 neighbours not kept. The
  // margin guarantees every kept voxel has all 26 neighbours on the grid.
  std::vector<std::uint8_t> boundary(total, 0);
#pragma omp parallel for schedule(static) if (parallel)
  for (int k = 1; k < nz - 1; ++k)
    for (int j = 1; j < ny - 1; ++j)
      for (int v = 1; v < nx - 1; ++v) {
        const long long idx = grid_.linear_index(v, j, k);
        if (!kept[idx]) continue;
        bool full = true;
        for (int dz = -1; dz <= 1 && full; ++dz)
          for (int dy = -1; dy <= 1 && full; ++dy)
            for (int dx = -1; dx <= 1 && full; ++dx)
              if (!kept[grid_.linear_index(v + dx, j + dy, k + dz)]) full = false;
        boundary[idx] = !full;
      }

#pragma omp parallel for schedule(static) if (parallel)
  for (int i = 0; i < n; ++i) {  // 4. Skin particles touch a boundary voxel.
    bool touches = false;
    for_each_voxel_of(i, [&](long long v) { touches = touches || boundary[v]; });
    is_skin_[i] = touches;
  }
  for (int i = 0; i < n; ++i)
    if (is_skin_[i]) skin_.push_back(i);

  // Closed body: everything not reachable from the border through free voxels (6-
  // connected). Free voxels come in runs along x; two runs in rows adjacent in y or z
  // are connected where their x ranges overlap. Runs are joined by union-find and the
  // pieces holding a border voxel (every border voxel is free: the margin) are outside.
  const long long rows = 1LL * ny * nz;
  std::vector<long long> row_first(static_cast<size_t>(rows) + 1, 0);
  std::vector<std::array<int, 2>> runs;  // [begin, end) along x
  for (long long r = 0; r < rows; ++r) {
    const std::uint8_t* row = kept.data() + r * nx;
    for (int v = 0; v < nx;) {
      if (row[v]) {
        ++v;
        continue;
      }
      const int begin = v;
      while (v < nx && !row[v])
        ++v;
      runs.push_back({begin, v});
    }
    row_first[static_cast<size_t>(r) + 1] = static_cast<long long>(runs.size());
  }
  std::vector<long long> parent(runs.size());
  std::iota(parent.begin(), parent.end(), 0LL);
  auto root = [&parent](long long a) {
    while (parent[static_cast<size_t>(a)] != a)
      a = parent[static_cast<size_t>(a)] =
          parent[static_cast<size_t>(parent[static_cast<size_t>(a)])];
    return a;
  };
  auto join_rows = [&](long long r, long long s) {  // runs of rows r and s that overlap
    long long a = row_first[static_cast<size_t>(r)], b = row_first[static_cast<size_t>(s)];
    const long long a_end = row_first[static_cast<size_t>(r) + 1],
                    b_end = row_first[static_cast<size_t>(s) + 1];
    while (a < a_end && b < b_end) {
      const auto& ra = runs[static_cast<size_t>(a)];
      const auto& rb = runs[static_cast<size_t>(b)];
      if (ra[0] < rb[1] && rb[0] < ra[1]) {
        const long long root_a = root(a), root_b = root(b);
        if (root_a != root_b)
          parent[static_cast<size_t>(std::max(root_a, root_b))] = std::min(root_a, root_b);
      }
      (ra[1] < rb[1] ? a : b) += 1;  // the run that ends first meets no later run
    }
  };
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j) {
      const long long r = j + 1LL * ny * k;
      if (j > 0) join_rows(r, r - 1);
      if (k > 0) join_rows(r, r - ny);
    }
  std::vector<std::uint8_t> outside(runs.size(), 0);
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j) {
      const long long r = j + 1LL * ny * k;
      const bool border_row = j == 0 || k == 0 || j == ny - 1 || k == nz - 1;
      for (long long a = row_first[static_cast<size_t>(r)];
           a < row_first[static_cast<size_t>(r) + 1]; ++a) {
        const auto& run = runs[static_cast<size_t>(a)];
        if (border_row || run[0] == 0 || run[1] == nx) outside[static_cast<size_t>(root(a))] = 1;
      }
    }
  for (size_t a = 0; a < runs.size(); ++a)
    outside[a] = outside[static_cast<size_t>(root(static_cast<long long>(a)))];
  closed_.assign(total, 1);
#pragma omp parallel for schedule(static) if (parallel)
  for (long long r = 0; r < rows; ++r)
    for (long long a = row_first[static_cast<size_t>(r)]; a < row_first[static_cast<size_t>(r) + 1];
         ++a) {
      const auto& run = runs[static_cast<size_t>(a)];
      if (outside[static_cast<size_t>(a)])
        std::fill(closed_.begin() + r * nx + run[0], closed_.begin() + r * nx + run[1], 0);
    }
}

bool SkinDetector::inside(const Eigen::Vector3d& p) const {
  if (closed_.empty()) return false;
  const Eigen::Vector3d idx = (p - grid_.origin_mm) / voxel_mm_;
  const int v = static_cast<int>(std::lround(idx.x())), j = static_cast<int>(std::lround(idx.y())),
            k = static_cast<int>(std::lround(idx.z()));
  if (v < 0 || j < 0 || k < 0 || v >= grid_.size[0] || j >= grid_.size[1] || k >= grid_.size[2])
    return false;
  return closed_[grid_.linear_index(v, j, k)] != 0;
}

}  // namespace organfit::fitting
