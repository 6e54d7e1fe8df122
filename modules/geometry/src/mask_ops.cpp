#include "organfit/geometry/mask_ops.h"

#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <mutex>
#include <nanoflann.hpp>
#include <stdexcept>

namespace organfit::geometry {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

/// 1D squared distance transform of f (sampled `step` apart) into d, in place of the
/// lower envelope of parabolas. f[0] is the line's sample `first`: positions are the
/// line's, (first + q) step, so that a piece of a line gives the same numbers as the
/// whole line where the piece decides them. v, z and g are scratch of size n, n+1 and n:
/// g[k] holds f + p^2 at the envelope's k-th parabola, computed once rather than at every
/// comparison. With `arg`, arg[q] is the sample whose parabola gives d[q] (unset where d
/// is infinite).
void edt_1d(const double* f, double* d, int first, int n, double step, std::vector<int>& v,
            std::vector<double>& z, std::vector<double>& g, int* arg = nullptr) {
  int k = -1;
  for (int q = 0; q < n; ++q) {
    if (f[q] == kInf) continue;
    const double pq = (first + q) * step;
    const double gq = f[q] + pq * pq;
    // The intersection s with the envelope's last parabola, popped while s <= z[k]. The
    // last one computed is the new parabola's z (the same quotient: not divided again).
    double s = -kInf;
    while (k >= 0) {
      s = (gq - g[k]) / (2 * pq - 2 * ((first + v[k]) * step));
      if (s <= z[k]) {
        --k;
      } else {
        break;
      }
    }
    ++k;
    v[k] = q;
    g[k] = gq;
    z[k] = k == 0 ? -kInf : s;
    z[k + 1] = kInf;
  }
  if (k < 0) {
    std::fill(d, d + n, kInf);
    return;
  }
  int j = 0;
  for (int q = 0; q < n; ++q) {
    while (z[j + 1] < (first + q) * step)
      ++j;
    const double dq = (q - v[j]) * step;
    d[q] = dq * dq + f[v[j]];
    if (arg) arg[q] = v[j];
  }
}

}  // namespace

namespace {
/// Per-thread room for one line's transforms (n voxels).
struct LineScratch {
  std::vector<double> values, f, out, z, g;
  std::vector<int> v, arg, id;
  std::vector<std::uint8_t> inside;
  explicit LineScratch(int n)
      : values(n), f(n), out(n), z(n + 1), g(n), v(n), arg(n), id(n), inside(n) {}
};

/// fn(first voxel, stride, n, scratch) for every line of the grid along `axis` (1 or 2),
/// on threads. The two other axes are walked the one of smaller stride inner, so that
/// consecutive lines lie side by side in memory and share the cache lines a line's gather
/// loads; a run of lines at a time, their costs differing.
template <class Fn>
void along_lines(const ImageGeometry& g, int axis, Fn&& fn) {
  const int dims[3] = {g.size[0], g.size[1], g.size[2]};
  const long long strides[3] = {1, g.size[0], 1LL * g.size[0] * g.size[1]};
  const int n = dims[axis];
  const long long stride = strides[axis];
  const int a1 = axis == 2 ? 1 : 2, a2 = axis == 0 ? 1 : 0;
#pragma omp parallel
  {
    LineScratch scratch(n);
#pragma omp for schedule(dynamic, 256) collapse(2)
    for (int p = 0; p < dims[a1]; ++p)
      for (int q = 0; q < dims[a2]; ++q)
        fn(p * strides[a1] + q * strides[a2], stride, n, scratch);
  }
}

/// The squared distance (mm^2) from each voxel of an asked side to the nearest voxel of
/// the other side (infinity when it has none), 0 at the voxels of a side not asked: the
/// outside's voxels (`inside` zero) always asked, the inside's when `inside_too`. Each
/// side's transform is 0 at the other side's voxels, so both live in one buffer: a line's
/// input to either is its values with the other side's set to 0.
GridBuffer<double> distance_to_other_side(const std::vector<std::uint8_t>& inside,
                                          const ImageGeometry& g, bool inside_too) {
  if (inside.size() != static_cast<size_t>(g.voxel_count()))
    throw std::invalid_argument("distance transform: size mismatch");
  const int nx = g.size[0], ny = g.size[1], nz = g.size[2];
  const bool asked_side[2] = {true, inside_too};  // outside, inside
  GridBuffer<double> d(inside.size());            // every voxel set below, on threads
  // Along x: the nearest voxel of the other side, by a sweep each way.
  const double sx = g.spacing_mm[0];
#pragma omp parallel for schedule(static)
  for (long long row = 0; row < 1LL * ny * nz; ++row) {
    double* line = d.data() + row * nx;
    const std::uint8_t* side = inside.data() + row * nx;
    int last[2] = {-1, -1};  // the nearest outside and inside voxel at or before i
    for (int i = 0; i < nx; ++i) {
      const int here = side[i] ? 1 : 0;
      last[here] = i;
      const int other = last[1 - here];
      const double dq = (i - other) * sx;
      line[i] = !asked_side[here] ? 0.0 : other >= 0 ? dq * dq : kInf;
    }
    int next[2] = {-1, -1};  // at or after i
    for (int i = nx - 1; i >= 0; --i) {
      const int here = side[i] ? 1 : 0;
      next[here] = i;
      const int other = next[1 - here];
      if (asked_side[here] && other >= 0) {
        const double dq = (i - other) * sx;
        line[i] = std::min(line[i], dq * dq);
      }
    }
  }
  for (int axis = 1; axis < 3; ++axis) {
    const double step = g.spacing_mm[axis];
    along_lines(g, axis, [&](long long base, long long stride, int n, LineScratch& s) {
      double* const line = d.data() + base;
      const std::uint8_t* const side = inside.data() + base;
      // The lines are walked in the order of the smaller stride: the next lines' values
      // share these cache lines, or lie in the next ones, fetched ahead here (8 doubles on,
      // within the grid).
      const long long ahead =
          base + (n - 1) * stride + 8 < static_cast<long long>(d.size()) ? 8 : 0;
      for (int t = 0; t < n; ++t) {
        __builtin_prefetch(line + t * stride + ahead);
        s.values[t] = line[t * stride];
        s.inside[t] = side[t * stride] ? 1 : 0;
      }
      // Each run of one side's voxels, where that side is asked, on its own: its voxels'
      // nearest of the other side lie within it or at the other side's voxels bounding it
      // (0 there; any beyond is farther than they are), and those bounding voxels are never
      // taken off the envelope, so the run with them gives the whole line's numbers.
      for (int a = 0; a < n;) {
        const int here = s.inside[a];
        int b = a;
        while (b + 1 < n && s.inside[b + 1] == here)
          ++b;
        if (asked_side[here]) {
          const int lo = a > 0 ? a - 1 : a, hi = b + 1 < n ? b + 1 : b;
          bool finite = lo < a || hi > b;  // a voxel of the other side: 0 there
          for (int t = lo; t <= hi; ++t) {
            s.f[t] = t < a || t > b ? 0.0 : s.values[t];
            finite = finite || s.f[t] != kInf;
          }
          if (finite) {  // else infinite throughout: the transform is itself
            edt_1d(s.f.data() + lo, s.out.data() + lo, lo, hi - lo + 1, step, s.v, s.z, s.g);
            for (int t = a; t <= b; ++t)
              line[t * stride] = s.out[t];
          }
        }
        a = b + 1;
      }
    });
  }
  return d;
}
}  // namespace

