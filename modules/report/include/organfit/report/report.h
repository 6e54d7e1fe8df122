#pragma once
// report.html: one self-contained page (no network) a physicist reads at a glance, and
// prints on A4.
//
// Top to bottom: warnings (outliers rejected, volume change, points never reached, an
// unconverged fit, a failed send); the structure the planning system receives (name,
// volume on the CT grid, contours, the export's topology and volume checks) beside the
// model's and the fit's numbers, each labelled in words with its unit; Dice, HD95 and
// mean surface distance against the truth where it is known; stage times; the error
// against run time (from history.csv, as SVG); every axial CT slice through the organ,
// browsable, with the planning contour (dashed), the fitted contour (solid) and the
// attractive points near the slice coloured by residual, beside the central coronal and
// sagittal planes; the CT window chosen from the organ's surroundings (soft tissue, lung
// or bone: the level nearest the median HU of a 10 mm shell around the organ), the others
// a click away (or #window=lung in the address); the fitted surface in a 3D view (canvas,
// drag to turn). Images are PNG in data URIs; the scripts are inline. Every value shown
// from run.json carries its key (data-key) and raw value (data-value) for checking.
// No patient name or ID appears unless `patient` is given (the scene asks for it).
#include <Eigen/Core>
#include <cstdint>
#include <functional>
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

/// A CT display window: HU from level - width/2 (black) to level + width/2 (white).
struct CtWindow {
  const char* name;  ///< "soft tissue", "lung", "bone"
  const char* id;    ///< "soft", "lung", "bone" (the page's #window= value)
  double level_hu, width_hu;
};

/// The windows the page offers, in this order: soft tissue (level 40, width 400 HU), lung
/// (-600, 1500), bone (400, 1800): the usual radiology presets.
const std::vector<CtWindow>& ct_windows();

/// The window for an organ: the one whose level is nearest the median HU of the CT
/// voxels within `shell_mm` outside `organ` (label 1). No voxel there: soft tissue.
struct WindowChoice {
  int window = 0;                     ///< index into ct_windows()
  double surroundings_median_hu = 0;  ///< what chose it
  long long surroundings_voxels = 0;
};
WindowChoice choose_window(const geometry::ImageGeometry& ct, const std::vector<float>& hu,
                           const geometry::LabelVolume& organ, double shell_mm = 10.0);

/// One CT plane through the organ, cropped around it, with outlines on it.
struct SliceView {
  std::string title;          ///< e.g. "axial, z = 1.2 mm"
  int width = 0, height = 0;  ///< pixels
  double pixel_w_mm = 1, pixel_h_mm = 1;
  /// One image per window of ct_windows(): width x height, row-major, top row first.
  std::vector<std::vector<std::uint8_t>> gray;
  std::vector<std::vector<Eigen::Vector2d>> planning, fitted;  ///< closed polylines, mm
  /// The uncertainty at each vertex of `fitted` (empty: not given).
  std::vector<std::vector<double>> fitted_sigma_mm;
  std::vector<ViewPoint> points;
  std::string left, right, top, bottom;  ///< patient directions at the edges (L, R, A, P, S, I)
};

enum class Plane { kAxial, kCoronal, kSagittal };

/// The plane through voxel `index` (k for axial, j for coronal, i for sagittal) of a CT,
/// cropped to `crop_lo`..`crop_hi` (voxel indices, inclusive), in every window of
/// ct_windows(); the masks' outlines traced on it (either may be null); the points within
/// `slab_mm` of the plane with their residuals.
SliceView slice_view(const geometry::ImageGeometry& ct, const std::vector<float>& hu, Plane plane,
                     int index, const std::array<int, 3>& crop_lo,
                     const std::array<int, 3>& crop_hi, const geometry::LabelVolume* planning,
                     const geometry::LabelVolume* fitted,
                     const std::vector<Eigen::Vector3d>& points_mm,
                     const std::vector<double>& residuals_mm, double slab_mm,
                     const std::function<double(const Eigen::Vector3d&)>& sigma_mm = {});

struct ReportInput {
  nlohmann::json run;                    ///< run.json as written
  std::string scene_yaml;                ///< resolved.yaml
  std::string history_csv;               ///< history.csv (empty without a fit)
  std::vector<SliceView> axial;          ///< every axial slice through the organ, inferior first
  int axial_shown = 0;                   ///< the one shown first (the organ's centre)
  std::vector<SliceView> views;          ///< further planes (the central coronal and sagittal)
  WindowChoice window;                   ///< the window shown first
  std::vector<float> surface_vertex_mm;  ///< fitted surface, x y z per vertex
  std::vector<int> surface_triangles;    ///< three indices per triangle
  std::vector<float> surface_sigma_mm;   ///< the uncertainty per vertex (empty: none)
  double sigma_scale_mm = 0;  ///< the colour scale's top (red): sigma far from every point
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
