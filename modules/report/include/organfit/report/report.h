#pragma once
// report.html: one self-contained page (no network) a physicist reads at a glance.
//
// Top to bottom: warnings (outliers rejected, volume change, points never reached, an
// unconverged fit); the scene and its outputs; stage times; model statistics; the error
// against run time (data residual and volume change against wall time, from history.csv,
// as SVG); axial, coronal and sagittal CT slices through the organ with the planning
// contour (dashed) and the fitted contour (solid) and the attractive points near each
// plane coloured by residual; the fitted surface in an embedded 3D view (canvas, drag to
// turn). Images are PNG in data URIs; the 3D view is plain JavaScript with its mesh inline.
// No patient name or ID appears unless `patient` is given (the scene asks for it).
#include <Eigen/Core>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "organfit/geometry/image_geometry.h"

namespace organfit::report {

/// A point in a view, in mm from the view's top-left corner.
struct ViewPoint {
  double x_mm = 0, y_mm = 0;
  double residual_mm = 0;  ///< colour: green < 1 mm, amber < 2 mm, red beyond
};

/// One CT plane through the organ, cropped around it, with outlines on it.
struct SliceView {
  std::string title;          ///< e.g. "axial, z = 1.2 mm"
  int width = 0, height = 0;  ///< pixels
  double pixel_w_mm = 1, pixel_h_mm = 1;
  std::vector<std::uint8_t> gray;  ///< width x height, row-major, top row first
  std::vector<std::vector<Eigen::Vector2d>> planning, fitted;  ///< closed polylines, mm
  std::vector<ViewPoint> points;
  std::string left, right, top, bottom;  ///< patient directions at the edges (L, R, A, P, S, I)
};

enum class Plane { kAxial, kCoronal, kSagittal };

/// The plane through voxel `index` (k for axial, j for coronal, i for sagittal) of a CT,
/// cropped to `crop_lo`..`crop_hi` (voxel indices, inclusive), soft-tissue window
/// (level 40, width 400 HU); the masks' outlines traced on it (either may be null); the
/// points within `slab_mm` of the plane with their residuals.
SliceView slice_view(const geometry::ImageGeometry& ct, const std::vector<float>& hu, Plane plane,
                     int index, const std::array<int, 3>& crop_lo,
                     const std::array<int, 3>& crop_hi, const geometry::LabelVolume* planning,
                     const geometry::LabelVolume* fitted,
                     const std::vector<Eigen::Vector3d>& points_mm,
                     const std::vector<double>& residuals_mm, double slab_mm);

struct ReportInput {
  nlohmann::json run;       ///< run.json as written
  std::string scene_yaml;   ///< resolved.yaml
  std::string history_csv;  ///< history.csv (empty without a fit)
  std::vector<SliceView> views;
  std::vector<float> surface_vertex_mm;  ///< fitted surface, x y z per vertex
  std::vector<int> surface_triangles;    ///< three indices per triangle
  std::vector<Eigen::Vector3d> points_mm;
  std::vector<double> residuals_mm;
  std::string patient;  ///< empty: no patient name or ID in the page
};

/// The page.
std::string report_html(const ReportInput& input);

/// An 8-bit grey PNG (for tests and the views).
std::string png_gray(int width, int height, const std::uint8_t* pixels);
/// RFC 4648 base64.
std::string base64(const std::string& bytes);

}  // namespace organfit::report