GridBuffer<double> squared_distance_transform(const std::vector<std::uint8_t>& feature,
                                              const ImageGeometry& g) {
  return distance_to_other_side(feature, g, false);
}

GridBuffer<double> squared_distance_across(const std::vector<std::uint8_t>& inside,
                                           const ImageGeometry& g) {
  return distance_to_other_side(inside, g, true);
}

std::vector<int> nearest_feature_transform(const std::vector<std::uint8_t>& feature,
                                           const ImageGeometry& g) {
  if (feature.size() != static_cast<size_t>(g.voxel_count()))
    throw std::invalid_argument("feature transform: size mismatch");
  if (g.voxel_count() > std::numeric_limits<int>::max())
    throw std::invalid_argument("feature transform: more than 2^31 voxels");
  const int nx = g.size[0], ny = g.size[1], nz = g.size[2];
  GridBuffer<double> d(feature.size());  // the squared distance so far, every voxel set
  std::vector<int> nearest(feature.size(), -1);
  // Along x: the nearest feature in the row, by a sweep each way.
  const double sx = g.spacing_mm[0];
#pragma omp parallel for schedule(static)
  for (long long row = 0; row < 1LL * ny * nz; ++row) {
    const long long base = row * nx;
    int last = -1;
    for (int i = 0; i < nx; ++i) {
      if (feature[static_cast<size_t>(base + i)]) last = i;
      const double dq = (i - last) * sx;
      d[base + i] = last >= 0 ? dq * dq : kInf;
      nearest[static_cast<size_t>(base + i)] = last >= 0 ? static_cast<int>(base + last) : -1;
    }
    int next = -1;
    for (int i = nx - 1; i >= 0; --i) {
      if (feature[static_cast<size_t>(base + i)]) next = i;
      if (next < 0) continue;
      const double dq = (next - i) * sx;
      if (dq * dq < d[base + i]) {
        d[base + i] = dq * dq;
        nearest[static_cast<size_t>(base + i)] = static_cast<int>(base + next);
      }
    }
  }
  // Along y, then z: each voxel takes the nearest of its line's voxels' nearest features.
  for (int axis = 1; axis < 3; ++axis) {
    const double step = g.spacing_mm[axis];
    along_lines(g, axis, [&](long long base, long long stride, int n, LineScratch& s) {
      bool finite = false;
      for (int t = 0; t < n; ++t) {
        s.values[t] = d[base + t * stride];
        s.id[t] = nearest[static_cast<size_t>(base + t * stride)];
        finite = finite || s.values[t] != kInf;
      }
      if (!finite) return;
      edt_1d(s.values.data(), s.out.data(), 0, n, step, s.v, s.z, s.g, s.arg.data());
      for (int t = 0; t < n; ++t) {
        d[base + t * stride] = s.out[t];
        nearest[static_cast<size_t>(base + t * stride)] = s.id[s.arg[t]];
      }
    });
  }
  return nearest;
}

ImageGeometry grid_covering(const Aabb& box, double voxel_mm, double margin_mm) {
  if (!(voxel_mm > 0)) throw std::invalid_argument("grid: voxel size must be > 0 mm");
  ImageGeometry g;
  g.spacing_mm = Eigen::Vector3d::Constant(voxel_mm);
  const Eigen::Vector3d lo = box.min_mm.array() - margin_mm;
  const Eigen::Vector3d hi = box.max_mm.array() + margin_mm;
  for (int d = 0; d < 3; ++d)
    g.size[d] = std::max(1, static_cast<int>(std::ceil((hi[d] - lo[d]) / voxel_mm)) + 1);
  g.origin_mm = lo;
  return g;
}

