#pragma once
// The global map of our fit (docs/method.md): x -> flow(fields(shears(a x + t))), an affine
// part with det(a) = 1, quadratic shears, smooth shear fields and, where a scene asks for
// it, an incompressible flow. Each part keeps volume (exactly; the flow to its RK4's error)
// and inverts (likewise); global_fit.h fits it.
#include <Eigen/Core>
#include <array>
#include <utility>
#include <vector>

#include "organfit/fitting/surface_samples.h"
#include "organfit/geometry/image_geometry.h"

namespace organfit::fitting {

struct AffineFit {
  Eigen::Matrix3d a = Eigen::Matrix3d::Identity();  ///< det(a) = 1
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  double rms_before_mm = 0, rms_after_mm = 0;  ///< point-to-surface, over the kept points
  /// the steps (ICP or Gauss-Newton) of the fits that made the map, those of the fit it
  /// started from included
  int iterations = 0;
};

/// Bending and twisting on top of the affine map: five shears applied in turn about
/// `centre` (u = q - centre),
///   x += c0 u_y^2 + c1 u_z^2 + c2 u_y u_z,
///   y += c3 u_x^2 + c4 u_z^2 + c5 u_x u_z,
///   z += c6 u_x^2 + c7 u_y^2 + c8 u_x u_y,
///   y += c9 u_x^2 + c10 u_z^2 + c11 u_x u_z,
///   x += c12 u_y^2 + c13 u_z^2 + c14 u_y u_z,
/// each moving one coordinate by a function of the other two: every shear, and so the
/// whole map, keeps volume exactly (Jacobian determinant 1), and inverts exactly. The
/// last two make a twist about any axis (a rotation growing along it) a sequence of three
/// shears, y z y about x (a rotation by phi is y -= tan(phi/2) z, z += sin(phi) y, y -=
/// tan(phi/2) z), x z x about y, x y x about z: with the first three alone, a cube's
/// corners twisted by 38 degrees were left 3 mm in (the cosine's part, second order).
struct QuadraticShears {
  static constexpr int kCount = 15;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  Eigen::Matrix<double, kCount, 1> c = Eigen::Matrix<double, kCount, 1>::Zero();
  Eigen::Vector3d apply(const Eigen::Vector3d& q) const;
  Eigen::Vector3d inverse(const Eigen::Vector3d& q) const;
};

/// Smooth shears on top of the quadratic ones: three fields applied in turn,
///   x += f_x(y, z),  y += f_y(x, z),  z += f_z(x, y),
/// each a sum of Gaussian bumps, f_a(v) = sum_j w_aj exp(-|v - c_j|^2 / (2 sigma^2)), their
/// centres c_j on a square grid of spacing sigma over the body's box in the plane of the
/// other two coordinates. Like the quadratic shears, each moves one coordinate by a
/// function of the other two: volume kept exactly, inverse exact. They carry what a
/// quadratic cannot, a change of shape over part of the organ (a dent from the rectum, a
/// push from the bladder), and carry it through the organ: a dent in the side the probe
/// sees moves the side it does not, as an incompressible body must.
struct ShearFields {
  double sigma_mm = 0;  ///< width of the bumps and spacing of their centres (0: no fields)
  Eigen::Vector3d origin_mm = Eigen::Vector3d::Zero();  ///< the grid's first centre, each axis
  Eigen::Vector3i count = Eigen::Vector3i::Zero();      ///< centres along each axis
  /// the bumps' heights (mm): field a's (a = 0, 1, 2) for the centres of the grid over the
  /// other two axes (b < c), centre (i, j) at index a * block + i + count[b] * j, where
  /// block is the largest count[b] * count[c] (unused entries zero)
  Eigen::VectorXd weights;

