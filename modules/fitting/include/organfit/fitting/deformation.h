#pragma once
// The fit's result as one map defined at every point: phi, from the planning organ to
// today's, and its inverse. A point q of today's anatomy comes from the planning point
//     phi^-1(q) = M^-1(q + u(q)),
// M the global map (global_fit.h: volume-preserving, exact inverse; the identity for the
// paper's method) and u the local displacement the particles carry, from where they are
// (x_i) back to where the global stage placed them (x_i^0): u(x_i) ~ x_i^0 - x_i.
//
// u is known near the particles and chosen far from them:
//  - near the particles, by moving least squares: an affine field fitted around q to the
//    particles within the support h, weights w(r) = (1 - r^2/h^2)^3. Affine fields are
//    reproduced exactly, and the field extrapolates past the outermost particles to the
//    surface, which lies beyond them. This answer is kept where it is well posed (4
//    particles or more, spread in every direction), the particles near q weigh at least
//    as much as one particle at q (sum of w >= 1), and the answer is at least as certain
//    as one particle's displacement at q ((M^-1)_00 <= 1, M the fit's weighted normal
//    matrix: beyond a thin layer of particles their jitter is amplified); else from a
//    support of 1.5 h or 2 h;
//  - everywhere else (beyond the particles, or where the model tore apart inside), u is
//    harmonic (the Laplace equation), matching the kept values and zero at
//    D = max(2 h, 2 max|u|) beyond them: at the nodes farther than D from every node
//    answered above, and on the lattice's faces, D beyond the particles' box. A harmonic
//    field has no interior extremum: |u| stays within the particles' moves.
// So far from the organ phi is the global map alone. Not the identity: the global map's
// bend is volume-preserving only as an exact shear, and decaying it to the identity folds
// the CT far from the organ (docs/decisions.md).
// The price: far from the organ the field is the global map's extrapolation, which grows
// with the distance (docs/outputs.md).
// M's shear fields are evaluated from their table (shear_field_table.h: within 1e-5 of
// their largest height, 4 to 5 times faster), so phi^-1 = M^-1(q + u) with that M.
// u is held on a lattice of h/3 (nodes over the particles' box widened by D and a node)
// and interpolated trilinearly; zero outside it. The moving least squares varies over h:
// a third of it holds the field within 0.04 mm of a lattice of h/8 on a real GTV
// (docs/decisions.md). Every node of a cell with a node it answers is answered by it too
// (the rim: fitted over 2h, whatever its weight), so a point it answers is interpolated
// from its answers alone: an affine motion is carried exactly up to the surface.
// At rest (x_i = x_i^0) u is zero everywhere and phi is the global map (its fields from
// their table): the identity gives the planning organ exactly.
//
// Since M keeps volume, det(grad phi) at the tissue now at q is 1 / det(I + grad u(q)).
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <vector>

#include "organfit/fitting/global_fit.h"
#include "organfit/fitting/shear_field_table.h"
#include "organfit/geometry/block_maxima.h"
#include "organfit/geometry/image_geometry.h"
#include "organfit/particles/state.h"

namespace organfit::fitting {

class Deformation {
 public:
  /// `placed` and `current`: the same particles (3 x N, mm) where the global stage put
  /// them and where they are now. Throws std::invalid_argument when the counts differ, a
  /// position is not finite, support_mm <= 0, or the particles span more than 2 m.
  Deformation(GlobalMap map, particles::Positions placed, particles::Positions current,
              double support_mm);
  /// The identity (no global map, no particles).
  Deformation();

  /// phi^-1(q): the planning point that today's point q came from (mm). Finite for every
  /// finite q.
  Eigen::Vector3d pull_back(const Eigen::Vector3d& q_mm) const;
  /// phi(r): where the planning point r is today (mm), by fixed-point iteration on
  /// q + u(q) = M(r).
  Eigen::Vector3d push_forward(const Eigen::Vector3d& r_mm) const;
  /// det(grad phi) at the tissue now at q: the ratio of its volume today to its planning
  /// volume (1 where phi keeps volume).
  double volume_ratio(const Eigen::Vector3d& q_mm) const;
  /// A lattice cell's edges (the differences of u between its corners: `along[a][e]`, the
  /// 4 edges along axis a), what det(grad phi) within the cell is made from.
  struct CellEdges {
    Eigen::Vector3d along[3][4];
  };
  /// The cell volume_ratio read last: a caller walking voxels in order (a row meets each
  /// cell at several voxels: the lattice is h / 3, a voxel far less) reads its corners once.
  struct CellCache {
    long long cell = -1;  // the cell's lowest node; -1: none read
    CellEdges edges;
  };
  /// volume_ratio(q_mm), the same number, with the cell kept in `cache`.
  double volume_ratio(const Eigen::Vector3d& q_mm, CellCache& cache) const;

