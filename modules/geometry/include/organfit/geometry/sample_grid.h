#pragma once
// Exact nearest-point queries among a fixed set of points (mm): the global fits ask
// them every iteration.
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>
#include <vector>

namespace organfit::geometry {

/// Nearest-sample queries among surface samples, bucketed on a grid of cubic cells:
/// exact (ties go to the lower index, as a scan would), and O(points x a few cells)
/// instead of O(points x samples): the fits ask it every iteration. By default about
/// cbrt(S) cells a side (a query deep inside a surface searches few rings of them); a
/// caller whose queries lie near dense samples (points near the surface they are fitted
/// to, a distance's voxels near its surface) asks for smaller cells, fewer samples a cell
/// (surface_cell_mm).
class SampleGrid {
 public:
  /// `cell_mm` > 0: cells of that size (mm), or larger where that would make more than
  /// 64 cells a sample; otherwise about cbrt(S) a side.
  explicit SampleGrid(const Eigen::Matrix3Xd& samples, double cell_mm = 0) {
    const Eigen::Index n = samples.cols();
    if (n == 0) return;
    lo_ = samples.rowwise().minCoeff();
    const Eigen::Vector3d extent = samples.rowwise().maxCoeff() - lo_;
    h_ = default_cell_mm(extent, n);
    if (cell_mm > 0) {
      const Eigen::Vector3d e = extent.array() + cell_mm;
      h_ = std::max({cell_mm, std::cbrt(e.prod() / (64.0 * static_cast<double>(n))), 1e-6});
    }
    for (int c = 0; c < 3; ++c)
      dim_[c] = std::min(1024, static_cast<int>(extent[c] / h_) + 1);
    const size_t cells = static_cast<size_t>(dim_[0]) * dim_[1] * dim_[2];
    start_.assign(cells + 1, 0);
    std::vector<int> cell(static_cast<size_t>(n));
#pragma omp parallel for schedule(static)
    for (Eigen::Index j = 0; j < n; ++j)
      cell[static_cast<size_t>(j)] = linear(cell_of(samples.col(j)));
    for (Eigen::Index j = 0; j < n; ++j)
      ++start_[static_cast<size_t>(cell[static_cast<size_t>(j)]) + 1];
    for (size_t c = 1; c <= cells; ++c)
      start_[c] += start_[c - 1];
    // By cell, ascending index within a cell: start_[c] advances to cell c's end, which is
    // cell c + 1's start, so one shift restores the starts (no copy of them: a surface's
    // grid has 10 cells or more a sample).
    order_.resize(static_cast<size_t>(n));
    for (Eigen::Index j = 0; j < n; ++j)
      order_[static_cast<size_t>(start_[static_cast<size_t>(cell[static_cast<size_t>(j)])]++)] =
          static_cast<int>(j);
    std::copy_backward(start_.begin(), start_.end() - 2, start_.end() - 1);
    start_[0] = 0;
    // The samples themselves in that order: a cell's are read one after another.
    points_.resize(3, n);
#pragma omp parallel for schedule(static)
    for (Eigen::Index k = 0; k < n; ++k)
      points_.col(k) = samples.col(order_[static_cast<size_t>(k)]);
  }

