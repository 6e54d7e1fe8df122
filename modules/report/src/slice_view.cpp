#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "organfit/geometry/mask_ops.h"
#include "organfit/geometry/slice_contours.h"
#include "organfit/report/report.h"

namespace organfit::report {
namespace {

/// The patient side an axis points to (DICOM LPS): +x left, +y posterior, +z superior.
std::string side(const Eigen::Vector3d& axis) {
  Eigen::Index d = 0;
  axis.cwiseAbs().maxCoeff(&d);
  static const char* plus[3] = {"L", "P", "S"};
  static const char* minus[3] = {"R", "A", "I"};
  return axis[d] >= 0 ? plus[d] : minus[d];
}

}  // namespace

const std::vector<CtWindow>& ct_windows() {
  static const std::vector<CtWindow> windows = {
      {"soft tissue", "soft", 40, 400}, {"lung", "lung", -600, 1500}, {"bone", "bone", 400, 1800}};
  return windows;
}

WindowChoice choose_window(const geometry::ImageGeometry& g, const std::vector<float>& hu,
                           const geometry::LabelVolume& organ, double shell_mm) {
  WindowChoice choice;
  // The organ's box grown by the shell: the distance transform runs on it alone.
  const geometry::IndexRange r = organ.range(1);
  if (r.empty()) return choice;
  std::array<int, 3> lo = r.lo, hi = r.hi;
  geometry::ImageGeometry box = g;
  for (int d = 0; d < 3; ++d) {
    const int margin = static_cast<int>(std::ceil(shell_mm / g.spacing_mm[d]));
    lo[d] = std::max(0, lo[d] - margin), hi[d] = std::min(g.size[d] - 1, hi[d] + margin);
    box.size[d] = hi[d] - lo[d] + 1;
  }
  std::vector<std::uint8_t> feature(static_cast<size_t>(box.size[0]) * box.size[1] * box.size[2]);
  auto local = [&](int i, int j, int k) {
    return (static_cast<size_t>(k - lo[2]) * box.size[1] + (j - lo[1])) * box.size[0] + (i - lo[0]);
  };
  for (int k = lo[2]; k <= hi[2]; ++k)
    for (int j = lo[1]; j <= hi[1]; ++j)
      for (int i = lo[0]; i <= hi[0]; ++i)
        feature[local(i, j, k)] = organ.at(i, j, k) == 1;
  const auto d2 = geometry::squared_distance_transform(feature, box);
  std::vector<float> shell;
  for (int k = lo[2]; k <= hi[2]; ++k)
    for (int j = lo[1]; j <= hi[1]; ++j)
      for (int i = lo[0]; i <= hi[0]; ++i) {
        const double d = d2[local(i, j, k)];
        if (d > 0 && d <= shell_mm * shell_mm)
          shell.push_back(hu[static_cast<size_t>(g.linear_index(i, j, k))]);
      }
  if (shell.empty()) return choice;
  std::nth_element(shell.begin(), shell.begin() + static_cast<long>(shell.size() / 2), shell.end());
  choice.surroundings_median_hu = shell[shell.size() / 2];
  choice.surroundings_voxels = static_cast<long long>(shell.size());
  const auto& windows = ct_windows();
  for (size_t w = 1; w < windows.size(); ++w)
    if (std::abs(windows[w].level_hu - choice.surroundings_median_hu) <
        std::abs(windows[static_cast<size_t>(choice.window)].level_hu -
                 choice.surroundings_median_hu))
      choice.window = static_cast<int>(w);
  return choice;
}

SliceView slice_view(const geometry::ImageGeometry& g, const std::vector<float>& hu, Plane plane,
                     int index, const std::array<int, 3>& lo, const std::array<int, 3>& hi,
                     const geometry::LabelVolume* planning, const geometry::LabelVolume* fitted,
                     const std::vector<Eigen::Vector3d>& points_mm,
                     const std::vector<double>& residuals_mm, double slab_mm,
                     const std::function<double(const Eigen::Vector3d&)>& sigma_mm) {
  // The view's columns run along axis `ca` (increasing), its rows down along axis `ra`
  // (increasing for axial, decreasing k for the others: superior at the top).
  const int normal = plane == Plane::kAxial ? 2 : plane == Plane::kCoronal ? 1 : 0;
  const int ca = plane == Plane::kSagittal ? 1 : 0;
  const int ra = plane == Plane::kAxial ? 1 : 2;
  const bool rows_down = plane == Plane::kAxial;
  if (index < 0 || index >= g.size[normal])
    throw std::invalid_argument("slice_view: plane outside the CT");
  SliceView v;
  v.width = hi[ca] - lo[ca] + 1;
  v.height = hi[ra] - lo[ra] + 1;
  if (v.width <= 0 || v.height <= 0) throw std::invalid_argument("slice_view: empty crop");
  v.pixel_w_mm = g.spacing_mm[ca];
  v.pixel_h_mm = g.spacing_mm[ra];
  const Eigen::Vector3d col_axis = g.direction.col(ca);
  const Eigen::Vector3d down_axis =
      rows_down ? Eigen::Vector3d(g.direction.col(ra)) : Eigen::Vector3d(-g.direction.col(ra));
  v.left = side(-col_axis), v.right = side(col_axis), v.top = side(-down_axis),
  v.bottom = side(down_axis);
  static const char* names[3] = {"sagittal", "coronal", "axial"};
  static const char* coords[3] = {"x", "y", "z"};
  Eigen::Vector3d at = Eigen::Vector3d::Zero();
  at[normal] = index;
  v.title = fmt::format("{}, {} = {:.1f} mm", names[normal], coords[normal],
                        g.index_to_physical(at)[normal]);

  auto voxel = [&](int c, int r) {
    std::array<int, 3> ijk{};
    ijk[normal] = index;
    ijk[ca] = lo[ca] + c;
    ijk[ra] = rows_down ? lo[ra] + r : hi[ra] - r;
    return ijk;
  };
  const auto& windows = ct_windows();
  v.gray.assign(windows.size(), std::vector<std::uint8_t>(static_cast<size_t>(v.width) * v.height));
  geometry::ImageGeometry flat;  // the view as a one-slice grid, in mm from its top-left corner
  flat.size = {v.width, v.height, 1};
  flat.spacing_mm = Eigen::Vector3d(v.pixel_w_mm, v.pixel_h_mm, 1);
  flat.origin_mm = Eigen::Vector3d(0.5 * v.pixel_w_mm, 0.5 * v.pixel_h_mm, 0);
  geometry::LabelVolume plan2d(flat), fit2d(flat);
  for (int r = 0; r < v.height; ++r)
    for (int c = 0; c < v.width; ++c) {
      const auto ijk = voxel(c, r);
      const double value = hu[static_cast<size_t>(g.linear_index(ijk[0], ijk[1], ijk[2]))];
      for (size_t w = 0; w < windows.size(); ++w)
        v.gray[w][static_cast<size_t>(r) * v.width + c] = static_cast<std::uint8_t>(std::clamp(
            (value - (windows[w].level_hu - windows[w].width_hu / 2)) / windows[w].width_hu * 255.0,
            0.0, 255.0));
      if (planning) plan2d.at(c, r, 0) = planning->at(ijk[0], ijk[1], ijk[2]) == 1;
      if (fitted) fit2d.at(c, r, 0) = fitted->at(ijk[0], ijk[1], ijk[2]) == 1;
    }
  auto outlines = [](const geometry::LabelVolume& m) {
    std::vector<std::vector<Eigen::Vector2d>> out;
    for (const auto& c : geometry::slice_contours(m, 1)) {
      std::vector<Eigen::Vector2d> line;
      for (const auto& p : c.points_mm)
        line.emplace_back(p.x(), p.y());
      out.push_back(std::move(line));
    }
    return out;
  };
  if (planning) v.planning = outlines(plan2d);
  if (fitted) v.fitted = outlines(fit2d);
  if (sigma_mm)
    for (const auto& line : v.fitted) {
      // Back from the view's mm to the CT's voxel index, then to patient mm.
      std::vector<double> values;
      for (const auto& p : line) {
        const double c = p.x() / v.pixel_w_mm - 0.5, r = p.y() / v.pixel_h_mm - 0.5;
        Eigen::Vector3d ijk;
        ijk[normal] = index;
        ijk[ca] = lo[ca] + c;
        ijk[ra] = rows_down ? lo[ra] + r : hi[ra] - r;
        values.push_back(sigma_mm(g.index_to_physical(ijk)));
      }
      v.fitted_sigma_mm.push_back(std::move(values));
    }
  for (size_t p = 0; p < points_mm.size(); ++p) {
    const Eigen::Vector3d idx = g.physical_to_index(points_mm[p]);
    if (std::abs(idx[normal] - index) * g.spacing_mm[normal] > slab_mm) continue;
    const double c = idx[ca] - lo[ca], r = rows_down ? idx[ra] - lo[ra] : hi[ra] - idx[ra];
    if (c < -0.5 || r < -0.5 || c > v.width - 0.5 || r > v.height - 0.5) continue;
    v.points.push_back({(c + 0.5) * v.pixel_w_mm, (r + 0.5) * v.pixel_h_mm,
                        p < residuals_mm.size() ? residuals_mm[p] : 0.0});
  }
  return v;
}

}  // namespace organfit::report
