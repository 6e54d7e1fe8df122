#include "organfit/particles/neighbour_list.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>

namespace organfit::particles {
namespace {

// Forward half stencil: the 13 neighbour cells "after" a cell, so each pair of cells
// is visited once. Reach: [-1, 1] in x and y, [0, 1] in z.
constexpr std::array<std::array<int, 3>, 13> kForward = {{{1, 0, 0},
                                                          {-1, 1, 0}, {0, 1, 0}, {1, 1, 0},
                                                          {-1, -1, 1}, {0, -1, 1}, {1, -1, 1},
                                                          {-1, 0, 1}, {0, 0, 1}, {1, 0, 1},
                                                          {-1, 1, 1}, {0, 1, 1}, {1, 1, 1}}};

// Cells per block edge. A block's pairs write only to its own cells and the layer of
// cells just beyond it, so blocks two apart (same colour) never write the same particle.
constexpr int kBlock = 4;

// Grids with more cells than this per particle are coarsened: a far-away particle
// must not make the grid (and memory) explode. Larger cells stay correct, only slower.
constexpr double kMaxCellsPerParticle = 8.0;
constexpr long long kMinCellBudget = 4096;

}  // namespace

NeighbourList::NeighbourList(double cutoff_mm, double skin_mm) : cutoff_(cutoff_mm), skin_(skin_mm) {
  if (!(cutoff_mm > 0) || !std::isfinite(cutoff_mm)) {
    throw std::invalid_argument("neighbour list: cutoff must be > 0 mm");
  }
  if (!(skin_mm > 0) || !std::isfinite(skin_mm)) {
    throw std::invalid_argument("neighbour list: skin must be > 0 mm");
  }
}

bool NeighbourList::update(const Eigen::Matrix3Xd& x) {
  if (valid_ && x.cols() == x_at_build_.cols()) {
    const double limit2 = 0.25 * skin_ * skin_;
    const long n = static_cast<long>(x.cols());
    bool moved = false;
#pragma omp parallel for reduction(|| : moved) schedule(static) if (n >= kParallelMinParticles)
    for (long i = 0; i < n; ++i) {
      if ((x.col(i) - x_at_build_.col(i)).squaredNorm() > limit2) moved = true;
    }
    if (!moved) return false;
  }
  build(x);
  return true;
}

void NeighbourList::build(const Eigen::Matrix3Xd& x) {
  ++builds_;
  valid_ = true;
  x_at_build_ = x;
  const int n = static_cast<int>(x.cols());
  order_.resize(n);
  first_.assign(n + 1, 0);
  neighbours_.clear();
  colours_.assign(8, {});
  block_begin_.clear();
  block_end_.clear();
  if (n == 0) {
    cell_begin_.clear();
    cell_end_.clear();
    return;
  }

  const Eigen::Vector3d lo = x.rowwise().minCoeff();
  const Eigen::Vector3d hi = x.rowwise().maxCoeff();
  const Eigen::Vector3d extent = (hi - lo).cwiseMax(1e-12);
  const double reach = cutoff_ + skin_;
  double cell = reach;
  std::array<long long, 3> dims{};
  const long long budget =
      std::max<long long>(kMinCellBudget, static_cast<long long>(kMaxCellsPerParticle * n));
  for (;;) {
    for (int d = 0; d < 3; ++d) dims[d] = std::max<long long>(1, std::floor(extent[d] / cell));
    if (dims[0] * dims[1] * dims[2] <= budget) break;
    cell *= 1.25;
  }
  const int nx = static_cast<int>(dims[0]), ny = static_cast<int>(dims[1]),
            nz = static_cast<int>(dims[2]);
  const long long ncells = dims[0] * dims[1] * dims[2];
  const Eigen::Vector3d inv_cell(nx / extent.x(), ny / extent.y(), nz / extent.z());

  // Cells are grouped in blocks of kBlock^3 cells; particles are stored block by block
  // (cells in order within a block), counting-sorted and stable in particle index.
  std::vector<int> cell_of(n);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d q = (x.col(i) - lo).cwiseProduct(inv_cell);
    const int cx = std::min(nx - 1, static_cast<int>(q.x()));
    const int cy = std::min(ny - 1, static_cast<int>(q.y()));
    const int cz = std::min(nz - 1, static_cast<int>(q.z()));
    cell_of[i] = cx + nx * (cy + ny * cz);
  }
  const int bx = (nx + kBlock - 1) / kBlock, by = (ny + kBlock - 1) / kBlock,
            bz = (nz + kBlock - 1) / kBlock;
  const long long nblocks = 1LL * bx * by * bz;
  // Rank of each cell in memory: block-major, then the cell's place in its block.
  std::vector<int> rank(ncells);
  {
    std::vector<int> block_fill(nblocks + 1, 0);
    auto block_of = [&](long long c) {
      const int cx = static_cast<int>(c % nx), cy = static_cast<int>((c / nx) % ny),
                cz = static_cast<int>(c / (1LL * nx * ny));
      return (cx / kBlock) + bx * ((cy / kBlock) + by * (cz / kBlock));
    };
    for (long long c = 0; c < ncells; ++c) ++block_fill[block_of(c) + 1];
    for (long long b = 0; b < nblocks; ++b) block_fill[b + 1] += block_fill[b];
    for (long long c = 0; c < ncells; ++c) rank[c] = block_fill[block_of(c)]++;
  }
  std::vector<int> count(ncells + 1, 0);
  for (int i = 0; i < n; ++i) ++count[rank[cell_of[i]] + 1];
  for (long long r = 0; r < ncells; ++r) count[r + 1] += count[r];
  cell_begin_.resize(ncells);
  cell_end_.resize(ncells);
  for (long long c = 0; c < ncells; ++c) {
    cell_begin_[c] = count[rank[c]];
    cell_end_[c] = count[rank[c] + 1];
  }
  {
    std::vector<int> fill(cell_begin_);
    for (int i = 0; i < n; ++i) order_[fill[cell_of[i]]++] = i;
  }
  // Slot range of each block, and the blocks of each colour (block coordinates mod 2).
  block_begin_.assign(nblocks, n);
  block_end_.assign(nblocks, 0);
  for (int cz = 0; cz < nz; ++cz)
    for (int cy = 0; cy < ny; ++cy)
      for (int cx = 0; cx < nx; ++cx) {
        const int c = cx + nx * (cy + ny * cz);
        const int b = (cx / kBlock) + bx * ((cy / kBlock) + by * (cz / kBlock));
        block_begin_[b] = std::min(block_begin_[b], cell_begin_[c]);
        block_end_[b] = std::max(block_end_[b], cell_end_[c]);
      }
  colours_.assign(8, {});
  for (int b3 = 0; b3 < bz; ++b3)
    for (int b2 = 0; b2 < by; ++b2)
      for (int b1 = 0; b1 < bx; ++b1) {
        const int b = b1 + bx * (b2 + by * b3);
        if (block_begin_[b] >= block_end_[b]) continue;
        colours_[(b1 % 2) + 2 * (b2 % 2) + 4 * (b3 % 2)].push_back(b);
      }
  std::vector<double> xs(3 * static_cast<size_t>(n));
  for (int s = 0; s < n; ++s)
    for (int d = 0; d < 3; ++d) xs[3 * s + d] = x(d, order_[s]);