  /// A cell size (mm) for queries near samples on a surface: about 4 samples an occupied
  /// cell. The default cells hold about cbrt(S) each there (a surface fills few of them),
  /// a few hundred tested a query; a surface's count a cell goes as the cell's area.
  static double surface_cell_mm(const Eigen::Matrix3Xd& samples) {
    const Eigen::Index n = samples.cols();
    if (n == 0) return 1;
    const Eigen::Vector3d lo = samples.rowwise().minCoeff();
    const Eigen::Vector3d extent = samples.rowwise().maxCoeff() - lo;
    const double h = default_cell_mm(extent, n);
    Eigen::Vector3i dim;
    for (int c = 0; c < 3; ++c)
      dim[c] = std::min(1024, static_cast<int>(extent[c] / h) + 1);
    std::vector<char> occupied(static_cast<size_t>(dim[0]) * dim[1] * dim[2], 0);
    long long count = 0;
    for (Eigen::Index j = 0; j < n; ++j) {
      size_t cell = 0;
      for (int c = 2; c >= 0; --c)
        cell = cell * static_cast<size_t>(dim[c]) +
               static_cast<size_t>(
                   std::min(dim[c] - 1, static_cast<int>((samples(c, j) - lo[c]) / h)));
      count += !occupied[cell];
      occupied[cell] = 1;
    }
    const double per_cell = static_cast<double>(n) / static_cast<double>(count);
    return per_cell > 4 ? h * std::sqrt(4 / per_cell) : h;
  }

  /// The nearest sample to q and the squared distance (mm^2), searched within `reach_mm`
  /// of q; {-1, inf} when there is none that near.
  std::pair<int, double> nearest(const Eigen::Vector3d& q,
                                 double reach_mm = std::numeric_limits<double>::infinity()) const {
    const std::pair<int, double> none{-1, std::numeric_limits<double>::infinity()};
    std::pair<int, double> best = none;
    if (points_.cols() == 0) return best;
    const double reach2 = reach_mm * reach_mm;
    walk(
        q,
        [&](int k) {
          const double d2 = (points_.col(k) - q).squaredNorm();
          const int j = order_[static_cast<size_t>(k)];
          if (d2 < best.second || (d2 == best.second && j < best.first)) best = {j, d2};
        },
        [&](double margin) { return std::min(best.second, reach2) <= margin * margin; });
    return best.second <= reach2 ? best : none;
  }

  /// nearest(q) for every column of `queries`, the same answers (ties to the lower index),
  /// by boxes of `box_mm`: the queries in one box share one list of candidates, the
  /// samples within d0 + 2 hd of the box's centre (d0 its own nearest sample's distance,
  /// hd the box's half-diagonal), which holds every sample at the least distance from any
  /// point of the box. For many queries deep inside a surface (a body's particles against
  /// its surface): each query then reads its box's list, not the shells of cells about it.
  std::vector<std::pair<int, double>> nearest_each(const Eigen::Matrix3Xd& queries,
                                                   double box_mm) const;
  /// The sample of least `cost(j)` and that cost, for a cost no less than the sample's
  /// distance to q (mm; the search stops where the unsearched samples are farther than
  /// the best cost). Exact; ties go to the lower index. {-1, inf} when there are none.
  template <class Cost>
  std::pair<int, double> least(const Eigen::Vector3d& q, Cost&& cost) const {
    std::pair<int, double> best{-1, std::numeric_limits<double>::infinity()};
    if (points_.cols() == 0) return best;
    walk(
        q,
        [&](int k) {
          const int j = order_[static_cast<size_t>(k)];
          const double c = cost(j);
          if (c < best.second || (c == best.second && j < best.first)) best = {j, c};
        },
        [&](double margin) { return best.second <= margin; });
    return best;
  }

  /// Appends to `out` the samples within `radius_mm` of q (squared distance at most
  /// radius^2), in ascending index.
  void within(const Eigen::Vector3d& q, double radius_mm, std::vector<int>& out) const {
    const size_t first = out.size();
    places_within(q, radius_mm, out);
    for (size_t e = first; e < out.size(); ++e)
      out[e] = order_[static_cast<size_t>(out[e])];
    std::sort(out.begin() + static_cast<long>(first), out.end());
  }

 private:
  /// Appends to `out` the places k in points_ (not the samples' indices) of the samples
  /// within `radius_mm` of q (squared distance at most radius^2), in the walk's order.
  void places_within(const Eigen::Vector3d& q, double radius_mm, std::vector<int>& out) const {
    if (points_.cols() == 0) return;
    const double r2 = radius_mm * radius_mm;
    walk(
        q,
        [&](int k) {
          if ((points_.col(k) - q).squaredNorm() <= r2) out.push_back(k);
        },
        [&](double margin) { return margin > radius_mm; });
  }