LabelVolume rasterize_balls(const Eigen::Matrix3Xd& centres, double radius_mm,
                            const ImageGeometry& g) {
  LabelVolume mask(g);
  const double r2 = radius_mm * radius_mm;
  // Each thread owns a run of slices and draws the part of every ball that falls in it:
  // no voxel is written by two threads.
#pragma omp parallel
  {
    const int threads = omp_get_num_threads(), me = omp_get_thread_num();
    const int k_lo = static_cast<int>(1LL * g.size[2] * me / threads);
    const int k_hi = static_cast<int>(1LL * g.size[2] * (me + 1) / threads) - 1;
    for (Eigen::Index c = 0; c < centres.cols(); ++c) {
      // Index range of the ball (the direction is orthonormal: reach = radius / spacing).
      const Eigen::Vector3d idx = g.physical_to_index(centres.col(c));
      int lo[3], hi[3];
      for (int d = 0; d < 3; ++d) {
        const double reach = radius_mm / g.spacing_mm[d];
        lo[d] = std::max(0, static_cast<int>(std::ceil(idx[d] - reach)));
        hi[d] = std::min(g.size[d] - 1, static_cast<int>(std::floor(idx[d] + reach)));
      }
      lo[2] = std::max(lo[2], k_lo), hi[2] = std::min(hi[2], k_hi);
      for (int k = lo[2]; k <= hi[2]; ++k)
        for (int j = lo[1]; j <= hi[1]; ++j)
          for (int i = lo[0]; i <= hi[0]; ++i) {
            const Eigen::Vector3d p = g.index_to_physical(Eigen::Vector3d(i, j, k));
            if ((p - centres.col(c)).squaredNorm() <= r2) mask.at(i, j, k) = 1;
          }
    }
  }
  return mask;
}

namespace {
/// Rows of bits (bit i of a row: voxel i along x, 64 to a word, zero past the row's end).
using Word = std::uint64_t;

/// out |= row shifted by s voxels towards larger i (s > 0) or smaller (s < 0).
void or_shifted(const Word* row, int words, int s, Word* out) {
  const int q = std::abs(s) / 64, b = std::abs(s) % 64;
  for (int k = 0; k < words; ++k) {
    Word w = 0;
    if (s > 0) {
      if (k - q >= 0) w = row[k - q] << b;
      if (b && k - q - 1 >= 0) w |= row[k - q - 1] >> (64 - b);
    } else {
      if (k + q < words) w = row[k + q] >> b;
      if (b && k + q + 1 < words) w |= row[k + q + 1] << (64 - b);
    }
    out[k] |= w;
  }
}

/// Bytes as bits and back, 8 voxels at a time where the machine is little-endian (a
/// word's byte b is the voxel at b), else one by one.
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
constexpr bool kBytesInOrder = true;
#else
constexpr bool kBytesInOrder = false;
#endif

/// Bit i of the result: whether in[i] is nonzero, for i < n (n <= 64).
Word pack_bits(const std::uint8_t* in, int n) {
  Word w = 0;
  int i = 0;
  if (kBytesInOrder) {
    for (; i + 8 <= n; i += 8) {
      std::uint64_t x;
      std::memcpy(&x, in + i, 8);
      x |= x >> 4, x |= x >> 2, x |= x >> 1;  // each byte's bits into its lowest
      x &= 0x0101010101010101ULL;
      w |= Word((x * 0x0102040810204080ULL) >> 56) << i;  // the 8 lowest bits gathered
    }
  }
  for (; i < n; ++i)
    w |= Word(in[i] != 0) << i;
  return w;
}

/// The 8 bytes (0 or 1) of each byte value's bits, lowest bit first.
constexpr std::array<std::uint64_t, 256> byte_spreads() {
  std::array<std::uint64_t, 256> t{};
  for (int v = 0; v < 256; ++v)
    for (int b = 0; b < 8; ++b)
      t[static_cast<size_t>(v)] |= std::uint64_t((v >> b) & 1) << (8 * b);
  return t;
}

/// out[i] = bit i of w (0 or 1), for i < n (n <= 64).
void unpack_bits(Word w, int n, std::uint8_t* out) {
  static constexpr std::array<std::uint64_t, 256> kSpread = byte_spreads();
  int i = 0;
  if (kBytesInOrder)
    for (; i + 8 <= n; i += 8)
      std::memcpy(out + i, &kSpread[static_cast<size_t>((w >> i) & 0xff)], 8);
  for (; i < n; ++i)
    out[i] = (w >> i) & 1;
}

/// A grid's voxels as rows of bits along x (bit i of a row: voxel i, 64 to a word, zero
/// past the row's end), with which rows hold any. The closing stays in bits from the
/// mask's bytes to its result, with no bytes made, complemented and read between its two
/// dilations: a 2.3 L lung's particle body on its truth's 0.5 mm lattice (39M voxels)
/// closed in 0.03 s, against 0.25 s with them.
struct BitRows {
  int nx = 0, rows = 0, words = 0;
  std::vector<Word> bits;
  std::vector<std::uint8_t> any;

