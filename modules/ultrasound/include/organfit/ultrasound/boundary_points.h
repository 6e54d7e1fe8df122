#pragma once
// Attractive points from an ultrasound volume: the organ's boundary found by an edge
// search along rays from a centre, as is usual for transrectal prostate ultrasound.
//
//   1. speckle reduction: Gaussian smoothing (sigma `smoothing_mm`) of the region of
//      interest (a cube of side 2 r_max around the centre);
//   2. rays from the centre in `rays` directions (a Fibonacci sphere); each is searched
//      between r_min and r_max or, with a prior shape (the organ model mapped into the
//      ultrasound frame), within `band_mm` of where the prior's surface crosses it;
//   3. the boundary on a ray: the steepest point of the first outward rise reaching half
//      the ray's largest (a dark gland into its bright capsule or the fat around it);
//      rays leaving the field of view first are dropped, and so are edges weaker than
//      `weak_edge_fraction` of the median edge (speckle, a fading interface);
//   4. outliers: a ray whose boundary radius differs from the median of its neighbours'
//      (the 8 nearest directions) by more than `mad_threshold` x 1.4826 MAD (at least
//      0.5 mm) is rejected;
//   5. the rest are subsampled to `target_count` points spread over the boundary
//      (farthest-point sampling of their ray directions from the most confident; spread
//      in positions would prefer outliers), each with a confidence: its rise over the
//      largest rise, in [0.1, 1].
#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "organfit/geometry/image_geometry.h"

namespace organfit::ultrasound {

struct BoundaryOptions {
  Eigen::Vector3d centre_mm = Eigen::Vector3d::Zero();  ///< inside the organ (volume frame)
  double r_min_mm = 2, r_max_mm = 40;
  std::function<bool(const Eigen::Vector3d&)>
      prior_inside;    ///< optional organ prior (volume frame)
  double band_mm = 8;  ///< search band around the prior's surface (used with a prior)
  int rays = 2000;
  double smoothing_mm = 1.0;
  double mad_threshold = 3.0;
  double weak_edge_fraction = 0.7;  ///< edges weaker than this x the median edge are dropped
  int target_count = 87;            ///< 0: keep every accepted ray
};

struct BoundaryPoint {
  Eigen::Vector3d p_mm;
  double confidence = 1;
};

struct BoundaryResult {
  std::vector<BoundaryPoint> points;
  int rays = 0, rays_in_view = 0, rejected = 0, weak = 0;
};

/// An ultrasound image shows millimetres to tens of centimetres: throws
/// std::invalid_argument, naming the extents, when one of `extent_mm` (an image's or a
/// volume's sides, mm) lies outside 1 mm to 1 m or is not finite (a pixel size in the wrong
/// unit, or a damaged calibration: the search steps by half a pixel across the region).
void check_field_of_view(const std::vector<double>& extent_mm);

/// Finds boundary points in `intensity` on `geometry`; `in_view` (optional, same size)
/// marks the field of view. Throws std::invalid_argument on sizes that do not match, a
/// centre outside the volume, or a volume that is not an ultrasound's (check_field_of_view).
BoundaryResult boundary_points(const geometry::ImageGeometry& geometry,
                               const std::vector<float>& intensity,
                               const std::vector<std::uint8_t>* in_view,
                               const BoundaryOptions& options);

struct TrackedSweep;

/// The same on a tracked 2D sweep (see sequence_metafile.h): in each frame whose plane
/// passes within r_max of the centre, `rays_per_frame` rays in the plane from the centre's
/// projection; neighbours are the adjacent rays of the same frame. Points in CT mm. Throws
/// std::invalid_argument on a frame that is not an ultrasound image (check_field_of_view).
BoundaryResult sweep_boundary_points(const TrackedSweep& sweep, const BoundaryOptions& options,
                                     int rays_per_frame = 180);

/// The engine under both: rays (origin, unit direction, in mm), each ray's neighbours
/// (for step 4), and a sampler of the smoothed image along ray r at point p (setting `ok`
/// false outside the field of view); steps 3 to 5 above, radii measured from each ray's
/// origin, directions for step 5 taken from options.centre_mm.
struct Ray {
  Eigen::Vector3d origin, direction;
};
using RaySampler = std::function<double(int ray, const Eigen::Vector3d& p_mm, bool& ok)>;
BoundaryResult search_rays(const std::vector<Ray>& rays,
                           const std::vector<std::vector<int>>& neighbours,
                           const RaySampler& sample, double step_mm,
                           const BoundaryOptions& options);

}  // namespace organfit::ultrasound