  /// A grid over `box` widened by one spacing, all weights zero.
  static ShearFields over(const Eigen::Vector3d& box_min_mm, const Eigen::Vector3d& box_max_mm,
                          double sigma_mm);
  bool empty() const { return sigma_mm <= 0 || weights.size() == 0 || weights.isZero(0); }
  int block() const;
  /// The index in `weights` of field a's centre (i, j) (the layout above).
  int weight_index(int a, int i, int j) const;
  /// Field a's heights as a count[b] x count[c] matrix, centre (i, j) at (i, j).
  Eigen::Map<const Eigen::MatrixXd> heights(int a) const;
  /// The bumps of field `a` at q (only q's other two coordinates count), index and value;
  /// those below 1e-6 are left out.
  void bumps(int a, const Eigen::Vector3d& q, std::vector<std::pair<int, double>>& out) const;
  double field(int a, const Eigen::Vector3d& q) const;  ///< f_a at q (mm)
  double largest_weight(int a) const;                   ///< field a's largest |bump height| (mm)
  /// A bound on |grad f_a| (mm per mm) over the points of `box` (mm; only its extent
  /// along the other two axes counts): the gradient, all bumps counted, sampled over the
  /// box and raised by what it can grow between samples.
  double largest_gradient(int a, const geometry::Aabb& box) const;
  Eigen::Vector3d apply(const Eigen::Vector3d& q) const;
  Eigen::Vector3d inverse(const Eigen::Vector3d& q) const;
};

/// A smooth incompressible flow on top of the shear fields: the map is the flow over unit
/// time of the velocity v = curl psi, psi(x) = sigma sum_n a_n B((x - c_n) / sigma), B the
/// tensor cubic B-spline, its nodes c_n on a cubic grid of spacing sigma (mm) over the body's
/// box, a_n (mm) three per node. v is divergence-free, so its flow keeps volume (to the
/// RK4 integration's error, kSteps steps; the inverse is the flow backwards). Where a shear
/// field moves a whole line of the body with a dent, the flow moves the tissue about a
/// change and no further (a dent, the bulge beside it), and it can round a cube into an
/// ellipsoid, which no shear can (the incompressible stationary velocity fields of
/// registration: Mansi et al., iLogDemons, 2011).
struct IncompressibleFlow {
  static constexpr int kSteps = 4;
  double sigma_mm = 0;  ///< node spacing and the B-spline's scale (0: no flow)
  Eigen::Vector3d origin_mm = Eigen::Vector3d::Zero();  ///< node (0, 0, 0)
  Eigen::Vector3i count = Eigen::Vector3i::Zero();      ///< nodes along each axis
  /// a_n (mm): node (i, j, k)'s three at 3 (i + count_x (j + count_y k)) + component
  Eigen::VectorXd potentials;

