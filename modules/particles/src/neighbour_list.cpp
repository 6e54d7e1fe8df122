#include "organfit/particles/neighbour_list.h"

#include <omp.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <stdexcept>

namespace organfit::particles {
namespace {

// Cells are half the reach (cutoff + skin) wide, so a particle's neighbours lie in the
// rows of cells at most kRowReach away in y and z, and a short run of cells along x in
// each row. Rows are contiguous in memory, so each is scanned as one run of slots.
constexpr int kRowReach = 2;

// Blocks are slabs: every cell along x, kBlock rows of cells in y and in z. A block's
// pairs write only to its own cells and to cells at most kRowReach beyond it in y and z,
// so blocks two apart in y or z (same colour) never write the same particle:
// kBlock >= 2 * kRowReach.
constexpr int kBlock = 4;
static_assert(kBlock >= 2 * kRowReach, "same-colour blocks must not share written cells");

// Grids with more cells than this per particle are coarsened: a far-away particle
// must not make the grid (and memory) explode. Larger cells stay correct, only slower.
constexpr double kMaxCellsPerParticle = 8.0;
constexpr long long kMinCellBudget = 4096;

}  // namespace

NeighbourList::NeighbourList(double cutoff_mm, double skin_mm)
    : cutoff_(cutoff_mm), skin_(skin_mm) {
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
  const auto start = std::chrono::steady_clock::now();
  build(x);
  build_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
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
  colours_.clear();
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
  double cell = reach / kRowReach;
  std::array<long long, 3> dims{};
  const long long budget =
      std::max<long long>(kMinCellBudget, static_cast<long long>(kMaxCellsPerParticle * n));
  for (;;) {
    for (int d = 0; d < 3; ++d)
      dims[d] = std::max<long long>(1, std::floor(extent[d] / cell));
    if (dims[0] * dims[1] * dims[2] <= budget) break;
    cell *= 1.25;
  }
  const int nx = static_cast<int>(dims[0]), ny = static_cast<int>(dims[1]),
            nz = static_cast<int>(dims[2]);
  const long long ncells = dims[0] * dims[1] * dims[2];
  const Eigen::Vector3d inv_cell(nx / extent.x(), ny / extent.y(), nz / extent.z());

  // Particles are stored block by block, and within a block in cell order (x fastest),
  // counting-sorted and stable in particle index: each row of cells is one run of slots.
  std::vector<int> cell_of(n);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d q = (x.col(i) - lo).cwiseProduct(inv_cell);
    const int cx = std::min(nx - 1, static_cast<int>(q.x()));
    const int cy = std::min(ny - 1, static_cast<int>(q.y()));
    const int cz = std::min(nz - 1, static_cast<int>(q.z()));
    cell_of[i] = cx + nx * (cy + ny * cz);
  }
  const int by = (ny + kBlock - 1) / kBlock, bz = (nz + kBlock - 1) / kBlock;
  const long long nblocks = 1LL * by * bz;
  // Rank of each cell in memory: block-major, then the cell's place in its block (its row
  // among the block's rows, z then y, times nx, plus x). Blocks before (b2, b3) hold
  // whole slabs of kBlock rows in z (each ny rows, nx cells) and, in slab b3, b2 blocks
  // of kBlock rows in y (each slab's height rows).
  std::vector<int> rank(ncells);
#pragma omp parallel for schedule(static) if (n >= kParallelMinParticles)
  for (int cz = 0; cz < nz; ++cz) {
    const int b3 = cz / kBlock;
    const int height = std::min(kBlock, nz - b3 * kBlock);  // the slab's rows in z
    for (int cy = 0; cy < ny; ++cy) {
      const int b2 = cy / kBlock;
      const int width = std::min(kBlock, ny - b2 * kBlock);  // the block's rows in y
      const long long block_start = (1LL * b3 * kBlock * ny + 1LL * b2 * kBlock * height) * nx;
      const long long row_in_block = 1LL * (cz - b3 * kBlock) * width + (cy - b2 * kBlock);
      const long long first = block_start + row_in_block * nx;
      int* out = rank.data() + 1LL * nx * (cy + 1LL * ny * cz);
      for (int cx = 0; cx < nx; ++cx)
        out[cx] = static_cast<int>(first + cx);
    }
  }
  std::vector<int> count(ncells + 1, 0);
  for (int i = 0; i < n; ++i)
    ++count[rank[cell_of[i]] + 1];
  for (long long r = 0; r < ncells; ++r)
    count[r + 1] += count[r];
  cell_begin_.resize(ncells);
  cell_end_.resize(ncells);
  for (long long c = 0; c < ncells; ++c) {
    cell_begin_[c] = count[rank[c]];
    cell_end_[c] = count[rank[c] + 1];
  }
  {
    std::vector<int> fill(cell_begin_);
    for (int i = 0; i < n; ++i)
      order_[fill[cell_of[i]]++] = i;
  }
  // Slot range of each block, and the blocks of each colour (block coordinates mod 2).
  block_begin_.assign(nblocks, n);
  block_end_.assign(nblocks, 0);
  for (int cz = 0; cz < nz; ++cz)
    for (int cy = 0; cy < ny; ++cy) {
      const int b = (cy / kBlock) + by * (cz / kBlock);
      const int row = nx * (cy + ny * cz);
      block_begin_[b] = std::min(block_begin_[b], cell_begin_[row]);
      block_end_[b] = std::max(block_end_[b], cell_end_[row + nx - 1]);
    }
  colours_.assign(4, {});
  for (int b3 = 0; b3 < bz; ++b3)
    for (int b2 = 0; b2 < by; ++b2) {
      const int b = b2 + by * b3;
      if (block_begin_[b] >= block_end_[b]) continue;
      colours_[(b2 % 2) + 2 * (b3 % 2)].push_back(b);
    }
  // Sorted positions by axis (structure of arrays): the distance test below then runs
  // on vector registers.
  std::vector<double> px(n), py(n), pz(n);
  for (int s = 0; s < n; ++s) {
    const int i = order_[s];
    px[s] = x(0, i), py[s] = x(1, i), pz[s] = x(2, i);
  }