  BitRows() = default;
  /// No voxel set: `rows` rows of `nx` voxels.
  BitRows(int nx_, int rows_)
      : nx(nx_),
        rows(rows_),
        words((nx + 63) / 64),
        bits(static_cast<size_t>(rows) * words, 0),
        any(static_cast<size_t>(rows), 0) {}
  /// The nonzero voxels of `set` (a grid's labels, i fastest).
  BitRows(const std::vector<std::uint8_t>& set, const ImageGeometry& g)
      : nx(g.size[0]),
        rows(g.size[1] * g.size[2]),
        words((nx + 63) / 64),
        bits(static_cast<size_t>(rows) * words),
        any(static_cast<size_t>(rows)) {
#pragma omp parallel for schedule(static)
    for (int row = 0; row < rows; ++row) {
      const std::uint8_t* in = set.data() + 1LL * row * nx;
      Word* b = bits.data() + 1LL * row * words;
      Word hit = 0;
      for (int q = 0; q < words; ++q)
        hit |= b[q] = pack_bits(in + 64 * q, std::min(64, nx - 64 * q));
      any[static_cast<size_t>(row)] = hit != 0;
    }
  }
  /// No voxel set, on `other`'s grid.
  static BitRows empty_like(const BitRows& other) {
    return BitRows(other.nx, other.rows);
  }
  /// Voxel i of row `row`: set, and whether it is.
  void set(long long row, int i) {
    bits[static_cast<size_t>(row * words + (i >> 6))] |= Word{1} << (i & 63);
    any[static_cast<size_t>(row)] = 1;
  }
  bool test(long long row, int i) const {
    return (bits[static_cast<size_t>(row * words + (i >> 6))] >> (i & 63)) & 1;
  }
  /// Every voxel flipped (the bits past a row's end left zero).
  void complement() {
    const int tail = nx % 64;
    const Word last = tail ? (Word{1} << tail) - 1 : ~Word{0};
#pragma omp parallel for schedule(static)
    for (int row = 0; row < rows; ++row) {
      Word* b = bits.data() + 1LL * row * words;
      Word hit = 0;
      for (int q = 0; q < words; ++q) {
        b[q] = ~b[q] & (q + 1 < words ? ~Word{0} : last);
        hit |= b[q];
      }
      any[static_cast<size_t>(row)] = hit != 0;
    }
  }
  /// The voxels as bytes, 1 or 0, into `out` (the grid's size).
  void to_bytes(std::vector<std::uint8_t>& out) const {
#pragma omp parallel for schedule(static)
    for (int row = 0; row < rows; ++row) {
      const Word* b = bits.data() + 1LL * row * words;
      std::uint8_t* o = out.data() + 1LL * row * nx;
      for (int q = 0; q < words; ++q)
        unpack_bits(b[q], std::min(64, nx - 64 * q), o + 64 * q);
    }
  }
};

/// The voxels of g within `radius_mm` of a voxel of `set`, as bits: what a
/// distance transform of `set` thresholded at radius_mm^2 gives, at a cost set by the
/// rows the set reaches rather than the voxels. The ball is a set of runs along x: for
/// each (dz, dy) a half-width w, dx in [-w, w], each offset's squared length summed as
/// the transform sums it, dz^2 + (dy^2 + dx^2), so that a voxel on the ball's rim falls
/// the same way. Row (j, k) of the result is then the union, over the ball's runs, of row
/// (j - dy, k - dz) of the set widened by w along x: rows held as bits, each set row
/// widened once for each half-width (within a block of slices), the unions taken 64
/// voxels at a time.
BitRows within_radius_of(const BitRows& set, const ImageGeometry& g, double radius_mm) {
  const int ny = g.size[1], nz = g.size[2];
  BitRows out = BitRows::empty_like(set);
  if (set.bits.empty()) return out;
  const double r2 = radius_mm * radius_mm;
  int reach[3];
  for (int d = 0; d < 3; ++d)
    reach[d] = std::min(g.size[d], static_cast<int>(std::floor(radius_mm / g.spacing_mm[d])) + 1);
  struct Run {
    int dy, w;
  };
  std::vector<std::vector<Run>> ball(2 * static_cast<size_t>(reach[2]) + 1);
  std::vector<int> widths;  // the runs' half-widths, each once, ascending
  for (int dz = -reach[2]; dz <= reach[2]; ++dz)
    for (int dy = -reach[1]; dy <= reach[1]; ++dy) {
      int w = -1;
      for (int dx = 0; dx <= reach[0]; ++dx) {
        const double x = dx * g.spacing_mm[0], y = dy * g.spacing_mm[1], z = dz * g.spacing_mm[2];
        if (z * z + (y * y + x * x) <= r2) w = dx;
      }
      if (w < 0) continue;
      ball[static_cast<size_t>(dz + reach[2])].push_back({dy, w});
      widths.push_back(w);
    }
  std::sort(widths.begin(), widths.end());
  widths.erase(std::unique(widths.begin(), widths.end()), widths.end());
  std::vector<int> slot(static_cast<size_t>(reach[0]) + 1, -1);  // a half-width's place
  for (size_t s = 0; s < widths.size(); ++s)
    slot[static_cast<size_t>(widths[s])] = static_cast<int>(s);
  const int words = set.words, nw = static_cast<int>(widths.size());
  const std::vector<Word>& bits = set.bits;
  const std::vector<std::uint8_t>& any = set.any;
  // Blocks of output slices; each widens the set's rows of the slices it reaches.
  constexpr int kBlock = 16;
  const int blocks = (nz + kBlock - 1) / kBlock;
#pragma omp parallel
  {
    std::vector<Word> widened, union_row(static_cast<size_t>(words));
#pragma omp for schedule(dynamic, 1)
    for (int block = 0; block < blocks; ++block) {
      const int k0 = block * kBlock, k1 = std::min(nz, k0 + kBlock) - 1;
      const int s0 = std::max(0, k0 - reach[2]), s1 = std::min(nz - 1, k1 + reach[2]);
      const size_t per_row = static_cast<size_t>(nw) * words;
      widened.assign(static_cast<size_t>(s1 - s0 + 1) * ny * per_row, 0);
      for (int s = s0; s <= s1; ++s)
        for (int j = 0; j < ny; ++j) {
          const long long row = 1LL * s * ny + j;
          if (!any[static_cast<size_t>(row)]) continue;
          const Word* b = bits.data() + row * words;
          Word* w_out = widened.data() + (static_cast<size_t>(s - s0) * ny + j) * per_row;
          std::copy_n(b, words, union_row.data());  // widened by 0
          int done = 0;
          for (int v = 0; v < nw; ++v) {
            for (; done < widths[static_cast<size_t>(v)]; ++done) {
              or_shifted(b, words, done + 1, union_row.data());
              or_shifted(b, words, -(done + 1), union_row.data());
            }
            std::copy_n(union_row.data(), words, w_out + static_cast<size_t>(v) * words);
          }
        }
      for (int k = k0; k <= k1; ++k)
        for (int j = 0; j < ny; ++j) {
          std::fill(union_row.begin(), union_row.end(), Word{0});
          bool hit = false;
          for (int dz = -reach[2]; dz <= reach[2]; ++dz) {
            const int s = k - dz;
            if (s < 0 || s >= nz) continue;
            for (const Run& run : ball[static_cast<size_t>(dz + reach[2])]) {
              const int jj = j - run.dy;
              if (jj < 0 || jj >= ny || !any[static_cast<size_t>(1LL * s * ny + jj)]) continue;
              const Word* w_in = widened.data() +
                                 (static_cast<size_t>(s - s0) * ny + jj) * per_row +
                                 static_cast<size_t>(slot[static_cast<size_t>(run.w)]) * words;
              for (int q = 0; q < words; ++q)
                union_row[static_cast<size_t>(q)] |= w_in[q];
              hit = true;
            }
          }
          if (!hit) continue;
          const long long row = 1LL * k * ny + j;
          std::copy_n(union_row.data(), words, out.bits.data() + row * words);
          out.any[static_cast<size_t>(row)] = 1;
        }
    }
  }
  return out;
}
}  // namespace

