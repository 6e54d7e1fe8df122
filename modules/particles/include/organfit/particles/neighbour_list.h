#pragma once
// A Verlet half neighbour list built by cell binning: O(N) build, O(N) use.
//
// Pairs closer than cutoff + skin are listed once (Newton's third law halves the pair
// work, as in LAMMPS). The list is rebuilt only when some particle has moved more than
// skin/2 since the last build, so no pair inside the cutoff is ever missed.
//
// Internally particles are sorted by cell (for memory locality); `order()` maps a
// sorted slot to its particle. Open (non-periodic) boundaries: the grid spans the
// particles' bounding box at build time.
//
// Build: cells are half the reach (cutoff + skin) wide and stored row by row (x
// fastest), so a particle's candidates are the runs of slots of at most 13 rows of
// cells ahead of it (2 rows in y and z), each run cut along x to the cells the sphere
// of reach can touch: about 2.5 candidates per listed pair, against 4.3 with cells one
// reach wide and their 13 neighbour cells.
//
// Deterministic threading: rows are grouped in blocks of 4 x 4 rows (slabs of cells
// along x), stored one after another in memory, and blocks are coloured by the parity
// of their (y, z) block coordinates. A block's pairs reach only its own cells and the
// two rows of cells beyond it, so blocks of one colour never write to the same
// particle. Colours are processed one after another, blocks of one colour in parallel,
// each block's slots in order: every force is summed in an order fixed by the geometry
// alone, hence bit-identical results for any thread count.
#include <Eigen/Core>
#include <vector>

namespace organfit::particles {

/// Below this many particles loops run on one thread: the same arithmetic in the same
/// order (results do not change), without the cost of waking threads at every barrier.
inline constexpr int kParallelMinParticles = 4096;

class NeighbourList {
 public:
  /// `cutoff_mm` of the pair law; `skin_mm` of extra reach that lets the list live
  /// several steps. Throws std::invalid_argument unless both are > 0 and finite.
  NeighbourList(double cutoff_mm, double skin_mm);

  /// Rebuilds when needed (first call, particle count changed, or a displacement over
  /// skin/2). Returns true when it rebuilt.
  bool update(const Eigen::Matrix3Xd& x);
  /// Forces a rebuild at the next update().
  void invalidate() { valid_ = false; }

  double cutoff() const { return cutoff_; }
  double skin() const { return skin_; }
  long long builds() const { return builds_; }
  /// Wall time spent building, summed over all builds (s): the "Neigh" line of a
  /// LAMMPS timing breakdown.
  double build_seconds() const { return build_seconds_; }
  int size() const { return static_cast<int>(order_.size()); }

  /// Sorted slot -> particle index.
  const std::vector<int>& order() const { return order_; }
  /// Neighbours of sorted slot s (as sorted slots): neighbours()[first()[s] .. first()[s+1]).
  const std::vector<int>& first() const { return first_; }
  const std::vector<int>& neighbours() const { return neighbours_; }
  /// Blocks of each colour, and the sorted slots of each block: [block_begin[b], block_end[b]).
  const std::vector<std::vector<int>>& colours() const { return colours_; }
  const std::vector<int>& block_begin() const { return block_begin_; }
  const std::vector<int>& block_end() const { return block_end_; }
  /// Number of listed pairs.
  long long pair_count() const { return static_cast<long long>(neighbours_.size()); }

 private:
  void build(const Eigen::Matrix3Xd& x);
  double cutoff_, skin_;
  bool valid_ = false;
  long long builds_ = 0;
  double build_seconds_ = 0;
  Eigen::Matrix3Xd x_at_build_;
  std::vector<int> order_, first_, neighbours_, cell_begin_, cell_end_, block_begin_, block_end_;
  std::vector<std::vector<int>> colours_;
  std::vector<std::vector<int>> runs_;  // each thread's lists during a build (room reused)
};

}  // namespace organfit::particles
