#pragma once
// The global map's shear fields (global_map.h) tabulated for evaluation at many points: a
// field f_a is a function of the other two coordinates, held with its gradient and mixed
// derivative at nodes sigma / 10 apart (nodes_per_sigma) over the plane of its bumps (6 sigmas
// beyond the outermost centres, where every bump is below 2e-8 of its height) and interpolated by
// bicubic Hermite. Made once from fitted weights, it evaluates a field in a quarter to a
// fifth of the time of its bumps (a window of 11 x 11 and up to six exponentials), which the
// deformation asks for at every voxel near the organ's surface (fitting/deformation.h).
//
// Its fields are themselves shears of one coordinate by a function of the other two:
// apply and inverse are exact inverses of each other and keep volume exactly. They
// differ from the bumps' by at most error().value_mm (of order 1e-5 of the largest
// height), and their gradients by at most error().gradient (2e-3 of the largest height
// per sigma): bounds from the Hermite interpolation's remainder and the bumps' fourth
// derivatives, carried into GlobalMap::inverse_stretch so that a stretch bound holds for
// this evaluation.
#include <Eigen/Core>
#include <array>
#include <vector>

#include "organfit/fitting/global_map.h"

namespace organfit::fitting {

class ShearFieldTable {
 public:
  /// No fields: every field zero.
  ShearFieldTable() = default;
  /// The table of `fields` (empty when fields.empty()).
  explicit ShearFieldTable(const ShearFields& fields);

  bool empty() const { return planes_[0].node.empty(); }
  /// f_a at q (mm), from q's other two coordinates; 0 beyond the table (and at a
  /// coordinate that is not finite).
  double field(int a, const Eigen::Vector3d& q) const;
  /// The fields in ShearFields' order: x += f_x, then y += f_y, then z += f_z.
  Eigen::Vector3d apply(const Eigen::Vector3d& q) const;
  Eigen::Vector3d inverse(const Eigen::Vector3d& q) const;
  /// How far field() may be from the bumps' smooth sum, and its gradient from theirs.
  const FieldEvaluationError& error() const { return error_; }

  /// Nodes per sigma along each axis of a plane: 10, fewer (down to 4, the errors stated
  /// growing as (10 / n)^3 and ^4) where that many would pass 8M nodes in all (a field
  /// sigma far below the organ's size: 100 nodes a bump).
  static constexpr int kNodesPerSigma = 10;
  int nodes_per_sigma() const { return per_sigma_; }
  /// Sigmas beyond the outermost bump centres that a plane reaches.
  static constexpr int kMarginSigmas = 6;

 private:
  /// Field a over the plane of axes b < c: node (p, q) at (origin_b + p h, origin_c + q h),
  /// four values a node: f, h df/db, h df/dc, h^2 d2f/db dc.
  struct Plane {
    int b = 0, c = 0, nb = 0, nc = 0;
    double origin_b = 0, origin_c = 0;
    std::vector<double> node;
  };
  std::array<Plane, 3> planes_;
  double h_mm_ = 1;
  int per_sigma_ = kNodesPerSigma;
  FieldEvaluationError error_;
};

}  // namespace organfit::fitting