  /// How phi^-1 = M^-1(q + u(q)) stretches distances over today's points in `box` (mm) is
  /// bounded by two parts: |phi^-1(p) - phi^-1(q)| <= stretch (1 + G) |p - q| + slack_mm,
  /// with stretch and slack M^-1's bound over the box grown by u's largest size (this),
  /// and G u_gradient_bound over the segment's box (a part as small as a ball about it).
  StretchBound map_inverse_stretch(const geometry::Aabb& box) const;
  /// A bound on |grad u| (Frobenius, unit-free) over `box` (mm): trilinear, its norm is
  /// largest at a cell's corner, from the cell's edge differences; the largest over the
  /// nodes of the cells the box touches, by blocks (geometry/block_maxima.h). u is steep
  /// where it falls away from the organ, gentle within it.
  double u_gradient_bound(const geometry::Aabb& box) const;

  /// Over the lattice's cells (trilinear gradient at the centres of each cell's eight
  /// octants): the smallest and largest det(grad phi); a value <= 0 means phi folds (not
  /// invertible) there.
  double min_volume_ratio() const;
  double max_volume_ratio() const;
  bool folds() const { return min_det_ <= 0; }
  /// phi is the identity: no local displacement and the global map's every part the
  /// identity (a model at rest carries its planning organ exactly).
  bool identity() const { return identity_; }
  /// Where u may be nonzero (mm): the lattice's box; empty at rest.
  geometry::Aabb local_box() const;
  /// The box of the particles (placed and current) widened by the support and the
  /// largest move (mm): where today's organ lies. Empty without particles.
  geometry::Aabb particle_box() const { return particle_box_; }
  const GlobalMap& global_map() const { return map_; }
  /// M(r): the global map at r (mm), its shear fields from their table, as phi uses it.
  Eigen::Vector3d map(const Eigen::Vector3d& r_mm) const { return map_.apply(r_mm, map_fields_); }
  /// The largest |u| over the lattice (mm; 0 at rest): phi(r) lies within it of M(r).
  double largest_u_mm() const { return largest_u_mm_; }
  double support_mm() const { return h_; }
  /// The spacing of u's lattice (mm): a third of the support.
  double lattice_mm() const;
  /// Lattice nodes where u is the moving least squares' answer, and where it is harmonic.
  long long fitted_nodes() const { return fitted_nodes_; }
  long long harmonic_nodes() const { return harmonic_nodes_; }

 private:
  GlobalMap map_;
  bool identity_ = true;  // no local displacement and the map the identity: q itself
  Eigen::Matrix3d map_inverse_a_ = Eigen::Matrix3d::Identity();
  ShearFieldTable map_fields_;  // map_'s shear fields, tabulated (shear_field_table.h)
  double h_ = 1;
  geometry::Aabb particle_box_;
  // The lattice: node (i, j, k) at origin_ + spacing_ * (i, j, k), n_ nodes a side.
  Eigen::Vector3d origin_ = Eigen::Vector3d::Zero();
  double spacing_ = 1;
  Eigen::Vector3i n_ = Eigen::Vector3i::Zero();
  std::vector<Eigen::Vector3f> values_;  // u (mm)
  double min_det_ = 1, max_det_ = 1;     // of det(grad phi^-1) over the lattice's cells
  double largest_u_mm_ = 0;              // |u| over the nodes
  geometry::BlockMaxima grad_u_sq_;      // |grad u|^2 bounds (Frobenius) at the nodes, by blocks
  long long fitted_nodes_ = 0, harmonic_nodes_ = 0;
  /// Solves the Laplace equation for u at the nodes neither `held` (values_ there: the
  /// answers, or zero beyond D) nor on the lattice's faces (u = 0), matching the held
  /// values; returns how many nodes it solved.
  long long solve_harmonic_part(const std::vector<std::uint8_t>& held);

  Eigen::Vector3d node(long long v) const;  ///< node v's position (mm)
  /// u (mm) at the 8 nodes of the cell whose lowest node is v0: corner c at offsets
  /// (c & 1, c >> 1 & 1, c >> 2 & 1).
  void cell_corners(long long v0, Eigen::Vector3d (&corner)[8]) const;
  /// The lattice cell holding q (its lowest node) and q's fraction f of it along each
  /// axis; -1 beyond the lattice (or without one), where u is zero.
  long long cell_at(const Eigen::Vector3d& q_mm, Eigen::Vector3d& f) const;
};

}  // namespace organfit::fitting
