#pragma once
// An organ's shape as an inside test, in mm (patient LPS): analytic (the paper's cube,
// an ellipsoid, a prostate-like egg, a notched lung) or a label mask (an organ imported
// from an RT Structure Set or segmented from CT).
#include <Eigen/Core>
#include <memory>
#include <optional>
#include <string>

#include "organfit/geometry/label_by_blocks.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/geometry/signed_distance.h"

namespace organfit::geometry {

struct Shape {
  enum class Kind { ellipsoid, box, egg, lung, mask };
  Kind kind = Kind::ellipsoid;
  Eigen::Vector3d size_mm = Eigen::Vector3d::Ones();    ///< full extents (before the notch)
  Eigen::Vector3d centre_mm = Eigen::Vector3d::Zero();  ///< centre (a mask: its centroid)
  std::shared_ptr<const LabelVolume> mask;              ///< kind "mask": label 1 is inside
  /// kind "mask": the organ is {distance->beyond_level(p) < 0}: the mask's signed distance
  /// (unsmoothed, on geometry::cropped_organ of it) at its volume level by the place
  /// between slices (SignedDistance::volume_level_at), the surface the
  /// fit's organ and every export have (fitting::organ_body), so that the reference the fit
  /// measures points against, generated points and a benchmark's truth are that organ too.
  /// Not the 0.5 level of the mask's trilinear interpolation, which holds a contour to the
  /// midplane between thick slices (docs/decisions.md, "A mask organ is one surface").
  std::shared_ptr<const SignedDistance> distance;
  Aabb box;  ///< kind "mask": bounds of its voxels, half a voxel more (where the level lies)
  bool inside(const Eigen::Vector3d& p) const;
  /// Whether inside() answers the same for every point within `radius_mm` of p, and what:
  /// never wrong, `unknown` near the surface. An analytic kind from a bound on how fast its
  /// defining function can change (a margin of 1e-9 relative for rounding); a mask from its
  /// distance's bound on its gradient over the ball.
  BallSide inside_ball(const Eigen::Vector3d& p, double radius_mm) const;
  /// The kind's name, as make_shape takes it: "ellipsoid", "box", "egg", "lung", "mask".
  const char* kind_name() const;
  Aabb bounds() const {
    return mask ? box : Aabb{centre_mm - 0.5 * size_mm, centre_mm + 0.5 * size_mm};
  }
  /// A box holding every point inside() says is inside: bounds(), and for a mask the part
  /// beyond its grid's faces where the organ reaches them (a scan that cut it: the distance
  /// goes on beyond its grid, signed_distance.h). A liver cut by its CT's top slice went on
  /// 3.5 mm past bounds() after a 1.1 stretch.
  Aabb extent() const;
};

/// A shape from a mask (label 1), its distance made and its levels found (`levels`, when
/// given, adopted instead: a saved model's, as SignedDistance::adopt_volume_levels takes
/// them).
/// Call outside a parallel region (the distance's passes are on threads). Throws
/// std::invalid_argument when the mask is empty.
Shape make_mask_shape(std::shared_ptr<const LabelVolume> mask,
                      std::optional<SignedDistance::VolumeLevels> levels = std::nullopt);

/// Makes a shape: "ellipsoid" and "box" as named; "egg" is an ellipsoid whose cross-
/// section narrows linearly towards -x (a prostate's apex, 30% narrower at the tip);
/// "lung" is an ellipsoid with a spherical notch cut from its -x side (the cardiac
/// notch). Throws std::invalid_argument on an unknown kind or non-positive size.
Shape make_shape(const std::string& kind, const Eigen::Vector3d& size_mm,
                 const Eigen::Vector3d& centre_mm);

/// The shape on `grid` (label 1 inside) over the voxels of `range` (0 elsewhere): each
/// voxel centre's inside(), blocks that inside_ball places wholly on one side set at once
/// (label_by_blocks.h): the same labels.
LabelVolume shape_on_grid(const Shape& shape, const ImageGeometry& grid, const IndexRange& range);

/// Volume of a shape by counting the voxel centres of a grid of `voxel_mm` inside it (mm^3).
double shape_volume_mm3(const Shape& shape, double voxel_mm);

/// A point inside the shape from which rays find its surface (mm): its centre (a mask's
/// centroid, about which the known deformations are defined) when the shape holds it, as an
/// analytic body always does; otherwise (a mask) its deepest voxel centre, the centre of
/// its largest inscribed ball by the voxels' distance transform (of ties, the first in
/// index order). A mask's centroid can lie outside it: a kidney's lies in its sinus, and
/// rays from there end at once (its generated points: 64 of 87 within 3 mm of it).
Eigen::Vector3d ray_origin_mm(const Shape& shape);

}  // namespace organfit::geometry
