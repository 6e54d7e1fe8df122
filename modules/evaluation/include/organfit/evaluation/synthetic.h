#pragma once
// Ground truth for fits (METHOD.md s.7): analytic organ shapes, known volume-preserving
// deformations with exact inverses, points sampled on the deformed surface, and the
// fitted model's surface compared with the true one.
#include <Eigen/Core>
#include <array>
#include <functional>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "organfit/fitting/attractive_points.h"
#include "organfit/fitting/embedded_body.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/geometry/shape.h"

namespace organfit::evaluation {

/// A displacement sampled on a grid: a point x moves to x + u(x), u trilinear between the
/// voxel centres and held at its border value beyond the grid (mm, patient frame). A FEM
/// solution is one (testdata/fem/fem_cases.py, read by bench/fem_cases.h).
struct SampledDisplacement {
  geometry::ImageGeometry grid;  ///< axis-aligned (identity direction)
  std::vector<float> u_mm;       ///< x, y, z per voxel, i fastest
  double largest_mm = 0;         ///< max |u| over the grid
  Eigen::Vector3d at(const Eigen::Vector3d& p_mm) const;
  /// du/dx at p (central differences over half a voxel), 3 x 3, dimensionless.
  Eigen::Matrix3d gradient(const Eigen::Vector3d& p_mm) const;
};

/// Checks the grid (axis-aligned, 3 values per voxel, finite) and sets largest_mm. Throws
/// std::invalid_argument otherwise.
SampledDisplacement make_sampled_displacement(const geometry::ImageGeometry& grid,
                                              std::vector<float> u_mm);

/// A volume-preserving deformation with a known inverse, about a centre c, applied in
/// this order (each step has Jacobian determinant 1, so their composition has too):
///   field:   x' = x + u(x), a sampled displacement (a FEM's; its inverse by Newton's
///            method, to 1e-5 mm)
///   stretch: x' = c + S (x - c), S = diag(s, 1/sqrt(s), 1/sqrt(s))
///   bend:    y' = y + b ((x' - c_x) / L)^2, with L the half-length along x
///   twist:   (y, z) turned about the x axis through c by  w (x - c_x) / L  radians
///   indent:  y' = y + a exp(-((x - c_x)^2 + (z - c_z)^2) / (2 sigma^2))   (rectal filling:
///            a column of tissue moved anteriorly for a < 0, dent behind, bulge in front)
///   push:    z' = z + p exp(-((x - c_x)^2 + (y - c_y)^2) / (2 sigma^2))   (bladder push)
///   rigid:   x' = c + R (x - c) + t, R the rotation by the vector `rotation_rad` (axis
///            times angle), t `shift_mm` (the organ's motion between sessions)
/// Each of bend, indent and push moves a coordinate by a function of the others (a shear);
/// the twist is a rotation whose angle depends on the untouched coordinate.
struct Deformation {
  double stretch = 1.0;
  double bend_mm = 0.0;
  double twist_rad = 0.0;  ///< w: the turn at x = c_x +- L
  double indent_mm = 0.0;  ///< a
  double push_mm = 0.0;    ///< p
  double bump_sigma_mm = 8.0;
  Eigen::Vector3d rotation_rad = Eigen::Vector3d::Zero();
  Eigen::Vector3d shift_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d centre_mm = Eigen::Vector3d::Zero();
  double half_length_mm = 1.0;
  std::shared_ptr<const SampledDisplacement> field;  ///< none: no sampled part
  Eigen::Vector3d apply(const Eigen::Vector3d& p) const;
  Eigen::Vector3d inverse(const Eigen::Vector3d& p) const;
  /// A radius (mm) within which inverse() lays every point of the ball of `radius_mm`
  /// about p, about inverse(p): each step's Lipschitz bound over the ball as it is carried,
  /// times a margin for rounding. Infinite with a sampled displacement (its inverse is
  /// iterative, to a tolerance).
  double inverse_radius(const Eigen::Vector3d& p, double radius_mm) const;
  Eigen::Matrix3d rotation() const;  ///< R of the rigid part
  bool is_identity() const {
    return stretch == 1.0 && bend_mm == 0.0 && twist_rad == 0.0 && indent_mm == 0.0 &&
           push_mm == 0.0 && rotation_rad.isZero(0) && shift_mm.isZero(0) && !field;
  }
};

struct SamplingOptions {
  int count = 87;
  double noise_mm = 0.5;          ///< isotropic Gaussian noise
  double outlier_fraction = 0.0;  ///< this fraction of points moved 5 to 15 mm off the surface
  bool half_coverage = false;     ///< only the +y half of the surface (what a probe sees)
  unsigned seed = 1;
};

/// Points on the deformed surface: boundary points of `shape` found along rays from a point
/// inside it (geometry::ray_origin_mm: its centre, or a mask's deepest voxel if it lies out;
/// uniform directions, the first exit, bisection to 0.01 mm; half coverage: directions with
/// y >= 0), mapped by `deformation`, then noise and outliers. Deterministic for a seed.
std::vector<fitting::AttractivePoint> sample_deformed_surface(const geometry::Shape& shape,
                                                              const Deformation& deformation,
                                                              const SamplingOptions& options);

/// The deformed shape's inside test: inside(deformation.inverse(p)).
std::function<bool(const Eigen::Vector3d&)> deformed_inside(const geometry::Shape& shape,
                                                            const Deformation& deformation);

/// A body given by its inside test and, when it has one, a test of a whole ball (all
/// inside, all outside, or not known; never wrong) that lets a lattice set the voxels far
/// from its surface without testing each.
struct InsideTest {
  std::function<bool(const Eigen::Vector3d&)> inside;
  std::function<geometry::BallSide(const Eigen::Vector3d&, double)> ball;  ///< may be empty
};

/// The body on `grid` (label 1 inside): each voxel centre tested, or with a ball test,
/// blocks of voxels it places wholly inside or outside set at once and the rest halved
/// down to single voxels, each tested: the same labels, at a cost set by the surface's
/// area rather than the body's volume. `inside` and `ball` are called from several threads.
geometry::LabelVolume sample_inside(const InsideTest& body, const geometry::ImageGeometry& grid);

/// The shape itself: its inside() and inside_ball().
InsideTest shape_body(const geometry::Shape& shape);

/// The deformed shape: deformed_inside, and its ball test: the shape's
/// (geometry::Shape::inside_ball) on the ball inverse_radius gives about inverse(p).
InsideTest deformed_body(const geometry::Shape& shape, const Deformation& deformation);

/// Voxel (mm) of the grid on which a fit is compared with a known truth (surface
/// distances, Dice, the benchmark's volumes): fixed, so that a measure does not depend on
/// a model's resolution. On a grid of rho/2, HD95 came in steps of 0.96 mm on the
/// prostate (rho 1.92 mm) and 1.5 mm on the real GTV (rho 3 mm), and the 30 mm cube at
/// rest was 0.44 mm from itself (its faces flip a whole layer of voxels).
inline constexpr double kTruthVoxelMm = 0.5;

/// A body on a KnownBody's lattice (voxels of `voxel_mm` fixed in space), made once and
/// compared with every truth on that lattice: the organ left as it was is compared with
/// its own shape (the discretisation floor) and with the deformed one. `labels` covers its
/// inside voxels with at least one voxel about them on every side (0 beyond), `inside`
/// is the index range of its inside voxels there, `surface` its surface voxels.
struct LatticeBody {
  geometry::LabelVolume labels;
  geometry::IndexRange inside;
  long long inside_voxels = 0;
  double voxel_mm = 0;
  std::unique_ptr<geometry::MaskSurface> surface;
};

/// A body known by its inside test (a synthetic case's truth), sampled on a lattice of
/// cubic voxels of `voxel_mm` fixed in space (centres at (n + f) voxel_mm on each patient
/// axis, f an irrational phase) and compared with other bodies on it (mask_ops.h has the
/// definitions). The lattice does not move with a compared body's box, so a measure
/// does not change with the phase of the samples, and the truth is sampled once, when
/// made, for all the bodies compared with it: the organ left as it was, the fitted organ,
/// the particles' balls, each baseline's. It is sampled over `bounds` (mm) and beyond,
/// grown until none of its inside voxels lies on the sampled part's faces: a connected
/// body is then whole within the sampled part whatever `bounds` missed (a part wholly
/// beyond them and apart from the rest would be missed). A compared body's measure is
/// that of its inside voxels alone (its surface and volume do not depend on the box it was
/// sampled over). `inside` is called from several threads; nothing is sampled after the
/// constructor. Throws std::invalid_argument for a voxel <= 0, bounds not finite, or a
/// body that reaches past 1e9 voxels.
class KnownBody {
 public:
  KnownBody(std::function<bool(const Eigen::Vector3d&)> inside, const geometry::Aabb& bounds,
            double voxel_mm);
  /// With a ball test as well, sampled as sample_inside() samples.
  KnownBody(InsideTest body, const geometry::Aabb& bounds, double voxel_mm);
  /// The organ a model carries (fitting/embedded_body.h) on the lattice, over its box with
  /// a margin of 2 voxels.
  LatticeBody sample(const fitting::EmbeddedBody& organ) const;
  /// The closed body of a particle set (balls of `radius_mm` closed by the same) on the
  /// lattice, over a box with a margin of 2 radii and 2 voxels.
  LatticeBody sample(const Eigen::Matrix3Xd& particles, double radius_mm) const;
  /// Compares a body on this lattice (volume_a_mm3: the body's, volume_b_mm3: this one's).
  /// Throws std::invalid_argument when it was sampled with another voxel size.
  geometry::SurfaceComparison compare(const LatticeBody& body) const;
  geometry::SurfaceComparison compare(const fitting::EmbeddedBody& organ) const {
    return compare(sample(organ));
  }
  geometry::SurfaceComparison compare(const Eigen::Matrix3Xd& particles, double radius_mm) const {
    return compare(sample(particles, radius_mm));
  }
  double voxel_mm() const { return voxel_mm_; }
  long long sampled_voxels() const { return sampled_.geometry.voxel_count(); }
  /// The part of the lattice covering `box` grown by `margin_mm` (what a compare uses).
  geometry::ImageGeometry lattice_covering(const geometry::Aabb& box, double margin_mm) const;