  // Parallel and deterministic: each slot's list depends only on the geometry.
  const double reach2 = reach * reach;
  const Eigen::Vector3d cell_size(extent.x() / nx, extent.y() / ny, extent.z() / nz);
  // Lists the candidates of slot s within reach into out[0, k); k may end above `last`
  // (the room), in which case the caller lists it again with more room.
  auto visit = [&](int s, int* out, int last) {
    const int c = cell_of[order_[s]];
    const int cy = (c / nx) % ny, cz = c / (nx * ny);
    const double xi = px[s], yi = py[s], zi = pz[s];
    int k = 0;
    // Branchless: every candidate is written, the count advances only for those within
    // reach (the test fails unpredictably for about half of the candidates).
    auto scan = [&](int from, int to) {
      for (int t = from; t < to; ++t) {
        const double dx = xi - px[t], dy = yi - py[t], dz = zi - pz[t];
        out[std::min(k, last)] = t;
        k += dx * dx + dy * dy + dz * dz < reach2;
      }
    };
    // The cell column along x holding x + dx (clamped as in binning).
    auto column = [&](double xq) {
      const double q = (xq - lo.x()) * inv_cell.x();
      return q <= 0 ? 0 : q >= nx - 1 ? nx - 1 : static_cast<int>(q);  // no int overflow
    };
    // Pruning is padded by a hair so that rounding never drops a pair within reach.
    const double prune2 = reach2 * (1 + 1e-12);
    // Own row: later slots of the own cell, then the cells ahead along x.
    const int own_row = nx * (cy + ny * cz);
    scan(s + 1, cell_end_[own_row + column(xi + reach * (1 + 1e-12))]);
    // Rows ahead: dz > 0 (any dy), or dz = 0 and dy > 0. Each pair is listed once.
    for (int oz = 0; oz <= kRowReach && cz + oz < nz; ++oz) {
      const int rz = cz + oz;
      const double z_lo = lo.z() + rz * cell_size.z();
      const double gz = oz == 0 ? 0.0 : std::max(0.0, z_lo - zi);
      for (int oy = oz == 0 ? 1 : -kRowReach; oy <= kRowReach; ++oy) {
        const int ry = cy + oy;
        if (ry < 0 || ry >= ny) continue;
        const double y_lo = lo.y() + ry * cell_size.y();
        const double gy = std::max({0.0, y_lo - yi, yi - (y_lo + cell_size.y())});
        const double g2 = gy * gy + gz * gz;
        if (g2 >= prune2) continue;
        const double rx = std::sqrt(prune2 - g2);
        const int row = nx * (ry + ny * rz);
        scan(cell_begin_[row + column(xi - rx)], cell_end_[row + column(xi + rx)]);
      }
    }
    return k;
  };
  // Each thread lists a run of consecutive slots into a list of its own (kept from build
  // to build: its room is reused), each slot's candidates first into a small buffer (the
  // branchless scan writes every candidate), and the runs are joined in slot order: the
  // lists one pass in slot order makes. Not into a buffer of fixed room per slot: that is
  // n x 64 ints or more (a quarter of a gigabyte at a million particles for a list that
  // keeps a tenth of it), and each new list would touch every page of it.
  std::vector<int> counts(n, 0);
  std::vector<int> run_first;  // each run's first slot
#pragma omp parallel if (n >= kParallelMinParticles)
  {
    const int threads = omp_get_num_threads(), me = omp_get_thread_num();
#pragma omp single
    {
      if (static_cast<int>(runs_.size()) < threads) runs_.resize(static_cast<size_t>(threads));
      for (int t = 0; t <= threads; ++t)
        run_first.push_back(static_cast<int>(1LL * n * t / threads));
    }  // (a barrier: every thread sees both)
    std::vector<int>& run = runs_[static_cast<size_t>(me)];
    run.clear();
    std::vector<int> buffer(64);
    for (int s = run_first[static_cast<size_t>(me)]; s < run_first[static_cast<size_t>(me) + 1];
         ++s) {
      // A rejected candidate may land one past the count: room for it at the end.
      int k = visit(s, buffer.data(), static_cast<int>(buffer.size()) - 1);
      if (k + 1 > static_cast<int>(buffer.size())) {  // rare: list it again with room
        buffer.resize(static_cast<size_t>(k) + 8);
        k = visit(s, buffer.data(), static_cast<int>(buffer.size()) - 1);
      }
      counts[s] = k;
      run.insert(run.end(), buffer.begin(), buffer.begin() + k);
    }
  }
  for (int s = 0; s < n; ++s)
    first_[s + 1] = first_[s] + counts[s];
  neighbours_.resize(first_[n]);
  const int run_count = static_cast<int>(run_first.size()) - 1;
#pragma omp parallel for schedule(static) if (n >= kParallelMinParticles)
  for (int t = 0; t < run_count; ++t)
    std::copy(runs_[static_cast<size_t>(t)].begin(), runs_[static_cast<size_t>(t)].end(),
              neighbours_.data() + first_[run_first[static_cast<size_t>(t)]]);
}

}  // namespace organfit::particles