void close_mask(LabelVolume& mask, double radius_mm) {
  if (radius_mm <= 0 || mask.labels.empty()) return;
  // What lies farther than r from the mask (the dilation's complement), then what lies
  // farther than r from that: all in bits, made bytes once.
  BitRows outside = within_radius_of(BitRows(mask.labels, mask.geometry), mask.geometry, radius_mm);
  outside.complement();
  BitRows closed = within_radius_of(outside, mask.geometry, radius_mm);
  closed.complement();
  closed.to_bytes(mask.labels);
}

LabelVolume closed_body(const Eigen::Matrix3Xd& centres, double radius_mm, double closing_mm,
                        const ImageGeometry& grid) {
  // Index box of the balls grown by the closing (and a voxel), clamped to the grid.
  const double reach = radius_mm + closing_mm;
  int lo[3] = {grid.size[0], grid.size[1], grid.size[2]}, hi[3] = {-1, -1, -1};
  for (Eigen::Index c = 0; c < centres.cols(); ++c) {
    const Eigen::Vector3d idx = grid.physical_to_index(centres.col(c));
    for (int d = 0; d < 3; ++d) {
      const double r = reach / grid.spacing_mm[d] + 1;
      lo[d] = std::min(lo[d], static_cast<int>(std::floor(idx[d] - r)));
      hi[d] = std::max(hi[d], static_cast<int>(std::ceil(idx[d] + r)));
    }
  }
  ImageGeometry part = grid;
  for (int d = 0; d < 3; ++d) {
    lo[d] = std::max(0, lo[d]);
    hi[d] = std::min(grid.size[d] - 1, hi[d]);
    if (lo[d] > hi[d]) {  // no ball, or all of them off the grid
      part.size = {0, 0, 0};
      return LabelVolume(part);
    }
  }
  for (int d = 0; d < 3; ++d)
    part.size[d] = hi[d] - lo[d] + 1;
  part.origin_mm = grid.index_to_physical(Eigen::Vector3d(lo[0], lo[1], lo[2]));
  LabelVolume body = rasterize_balls(centres, radius_mm, part);
  close_mask(body, closing_mm);
  return body;
}

LabelVolume closed_body_on_grid(const Eigen::Matrix3Xd& centres, double radius_mm,
                                double closing_mm, const ImageGeometry& grid) {
  const LabelVolume part = closed_body(centres, radius_mm, closing_mm, grid);
  LabelVolume out(grid);
  const ImageGeometry& p = part.geometry;
  if (p.voxel_count() == 0) return out;
  const Eigen::Vector3d o = grid.physical_to_index(p.origin_mm).array().round();
  const int i0 = static_cast<int>(o.x()), j0 = static_cast<int>(o.y()),
            k0 = static_cast<int>(o.z());
#pragma omp parallel for schedule(static)
  for (int k = 0; k < p.size[2]; ++k)
    for (int j = 0; j < p.size[1]; ++j)
      std::copy_n(&part.labels[static_cast<size_t>(p.linear_index(0, j, k))], p.size[0],
                  &out.at(i0, j0 + j, k0 + k));
  return out;
}