 private:
  void cover(const geometry::ImageGeometry& g);  // samples the union of g and what was sampled
  // Whether an inside voxel lies on the sampled part's low and high face, each axis.
  std::array<std::array<bool, 2>, 3> faces_touched() const;
  // `whole` (a body on a part of the lattice) as a LatticeBody: as it is when no inside
  // voxel lies on its faces, else the part about its inside voxels, 2 voxels wide.
  LatticeBody on_lattice(geometry::LabelVolume whole) const;
  InsideTest body_;
  geometry::Aabb bounds_;
  double voxel_mm_;
  geometry::LabelVolume sampled_;  // label 1 inside, on the part of the lattice sampled
  long long inside_voxels_ = 0;
  std::unique_ptr<geometry::MaskSurface> surface_;  // the sampled part's inside voxels'
};

/// Compares the closed body of a particle set (balls of `radius_mm`, closed by the same)
/// with a body given by its inside test: KnownBody's compare, for one body.
geometry::SurfaceComparison compare_with_body(
    const Eigen::Matrix3Xd& particles, double radius_mm,
    const std::function<bool(const Eigen::Vector3d&)>& inside, const geometry::Aabb& body_bounds,
    double voxel_mm);

/// Compares the organ a model carries (fitting/embedded_body.h) with a body given by its
/// inside test: KnownBody's compare, for one body.
geometry::SurfaceComparison compare_with_body(
    const fitting::EmbeddedBody& organ, const std::function<bool(const Eigen::Vector3d&)>& inside,
    const geometry::Aabb& body_bounds, double voxel_mm);

}  // namespace organfit::evaluation
