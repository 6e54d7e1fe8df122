#include "organfit/geometry/block_maxima.h"

#include <algorithm>
#include <limits>
#include <stdexcept>

namespace organfit::geometry {

Eigen::Vector3i BlockMaxima::finest_dims(const std::array<int, 3>& size) {
  Eigen::Vector3i dims;
  for (int a = 0; a < 3; ++a)
    dims[a] = std::max(1, (size[a] + kFinest - 1) / kFinest);
  return dims;
}

BlockMaxima::BlockMaxima(const std::array<int, 3>& size, std::vector<double> finest) : size_(size) {
  Eigen::Vector3i dims = finest_dims(size);
  if (finest.size() != static_cast<size_t>(dims.prod()))
    throw std::invalid_argument("block maxima: the finest blocks' count does not match the grid");
  levels_.push_back(std::move(finest));
  dims_.push_back(dims);
  while (dims.maxCoeff() > 1) {  // each coarser level the maxima of 2 x 2 x 2 blocks
    const Eigen::Vector3i fd = dims;
    dims = (fd.array() + 1) / 2;
    std::vector<double> coarse(static_cast<size_t>(dims.prod()),
                               -std::numeric_limits<double>::infinity());
    const std::vector<double>& fine = levels_.back();
    for (int c = 0; c < fd.z(); ++c)
      for (int b = 0; b < fd.y(); ++b)
        for (int a = 0; a < fd.x(); ++a) {
          double& m = coarse[static_cast<size_t>(a / 2 + dims.x() * (b / 2 + dims.y() * (c / 2)))];
          m = std::max(m, fine[static_cast<size_t>(a + fd.x() * (b + fd.y() * c))]);
        }
    levels_.push_back(std::move(coarse));
    dims_.push_back(dims);
  }
}

double BlockMaxima::largest() const {
  return levels_.empty() ? -std::numeric_limits<double>::infinity() : levels_.back().front();
}

double BlockMaxima::over(const std::array<int, 3>& lo_in, const std::array<int, 3>& hi_in) const {
  if (levels_.empty()) return -std::numeric_limits<double>::infinity();
  std::array<int, 3> lo, hi;
  int extent = 1;
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::clamp(lo_in[a], 0, size_[a] - 1), hi[a] = std::clamp(hi_in[a], 0, size_[a] - 1);
    extent = std::max(extent, hi[a] - lo[a] + 1);
  }
  size_t level = 0;  // the finest whose blocks are at least the box's size
  while (level + 1 < levels_.size() && (kFinest << level) < extent)
    ++level;
  const int block = kFinest << level;
  const Eigen::Vector3i& dims = dims_[level];
  const std::vector<double>& values = levels_[level];
  double m = -std::numeric_limits<double>::infinity();
  for (int c = lo[2] / block; c <= hi[2] / block; ++c)
    for (int b = lo[1] / block; b <= hi[1] / block; ++b)
      for (int a = lo[0] / block; a <= hi[0] / block; ++a)
        m = std::max(m, values[static_cast<size_t>(a + dims.x() * (b + dims.y() * c))]);
  return m;
}

}  // namespace organfit::geometry