namespace {
/// Calls on_surface(i) for each voxel of row (j, k) that is inside the mask and has a face
/// neighbour outside it or lies on the grid's edge, in order of i. The row and its four
/// neighbouring rows are read by pointer: the whole grid is scanned (43M voxels for a lung's
/// truth at 0.5 mm), and most of it is outside.
template <class F>
void surface_of_row(const LabelVolume& mask, int j, int k, F&& on_surface) {
  const ImageGeometry& g = mask.geometry;
  const int nx = g.size[0];
  const long long row_stride = nx, slice_stride = static_cast<long long>(nx) * g.size[1];
  const std::uint8_t* row = mask.labels.data() + g.linear_index(0, j, k);
  const bool edge_row = j == 0 || k == 0 || j == g.size[1] - 1 || k == g.size[2] - 1;
  auto eight = [](const std::uint8_t* p) {
    std::uint64_t w;
    std::memcpy(&w, p, 8);
    return w;
  };
  auto no_zero_byte = [](std::uint64_t w) {
    return ((w - 0x0101010101010101ULL) & ~w & 0x8080808080808080ULL) == 0;
  };
  for (int i = 0; i < nx; ++i) {
    // Eight voxels at once where all are outside, or all inside with every face neighbour
    // inside too: most of a grid is one or the other.
    while (i + 8 <= nx) {
      const std::uint64_t w = eight(row + i);
      if (w == 0 ||
          (!edge_row && i >= 1 && i + 9 <= nx && no_zero_byte(w) &&
           no_zero_byte(eight(row + i - 1)) && no_zero_byte(eight(row + i + 1)) &&
           no_zero_byte(eight(row + i - row_stride)) && no_zero_byte(eight(row + i + row_stride)) &&
           no_zero_byte(eight(row + i - slice_stride)) &&
           no_zero_byte(eight(row + i + slice_stride))))
        i += 8;
      else
        break;
    }
    if (i >= nx) break;
    if (!row[i]) continue;
    if (edge_row || i == 0 || i == nx - 1 || !row[i - 1] || !row[i + 1] || !row[i - row_stride] ||
        !row[i + row_stride] || !row[i - slice_stride] || !row[i + slice_stride])
      on_surface(i);
  }
}
}  // namespace

std::vector<std::uint8_t> surface_of(const LabelVolume& mask) {
  const auto& g = mask.geometry;
  std::vector<std::uint8_t> s(mask.labels.size(), 0);
#pragma omp parallel for schedule(static)
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j) {
      std::uint8_t* out = s.data() + g.linear_index(0, j, k);
      surface_of_row(mask, j, k, [out](int i) { out[i] = 1; });
    }
  return s;
}

std::vector<Eigen::Vector3i> surface_voxels(const LabelVolume& mask) {
  const ImageGeometry& g = mask.geometry;
  // Each slice's voxels on a thread, then the slices in order: the grid's order, as one
  // pass would give them.
  std::vector<std::vector<Eigen::Vector3i>> slices(static_cast<size_t>(g.size[2]));
#pragma omp parallel for schedule(dynamic, 4)
  for (int k = 0; k < g.size[2]; ++k) {
    auto& slice = slices[static_cast<size_t>(k)];
    for (int j = 0; j < g.size[1]; ++j)
      surface_of_row(mask, j, k, [&slice, j, k](int i) { slice.emplace_back(i, j, k); });
  }
  std::vector<Eigen::Vector3i> out;
  size_t total = 0;
  for (const auto& slice : slices)
    total += slice.size();
  out.reserve(total);
  for (const auto& slice : slices)
    out.insert(out.end(), slice.begin(), slice.end());
  return out;
}

namespace {
/// The surface voxels' centres (mm, 3 x N) as nanoflann reads a point set.
struct VoxelCentres {
  Eigen::Matrix3Xd points;
  size_t kdtree_get_point_count() const { return static_cast<size_t>(points.cols()); }
  double kdtree_get_pt(size_t i, size_t axis) const {
    return points(static_cast<Eigen::Index>(axis), static_cast<Eigen::Index>(i));
  }
  template <class Box>
  bool kdtree_get_bbox(Box&) const {
    return false;  // the tree finds the box itself
  }
};
using VoxelTree =
    nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, VoxelCentres>,
                                        VoxelCentres, 3, std::uint32_t>;
/// Points a leaf (nanoflann's default is 10): the distances between the truth's surfaces of
/// a 1.5 L liver at 0.5 mm took the same time within 10% at 8, 16 and 32.
constexpr size_t kLeafPoints = 16;
/// How far (voxels of the finest axis) the lattice is searched before the tree is asked
/// (below): at most 268 offsets however thick the slices (a ball of 4 coarse voxels on a
/// CT's 0.5 x 0.5 x 5 mm grid would hold 27,000, each read by every far query).
constexpr double kGridReachVoxels = 4;
}  // namespace

// Two searches, each where it is fast; the distances are the same either way (exact
// nearest neighbours). A query on the mask's lattice (another surface's voxel: every
// comparison's case) looks for a surface voxel at the offsets of its ball in order of
// length, each one bit read: the first hit is its distance. The truth of a 1.5 L liver at
// 0.5 mm (547,000 surface voxels) against its three bodies so took about a third of the CPU
// time of a grid of cells two voxels wide searched shell by shell (docs/decisions.md).
// Beyond 4 voxels a ball has too many offsets (they go as the cube of its radius; 6 and 8
// voxels took as long in all), and a query off the lattice has none: a k-d tree, whose
// boxes skip the empty space, answers those. It is built when a query first needs it:
// two surfaces that close need none.
struct MaskSurface::Search {
  VoxelCentres centres;
  std::once_flag tree_built;
  std::unique_ptr<VoxelTree> tree;
  // The lattice: the mask's grid, its surface voxels as bits on it grown by `pad` voxels
  // on every side (a ball about any voxel of the grid stays within), rows along x.
  ImageGeometry grid;
  Eigen::Vector3i pad = Eigen::Vector3i::Zero();
  int ny = 0;  // the grown grid's rows a slice
  BitRows surface;
  struct Offset {
    long long row;  // rows to step (dz * ny + dy of the grown grid)
    int dx;
    double d2_mm2;  // its squared length, summed as within_radius_of sums it
  };
  std::vector<Offset> ball;  // within the reach, ascending length
};

