#pragma once
// Skin particles by the paper's voxel method (s.3.1, METHOD.md s.4), and an
// inside/outside test for points against the model.
//
//  1. Voxelise the bounding box of the particles (cubic voxels of `voxel_mm`).
//  2. Keep the voxels that intersect a particle (a ball of radius rho).
//  3. Delete every kept voxel whose 26 neighbours are all kept.
//  4. Skin particles are those that intersect a remaining voxel.
//
// Linear in N: each particle touches O((2 rho / h + 1)^3) voxels. The voxel size matters
// (METHOD s.8): h = rho finds the true outer layer; much smaller voxels see the gaps
// between packed balls as surface and mark every particle.
//
// Inside test: the voxels not reachable from the grid's border through free voxels are
// the closed body (kept voxels plus enclosed gaps); a point is inside when its voxel is.
//
// Recomputed only when some particle has moved more than `recompute_fraction * h`
// since the last computation (the skin cannot change before).
#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "organfit/geometry/image_geometry.h"

namespace organfit::fitting {

class SkinDetector {
 public:
  /// Throws std::invalid_argument unless voxel_mm > 0, radius_mm > 0 and
  /// 0 < recompute_fraction <= 1.
  SkinDetector(double voxel_mm, double radius_mm, double recompute_fraction = 0.5);

  /// Recomputes when needed; returns true when it did.
  bool update(const Eigen::Matrix3Xd& x);
  /// Forces a recomputation at the next update().
  void invalidate() { valid_ = false; }

  const std::vector<int>& skin() const { return skin_; }
  bool is_skin(int i) const { return is_skin_[static_cast<size_t>(i)] != 0; }
  /// True when p (mm) lies in the closed voxel body of the last computation.
  bool inside(const Eigen::Vector3d& p) const;
  long long computations() const { return computations_; }
  double voxel_mm() const { return voxel_mm_; }
  const geometry::ImageGeometry& grid() const { return grid_; }

 private:
  void compute(const Eigen::Matrix3Xd& x);
  double voxel_mm_, radius_mm_, recompute_fraction_;
  bool valid_ = false;
  long long computations_ = 0;
  Eigen::Matrix3Xd x_at_compute_;
  geometry::ImageGeometry grid_;
  std::vector<std::uint8_t> closed_;  // 1 inside the closed body
  std::vector<int> skin_;
  std::vector<std::uint8_t> is_skin_;
};

}  // namespace organfit::fitting