  /// Nodes over `box` widened by two spacings (the B-spline's reach), all potentials zero.
  static IncompressibleFlow over(const Eigen::Vector3d& box_min_mm,
                                 const Eigen::Vector3d& box_max_mm, double sigma_mm);
  bool empty() const { return sigma_mm <= 0 || potentials.size() == 0 || potentials.isZero(0); }
  /// grad(B-spline of node n) at q (per sigma: v = sum_n gradient_n x a_n) for the up to 64
  /// nodes whose support holds q.
  void basis_gradients(const Eigen::Vector3d& q,
                       std::vector<std::pair<int, Eigen::Vector3d>>& out) const;
  Eigen::Vector3d velocity(const Eigen::Vector3d& q) const;  ///< mm per unit time
  Eigen::Vector3d apply(const Eigen::Vector3d& q) const;
  Eigen::Vector3d inverse(const Eigen::Vector3d& q) const;
  /// Bounds over all space, from the largest first and second differences of the
  /// potentials between nodes (one pass over them).
  struct Bounds {
    double speed_mm = 0;           ///< |v|
    double velocity_gradient = 0;  ///< the spectral norm of grad v, per unit time
  };
  Bounds bounds() const;
  /// The pull per potential^2 that gives the potentials the prior ShearFields' heights have
  /// at a pull of one per height^2: the same mean variance of a point's move.
  static double stiffness_per_field_stiffness();
};

/// How far apart a map can put two points: |f(p) - f(q)| <= stretch |p - q| + slack_mm
/// for p, q in a given box. `stretch` bounds the largest singular value of f's Jacobian
/// there; `slack_mm` what the computed f may differ from that smooth map (the Gaussian
/// bumps below 1e-6 that ShearFields leaves out).
struct StretchBound {
  double stretch = 1;
  double slack_mm = 0;
};

class ShearFieldTable;

/// How far an evaluation of the shear fields may be from their bumps' smooth sum, each
/// field: its value (mm) and its gradient (mm per mm). Zero for the bumps themselves
/// (what they leave out is StretchBound's slack); a table's (shear_field_table.h) else.
struct FieldEvaluationError {
  std::array<double, 3> value_mm{0, 0, 0};
  std::array<double, 3> gradient{0, 0, 0};
};

/// The global map: affine (det 1), then quadratic shears, then smooth shear fields, then
/// the flow. Volume-preserving.
struct GlobalMap {
  AffineFit affine;
  QuadraticShears shears;
  ShearFields fields;
  IncompressibleFlow flow;
  double rms_after_mm = 0;  ///< point-to-surface over the kept points
  bool refused = false;     ///< no plausible map: the identity instead
  /// When refused: the best fit's move of the organ (its surface's mean displacement, mm) and
  /// its largest stretch (the largest of its principal stretches and their inverses).
  double refused_move_mm = 0, refused_stretch = 1;
  bool shears_dropped = false;  ///< the shears were implausible: the affine part alone
  /// which fit of fit_global_map's it is: "affine", "whole map", "whole map annealed",
  /// "signed distance", "signed distance (shears)", "signed distance (stiffer shears)"
  /// ("none": not fitted); with shear fields on top of it when `fields` is not empty
  const char* found_by = "none";
  /// The share of the fitted change kept (towards_identity): what the points show beyond
  /// their noise (fit_global_map); 1 when nothing was shrunk.
  double kept_share = 1;
  Eigen::Vector3d apply(const Eigen::Vector3d& p) const {
    return flow.apply(fields.apply(shears.apply(affine.a * p + affine.t)));
  }
  /// Every part the identity (a map never fitted, or fitted to no change at all).
  bool identity() const {
    return affine.a == Eigen::Matrix3d::Identity() && affine.t.isZero(0) && shears.c.isZero(0) &&
           fields.empty() && flow.empty();
  }
  Eigen::Vector3d inverse(const Eigen::Vector3d& q) const;
  /// The same with affine.a's inverse at hand (`a_inverse`), for callers that invert
  /// many points through one map.
  Eigen::Vector3d inverse(const Eigen::Vector3d& q, const Eigen::Matrix3d& a_inverse) const {
    return a_inverse * (shears.inverse(fields.inverse(flow.inverse(q))) - affine.t);
  }
  /// apply and inverse with the fields evaluated by `table` (made from `fields`).
  Eigen::Vector3d apply(const Eigen::Vector3d& p, const ShearFieldTable& table) const;
  Eigen::Vector3d inverse(const Eigen::Vector3d& q, const Eigen::Matrix3d& a_inverse,
                          const ShearFieldTable& table) const;
  /// A bound on how the inverse stretches distances over `box` (mm), from each part's
  /// largest gradient there: the fields' from their largest weight, the shears' from the
  /// box's extent about their centre (grown by the fields' largest move), the affine
  /// part's from its smallest singular value. Loose (a product of the parts' bounds) but
  /// never below the truth. With `evaluation`, for fields evaluated within that error of
  /// their bumps (a table's): each field's gradient bound and move grown by it.
  StretchBound inverse_stretch(const geometry::Aabb& box,
                               const FieldEvaluationError& evaluation = {}) const;
};

/// The surface samples moved by `map` (its fields from their table, shear_field_table.h):
/// points mapped, normals turned by the inverse transpose of its Jacobian (by central
/// differences) and made unit again; their keys kept.
SurfaceSamples map_surface(const GlobalMap& map, const SurfaceSamples& surface);

/// How much `map` changes the shape and orientation of the body whose surface is sampled
/// (mm): the RMS displacement of the samples about their mean displacement (the
/// translation).
double shape_change_mm(const GlobalMap& map, const SurfaceSamples& surface);

/// `map` moved a share `c` (0 to 1) of the way from the identity: the affine part about
/// `centre` (mm) as a rotation by c of its angle and a stretch by its principal stretches to
/// the power c (det 1 kept), its translation there times c; the shears' coefficients, the
/// fields' heights and the flow's potentials times c. Each part keeps volume as before; c = 1
/// is `map`, c = 0 the identity.
GlobalMap towards_identity(const GlobalMap& map, double c, const Eigen::Vector3d& centre);

/// How far (mm) the quadratic shears, the shear fields and the flow each move any of the
/// surface samples at most: the shears from the affine image, the fields from the sheared
/// one, the flow from the fields'. Each is bounded by max_shear_mm x the body's size for a
/// map to be plausible.
struct LargestMoves {
  double shears_mm = 0, fields_mm = 0, flow_mm = 0;
};
LargestMoves largest_moves(const GlobalMap& map, const SurfaceSamples& surface);

}  // namespace organfit::fitting