MaskSurface::MaskSurface(const LabelVolume& mask) : search_(std::make_unique<Search>()) {
  Search& s = *search_;
  const ImageGeometry& g = mask.geometry;
  s.grid = g;
  const std::vector<Eigen::Vector3i> voxels = surface_voxels(mask);
  Eigen::Matrix3Xd& points = s.centres.points;
  points.resize(3, static_cast<Eigen::Index>(voxels.size()));
  for (size_t v = 0; v < voxels.size(); ++v)
    points.col(static_cast<Eigen::Index>(v)) =
        g.origin_mm + voxels[v].cast<double>().cwiseProduct(g.spacing_mm);
  if (voxels.empty()) return;
  const double reach_mm = kGridReachVoxels * g.spacing_mm.minCoeff();
  const double r2 = reach_mm * reach_mm;
  for (int d = 0; d < 3; ++d)
    s.pad[d] = static_cast<int>(std::floor(reach_mm / g.spacing_mm[d]));
  s.ny = g.size[1] + 2 * s.pad[1];
  s.surface = BitRows(g.size[0] + 2 * s.pad[0], (g.size[2] + 2 * s.pad[2]) * s.ny);
  for (const Eigen::Vector3i& v : voxels)
    s.surface.set(1LL * (v.z() + s.pad[2]) * s.ny + (v.y() + s.pad[1]), v.x() + s.pad[0]);
  for (int dz = -s.pad[2]; dz <= s.pad[2]; ++dz)
    for (int dy = -s.pad[1]; dy <= s.pad[1]; ++dy)
      for (int dx = -s.pad[0]; dx <= s.pad[0]; ++dx) {
        const double x = dx * g.spacing_mm[0], y = dy * g.spacing_mm[1], z = dz * g.spacing_mm[2];
        const double d2 = z * z + (y * y + x * x);
        if (d2 <= r2) s.ball.push_back({1LL * dz * s.ny + dy, dx, d2});
      }
  std::stable_sort(
      s.ball.begin(), s.ball.end(),
      [](const Search::Offset& a, const Search::Offset& b) { return a.d2_mm2 < b.d2_mm2; });
}

MaskSurface::~MaskSurface() = default;
MaskSurface::MaskSurface(MaskSurface&&) noexcept = default;
MaskSurface& MaskSurface::operator=(MaskSurface&&) noexcept = default;

const Eigen::Matrix3Xd& MaskSurface::points_mm() const {
  return search_->centres.points;
}

long long MaskSurface::near_distances(const Eigen::Matrix3Xd& q, std::vector<double>& d) const {
  d.assign(static_cast<size_t>(q.cols()), std::numeric_limits<double>::infinity());
  const Search& s = *search_;
  if (s.centres.points.cols() == 0) return 0;
  const ImageGeometry& g = s.grid;
  long long far = 0;  // queries off the lattice or beyond the ball (left at infinity)
#pragma omp parallel for schedule(dynamic, 1024) reduction(+ : far)
  for (long long k = 0; k < static_cast<long long>(d.size()); ++k) {
    // On the lattice: within a millionth of a voxel of a voxel centre of the grid.
    const Eigen::Vector3d f =
        (q.col(static_cast<Eigen::Index>(k)) - g.origin_mm).cwiseQuotient(g.spacing_mm);
    const Eigen::Vector3d r = f.array().round();
    if ((f - r).cwiseAbs().maxCoeff() > 1e-6 || (r.array() < 0).any() || r.x() >= g.size[0] ||
        r.y() >= g.size[1] || r.z() >= g.size[2]) {
      ++far;
      continue;
    }
    const Eigen::Vector3i v = r.cast<int>() + s.pad;
    const long long row = 1LL * v.z() * s.ny + v.y();
    for (const Search::Offset& o : s.ball)
      if (s.surface.test(row + o.row, v.x() + o.dx)) {
        d[static_cast<size_t>(k)] = std::sqrt(o.d2_mm2);
        break;
      }
    far += d[static_cast<size_t>(k)] == HUGE_VAL;
  }
  return far;
}

void MaskSurface::build_tree() const {
  Search& s = *search_;
  std::call_once(s.tree_built, [&s] {
    s.tree = std::make_unique<VoxelTree>(3, s.centres,
                                         nanoflann::KDTreeSingleIndexAdaptorParams(kLeafPoints));
  });
}

void MaskSurface::far_distances(const Eigen::Matrix3Xd& q, std::vector<double>& d) const {
  build_tree();
  const VoxelTree& tree = *search_->tree;
#pragma omp parallel for schedule(dynamic, 256)
  for (long long k = 0; k < static_cast<long long>(d.size()); ++k) {
    if (d[static_cast<size_t>(k)] < HUGE_VAL) continue;
    std::uint32_t nearest = 0;
    double d2 = std::numeric_limits<double>::infinity();
    nanoflann::KNNResultSet<double, std::uint32_t> found(1);
    found.init(&nearest, &d2);
    tree.findNeighbors(found, q.col(static_cast<Eigen::Index>(k)).data(),
                       nanoflann::SearchParams());
    d[static_cast<size_t>(k)] = std::sqrt(d2);
  }
}

std::vector<double> MaskSurface::distances_from(const Eigen::Matrix3Xd& q) const {
  std::vector<double> d;
  if (near_distances(q, d) > 0) far_distances(q, d);
  return d;
}