  // One pass into a fixed stride per slot (parallel and deterministic: each slot's list
  // depends only on the geometry), then compacted. The stride is re-learnt on overflow.
  const double reach2 = reach * reach;
  const Eigen::Vector3d cell_size(extent.x() / nx, extent.y() / ny, extent.z() / nz);
  auto visit = [&](int s, auto&& emit) {
    const int c = cell_of[order_[s]];
    const int cx = c % nx, cy = (c / nx) % ny, cz = c / (nx * ny);
    const double xi = xs[3 * s], yi = xs[3 * s + 1], zi = xs[3 * s + 2];
    // Branchless: every candidate is written, the count advances only for those within
    // reach (the test fails unpredictably for ~1/3 of candidates).
    auto scan = [&](int from, int to) {
      for (int t = from; t < to; ++t) {
        const double dx = xi - xs[3 * t], dy = yi - xs[3 * t + 1], dz = zi - xs[3 * t + 2];
        emit(t, dx * dx + dy * dy + dz * dz < reach2);
      }
    };
    scan(s + 1, cell_end_[c]);  // own cell: later slots only
    for (const auto& o : kForward) {
      const int ox = cx + o[0], oy = cy + o[1], oz = cz + o[2];
      if (ox < 0 || oy < 0 || oz < 0 || ox >= nx || oy >= ny || oz >= nz) continue;
      // Skip a cell whose box lies entirely beyond reach of this particle.
      const int oi[3] = {ox, oy, oz};
      const double p[3] = {xi, yi, zi};
      double gap2 = 0;
      for (int d = 0; d < 3; ++d) {
        const double lo_d = lo[d] + oi[d] * cell_size[d];
        const double g = std::max({0.0, lo_d - p[d], p[d] - (lo_d + cell_size[d])});
        gap2 += g * g;
      }
      if (gap2 >= reach2) continue;
      const int oc = ox + nx * (oy + ny * oz);
      scan(cell_begin_[oc], cell_end_[oc]);
    }
  };
  std::vector<int> counts(n, 0);
  for (;;) {
    const size_t stride = static_cast<size_t>(stride_);
    scratch_.resize(stride * n);
    int overflow = 0;
#pragma omp parallel for schedule(dynamic, 256) reduction(max : overflow) if (n >= kParallelMinParticles)
    for (int s = 0; s < n; ++s) {
      int k = 0;
      int* out = scratch_.data() + stride * s;
      const int last = stride_ - 1;  // a rejected candidate may land one past the count
      visit(s, [&](int t, bool within) {
        out[std::min(k, last)] = t;
        k += within;
      });
      counts[s] = k;
      overflow = std::max(overflow, k + 1);
    }
    if (overflow <= stride_) break;
    stride_ = overflow + 8;  // rare: denser than ever before; redo with room
  }
  for (int s = 0; s < n; ++s) first_[s + 1] = first_[s] + counts[s];
  neighbours_.resize(first_[n]);
#pragma omp parallel for schedule(static) if (n >= kParallelMinParticles)
  for (int s = 0; s < n; ++s) {
    std::copy_n(scratch_.data() + static_cast<size_t>(stride_) * s, counts[s],
                neighbours_.data() + first_[s]);
  }
}

}  // namespace organfit::particles