  /// About cbrt(S) cells a side over the samples' `extent` (mm).
  static double default_cell_mm(const Eigen::Vector3d& extent, Eigen::Index n) {
    return std::max(extent.maxCoeff() / std::max(1.0, std::cbrt(static_cast<double>(n))), 1e-6);
  }

  /// Visits the samples (by their place k in points_) shell by shell of cells about q's
  /// (clamped) cell: Chebyshev
  /// distance 0, 1, ... After each shell, `done(margin)` is asked with q's distance (mm)
  /// to the cells not yet searched, a lower bound on every unvisited sample's distance
  /// to q; the walk ends when it says so or when every cell is searched.
  template <class Visit, class Done>
  void walk(const Eigen::Vector3d& q, Visit&& visit, Done&& done) const {
    const Eigen::Vector3i c = cell_of(q);
    for (int r = 0;; ++r) {
      const Eigen::Vector3i lo = (c.array() - r).max(0), hi = (c.array() + r).min(dim_.array() - 1);
      // The shell's cells alone (O(r^2) of them, not the block's O(r^3)): a plane where z
      // is on the shell, rows where y is, else the two ends of the row. The order within
      // a shell does not matter: ties go by index.
      auto cell_run = [&](int x0, int x1, int y, int z) {
        const int first = linear(Eigen::Vector3i(x0, y, z));
        for (int k = start_[static_cast<size_t>(first)];
             k < start_[static_cast<size_t>(first + x1 - x0) + 1]; ++k)
          visit(k);
      };
      for (int z = lo.z(); z <= hi.z(); ++z) {
        const bool z_on = std::abs(z - c.z()) == r;
        for (int y = lo.y(); y <= hi.y(); ++y) {
          if (z_on || std::abs(y - c.y()) == r) {
            cell_run(lo.x(), hi.x(), y, z);
          } else {
            if (c.x() - r >= lo.x()) cell_run(c.x() - r, c.x() - r, y, z);
            if (r > 0 && c.x() + r <= hi.x()) cell_run(c.x() + r, c.x() + r, y, z);
          }
        }
      }
      if ((lo.array() == 0).all() && (hi.array() == dim_.array() - 1).all()) return;
      const Eigen::Vector3d block_lo = lo_ + h_ * lo.cast<double>(),
                            block_hi = lo_ + h_ * (hi.array() + 1).matrix().cast<double>();
      double margin = std::numeric_limits<double>::infinity();
      for (int a = 0; a < 3; ++a) {
        if (lo[a] > 0) margin = std::min(margin, q[a] - block_lo[a]);
        if (hi[a] < dim_[a] - 1) margin = std::min(margin, block_hi[a] - q[a]);
      }
      if (margin > 0 && done(margin)) return;
    }
  }

  Eigen::Vector3i cell_of(const Eigen::Vector3d& q) const {
    Eigen::Vector3i c;
    for (int a = 0; a < 3; ++a)
      c[a] = static_cast<int>(
          std::clamp(std::floor((q[a] - lo_[a]) / h_), 0.0, static_cast<double>(dim_[a] - 1)));
    return c;
  }
  int linear(const Eigen::Vector3i& c) const {
    return (c.z() * dim_[1] + c.y()) * dim_[0] + c.x();
  }
  Eigen::Matrix3Xd points_;  // the samples by cell: points_.col(k) is sample order_[k]
  Eigen::Vector3d lo_ = Eigen::Vector3d::Zero();
  double h_ = 1;
  Eigen::Vector3i dim_ = Eigen::Vector3i::Ones();
  std::vector<int> start_, order_;
};

}  // namespace organfit::geometry