void surface_distances(const MaskSurface& a, const MaskSurface& b, SurfaceComparison& out) {
  // Both ways near the surfaces first; then the trees the far queries need, built at once
  // (each tree is built on one thread: two surfaces far apart, as the organ left
  // undeformed is from its deformed truth, build theirs side by side).
  std::vector<double> dist, b_to_a;
  const bool a_far = b.near_distances(a.points_mm(), dist) > 0;
  const bool b_far = a.near_distances(b.points_mm(), b_to_a) > 0;
  if (a_far && b_far) {
#pragma omp parallel sections
    {
#pragma omp section
      b.build_tree();
#pragma omp section
      a.build_tree();
    }
  }
  if (a_far) b.far_distances(a.points_mm(), dist);
  if (b_far) a.far_distances(b.points_mm(), b_to_a);
  dist.insert(dist.end(), b_to_a.begin(), b_to_a.end());
  if (dist.empty()) return;
  double sum = 0;
  for (double d : dist)
    sum += d;
  out.msd_mm = sum / static_cast<double>(dist.size());
  const size_t k = static_cast<size_t>(std::ceil(0.95 * dist.size())) - 1;
  std::nth_element(dist.begin(), dist.begin() + k, dist.end());
  out.hd95_mm = dist[k];
}

SurfaceComparison compare_masks(const LabelVolume& a, const LabelVolume& b) {
  if (a.geometry.size != b.geometry.size) throw std::invalid_argument("compare: different grids");
  SurfaceComparison r;
  // Surface distances by nearest-voxel queries among the surface voxels alone: the
  // values a distance transform of the whole grid gives, at a cost set by the surfaces'
  // areas rather than the grid's volume.
  surface_distances(MaskSurface(a), MaskSurface(b), r);
  long long inter = 0, na = 0, nb = 0;
  for (size_t i = 0; i < a.labels.size(); ++i) {
    na += a.labels[i] != 0;
    nb += b.labels[i] != 0;
    inter += a.labels[i] != 0 && b.labels[i] != 0;
  }
  const double vox = a.geometry.voxel_volume_mm3();
  r.volume_a_mm3 = na * vox;
  r.volume_b_mm3 = nb * vox;
  r.dice = na + nb > 0 ? 2.0 * inter / static_cast<double>(na + nb) : 1.0;
  return r;
}

namespace {
Aabb bounds_of(const Eigen::Matrix3Xd& x) {
  return {x.rowwise().minCoeff(), x.rowwise().maxCoeff()};
}
}  // namespace

double particle_body_volume_mm3(const Eigen::Matrix3Xd& centres, double radius_mm, double voxel_mm,
                                double closing_mm) {
  if (centres.cols() == 0) return 0.0;
  const ImageGeometry g =
      grid_covering(bounds_of(centres), voxel_mm, radius_mm + closing_mm + 2 * voxel_mm);
  return closed_body_on_grid(centres, radius_mm, closing_mm, g).volume_mm3(1);
}

SurfaceComparison compare_particle_bodies(const Eigen::Matrix3Xd& a, const Eigen::Matrix3Xd& b,
                                          double radius_mm, double voxel_mm, double closing_mm) {
  Aabb box = bounds_of(a);
  const Aabb bb = bounds_of(b);
  box.min_mm = box.min_mm.cwiseMin(bb.min_mm);
  box.max_mm = box.max_mm.cwiseMax(bb.max_mm);
  const ImageGeometry g = grid_covering(box, voxel_mm, radius_mm + closing_mm + 2 * voxel_mm);
  return compare_masks(closed_body_on_grid(a, radius_mm, closing_mm, g),
                       closed_body_on_grid(b, radius_mm, closing_mm, g));
}

LabelVolume cropped_organ(const LabelVolume& mask) {
  const ImageGeometry& g = mask.geometry;
  const IndexRange box = mask.range(1);
  std::array<int, 3> lo = box.lo, hi = box.hi;
  ImageGeometry crop = g;
  for (int d = 0; d < 3; ++d) {
    lo[d] = std::max(0, lo[d] - 1), hi[d] = std::min(g.size[d] - 1, hi[d] + 1);
    crop.size[d] = hi[d] - lo[d] + 1;
  }
  crop.origin_mm = g.index_to_physical(Eigen::Vector3d(lo[0], lo[1], lo[2]));
  LabelVolume out(crop);
  for (int k = lo[2]; k <= hi[2]; ++k)
    for (int j = lo[1]; j <= hi[1]; ++j)
      for (int i = lo[0]; i <= hi[0]; ++i)
        out.at(i - lo[0], j - lo[1], k - lo[2]) = mask.at(i, j, k) == 1;
  return out;
}

bool inside_interpolated(const LabelVolume& mask, const Eigen::Vector3d& p_mm) {
  const auto& g = mask.geometry;
  const Eigen::Vector3d idx = g.physical_to_index(p_mm);
  if (!idx.allFinite()) return false;
  const Eigen::Vector3d base = idx.array().floor();
  if ((base.array() < -1).any() || base.x() >= g.size[0] || base.y() >= g.size[1] ||
      base.z() >= g.size[2])
    return false;
  double value = 0;
  for_each_trilinear_corner(idx - base, [&](int di, int dj, int dk, double weight) {
    const int i = static_cast<int>(base.x()) + di, j = static_cast<int>(base.y()) + dj,
              k = static_cast<int>(base.z()) + dk;
    if (i < 0 || j < 0 || k < 0 || i >= g.size[0] || j >= g.size[1] || k >= g.size[2]) return;
    if (mask.at(i, j, k) == 1) value += weight;
  });
  return value >= 0.5;
}

}  // namespace organfit::geometry
