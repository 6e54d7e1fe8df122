#include "organfit/pipeline/export_stage.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <new>

#include "organfit/dicom/registration_writer.h"
#include "organfit/dicom/rtstruct_writer.h"
#include "organfit/geometry/grid_edges.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/geometry/slice_contours.h"
#include "organfit/geometry/topology.h"
#include "organfit/itkbridge/itk_images.h"
#include "organfit/meshing/surface.h"
#include "organfit/support/error.h"
#include "organfit/support/progress.h"

namespace organfit::pipeline {

void PendingExport::commit() {
  Progress progress("export: writing", static_cast<long long>(writes_.size()));
  long long written = 0;
  for (auto& write : writes_) {
    write(summary);
    progress.update(++written);
  }
  writes_.clear();
}

namespace {

/// Characters of UTF-8 text (bytes that do not continue a character).
int utf8_characters(const std::string& text) {
  return static_cast<int>(std::count_if(text.begin(), text.end(), [](char c) {
    return (static_cast<unsigned char>(c) & 0xC0) != 0x80;
  }));
}

}  // namespace

std::string fitted_roi_name(const std::string& organ_name) {
  const std::string suffix = "_fit";
  std::string organ = organ_name;
  while (utf8_characters(organ) > kRoiNameCharacters - static_cast<int>(suffix.size())) {
    // The last character: its continuation bytes, then the byte that starts it.
    while (!organ.empty() && (static_cast<unsigned char>(organ.back()) & 0xC0) == 0x80)
      organ.pop_back();
    if (!organ.empty()) organ.pop_back();
  }
  return organ + suffix;
}

std::string roi_name_problem(const std::string& name) {
  if (utf8_characters(name) > kRoiNameCharacters)
    return fmt::format("a ROI Name is at most {} characters (DICOM's LO); this one has {}",
                       kRoiNameCharacters, utf8_characters(name));
  if (name.find('\\') != std::string::npos)
    return "a ROI Name holds no backslash (DICOM's separator of values)";
  if (std::any_of(name.begin(), name.end(),
                  [](char c) { return static_cast<unsigned char>(c) < 0x20 || c == 0x7f; }))
    return "a ROI Name holds no control characters";
  return "";
}

namespace {
/// An RT ROI Interpreted Type as read, if it is a DICOM code string (A-Z, 0-9, space,
/// underscore; at most 16 characters), else ORGAN.
std::string type_or_organ(const std::string& type) {
  const bool code_string =
      !type.empty() && type.size() <= 16 && std::all_of(type.begin(), type.end(), [](char ch) {
        return (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') || ch == ' ' || ch == '_';
      });
  return code_string ? type : "ORGAN";
}
}  // namespace

dicom::StructureSet read_rois_to_copy(const std::filesystem::path& file,
                                      const dicom::CtSeries& ct) {
  dicom::StructureSet set = dicom::read_rtstruct(file);
  for (const auto& roi : set.rois)
    dicom::check_structure_set_matches_ct(set, roi, ct, file.string());
  return set;
}

namespace {
nlohmann::json to_json(const geometry::Topology& t) {
  return {{"components", t.components},
          {"cavities", t.cavities},
          {"single_voxel_components", t.single_voxel_components},
          {"single_voxel_cavities", t.single_voxel_cavities}};
}

/// The planning organ on the export's grid, measured once for the repair and the checks.
struct PlanningOnGrid {
  geometry::LabelVolume mask;
  geometry::Topology topology;
  explicit PlanningOnGrid(geometry::LabelVolume m)
      : mask(std::move(m)), topology(geometry::topology_of(mask)) {}
  /// A one-pixel speck of `organ` on this grid is the planning organ's own when the
  /// planning organ has a speck of the same kind at its pre-image (the nearest voxel).
  geometry::SpeckExplained explains(const fitting::EmbeddedBody& organ) const {
    return [this, &organ](int i, int j, int k, bool island) {
      const Eigen::Vector3d q = mask.geometry.index_to_physical(Eigen::Vector3d(i, j, k));
      const Eigen::Vector3d p = mask.geometry.physical_to_index(organ.pull_back(q));
      return geometry::is_slice_speck(mask, static_cast<int>(std::lround(p.x())),
                                      static_cast<int>(std::lround(p.y())),
                                      static_cast<int>(std::lround(p.z())), island);
    };
  }
};

/// Copies of the export's grid, moved by parts of a voxel, that the exported organ's volume
/// is counted on where it differs from the expected by more than 0.5%: 16, whose mean's
/// standard error is a quarter of the grid's spread (0.03 s on a prostate, 1.1 s on a
/// 1.5 L liver, which needs them rarely: its spread is 0.1% of its volume).
constexpr int kGridShifts = 16;

/// The voxels of `body` (label 1) whose pre-image through the organ's deformation lies
/// beyond the box of `field_of_view` (half a voxel past its outer voxels' centres): tissue
/// that lay beyond the planning CT's field of view; by the face it lay beyond (-i, +i, -j,
/// +j, -k, +k) in `by_face` when given.
long long voxels_from_beyond(const fitting::EmbeddedBody& organ, const geometry::LabelVolume& body,
                             const geometry::ImageGeometry& field_of_view,
                             std::array<long long, 6>* by_face) {
  const geometry::ImageGeometry& g = body.geometry;
  long long beyond = 0;
  long long faces[6] = {0, 0, 0, 0, 0, 0};
#pragma omp parallel for collapse(2) schedule(static) reduction(+ : beyond) reduction(+ : faces[:6])
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        if (body.at(i, j, k) != 1) continue;
        const Eigen::Vector3d p = field_of_view.physical_to_index(
            organ.pull_back(g.index_to_physical(Eigen::Vector3d(i, j, k))));
        for (int d = 0; d < 3; ++d) {
          const int face = p[d] < -0.5                          ? 2 * d
                           : p[d] > field_of_view.size[d] - 0.5 ? 2 * d + 1
                                                                : -1;
          if (face < 0) continue;
          ++beyond, ++faces[face];
          break;
        }
      }
  if (by_face)
    for (int f = 0; f < 6; ++f)
      (*by_face)[static_cast<size_t>(f)] = faces[f];
  return beyond;
}

/// The checks of the exported organ (after `repair`) against the planning organ on the
/// same grid.
void check_organ(const fitting::EmbeddedBody& organ, const geometry::LabelVolume& exported,
                 const PlanningOnGrid& planned,
                 const std::vector<geometry::SliceContour>& exported_contours,
                 const geometry::TopologyRepair& repair, PendingExport& out) {
  nlohmann::json checks;
  checks["sampling_repaired"] = {{"slice_islands_removed", repair.slice_islands_removed},
                                 {"slice_holes_filled", repair.slice_holes_filled},
                                 {"components_removed", repair.components_removed},
                                 {"cavities_filled", repair.cavities_filled},
                                 {"voxels", repair.voxels_changed}};
  const geometry::LabelVolume& planning = planned.mask;
  const geometry::Topology& before = planned.topology;
  const geometry::Topology after = geometry::topology_of(exported);
  checks["topology_planning"] = to_json(before);
  checks["topology_exported"] = to_json(after);
  checks["topology_kept"] = before == after;
  if (!(before == after))
    out.warnings.push_back(fmt::format(
        "export: the exported organ has {} component(s) ({} of one voxel) and {} cavity(ies) "
        "({} of one voxel); the planning organ {} and {}",
        after.components, after.single_voxel_components, after.cavities,
        after.single_voxel_cavities, before.components, before.cavities));
  // Volume: the planning organ's voxels times the deformation's volume change, against
  // the exported voxels, within 0.5%. Where they differ by more, the difference may be the
  // grid's: the same organ counted on copies of the grid moved by parts of a voxel varies
  // by a slice's worth at each end between thick slices (the default scene's prostate from
  // -1.2% to +2.2% over 64 copies; 2.5 mm slices), and the CT's own grid
  // is one of those phases. Their mean, the exported count among them, is the organ's
  // volume without the grid's phase; it is what must then be within 0.5%, and 3 standard
  // errors of the mean (docs/decisions.md, "The exported volume against the grid's phase").
  const double planning_cm3 = planning.volume_mm3(1) / 1000.0;
  const double exported_cm3 = exported.volume_mm3(1) / 1000.0;
  const double ratio = organ.volume_ratio(exported);
  const std::array<long long, 6> on_faces = geometry::voxels_on_faces(exported),
                                 planning_on_faces = geometry::voxels_on_faces(planning);
  // Tissue from beyond the CT's field of view: where the planning organ reaches a face of
  // the grid it goes on beyond it (geometry/signed_distance.h: as deep beyond the face as
  // it is on it), and a fit that draws the organ in brings some of that onto the grid,
  // which the planning organ's count never held. Today's organ from within the field of
  // view is what the planning organ moved by the fit is compared with, on every grid.
  const geometry::ImageGeometry& grid = exported.geometry;
  const bool planning_at_edge = std::any_of(planning_on_faces.begin(), planning_on_faces.end(),
                                            [](long long n) { return n > 0; });
  std::array<long long, 6> entered_by_face{};
  const long long entered =
      planning_at_edge ? voxels_from_beyond(organ, exported, grid, &entered_by_face) : 0;
  const double voxel_cm3 = grid.spacing_mm.prod() / 1000.0;
  const double entered_cm3 = static_cast<double>(entered) * voxel_cm3;
  const double expected_cm3 = planning_cm3 * ratio + entered_cm3;
  double tolerance_cm3 = 0.005 * expected_cm3;
  double compared_cm3 = exported_cm3;
  checks["planning_volume_on_ct_grid_cm3"] = planning_cm3;
  checks["deformation_volume_change_pct"] = 100 * (ratio - 1);
  checks["from_beyond_ct_cm3"] = entered_cm3;
  checks["expected_volume_on_ct_grid_cm3"] = expected_cm3;
  checks["volume_difference_cm3"] = exported_cm3 - expected_cm3;
  checks["volume_on_shifted_grids"] = nullptr;
  if (entered > 0) {
    std::string from;
    for (int face = 0; face < 6; ++face)
      if (entered_by_face[static_cast<size_t>(face)] > 0)
        from += fmt::format("{}{} {:.3f} cm3", from.empty() ? "" : ", ",
                            geometry::side_of_face(grid, face),
                            entered_by_face[static_cast<size_t>(face)] * voxel_cm3);
    out.warnings.push_back(fmt::format(
        "export: {:.3f} cm3 of the exported organ ({:.2f}%) came onto the CT's grid from "
        "beyond its field of view ({}), where the planning CT does not show the organ: its "
        "shape there is extrapolated from the CT's last plane",
        entered_cm3, 100 * entered_cm3 / std::max(exported_cm3, 1e-12), from));
  }
  // The organ on a face of the CT's grid, more than the planning organ was: it goes on
  // beyond the CT's field of view, which cannot hold it, and what is written is cut there.
  nlohmann::json cut = nlohmann::json::array();
  std::string sides;
  for (int face = 0; face < 6; ++face) {
    const auto f = static_cast<size_t>(face);
    if (on_faces[f] <= planning_on_faces[f]) continue;
    const char* side = geometry::side_of_face(exported.geometry, face);
    cut.push_back(
        {{"side", side}, {"voxels", on_faces[f]}, {"planning_voxels", planning_on_faces[f]}});
    sides += fmt::format("{}{} ({} voxels on the CT's last plane there, the planning organ {})",
                         sides.empty() ? "" : "; ", side, on_faces[f], planning_on_faces[f]);
  }
  checks["cut_by_ct_edge"] = cut;
  // A cut organ is warned about as such below: no copies counted for it.
  if (std::abs(exported_cm3 - expected_cm3) > tolerance_cm3 && cut.empty()) {
    // Each copy's organ from within the field of view (the CT's grid's box), in cm3.
    std::vector<double> volumes = organ.on_shifted_grids(
        exported.geometry, kGridShifts, [&](const geometry::LabelVolume& body) {
          const long long beyond =
              planning_at_edge ? voxels_from_beyond(organ, body, grid, nullptr) : 0;
          return (body.volume_mm3(1) - static_cast<double>(beyond) * grid.spacing_mm.prod()) /
                 1000.0;
        });
    volumes.push_back(exported_cm3 - entered_cm3);
    const auto n = static_cast<double>(volumes.size());
    double mean = 0, square = 0;
    for (const double v : volumes)
      mean += v / n;
    for (const double v : volumes)
      square += (v - mean) * (v - mean);
    const double sd = std::sqrt(square / (n - 1));
    compared_cm3 = mean + entered_cm3;  // against expected_cm3, which holds entered_cm3
    tolerance_cm3 += 3 * sd / std::sqrt(n);
    checks["volume_on_shifted_grids"] = {
        {"grids", volumes.size()}, {"mean_cm3", mean}, {"sd_cm3", sd}};
  }
  checks["volume_tolerance_cm3"] = tolerance_cm3;
  checks["volume_kept"] = std::abs(compared_cm3 - expected_cm3) <= tolerance_cm3;
  if (!cut.empty())
    out.warnings.push_back(fmt::format(
        "export: the fitted organ reaches the planning CT's edge: {}. It goes on beyond the "
        "CT's field of view, and the organ on the CT's grid (structure set, label map) is cut "
        "there: {:.3f} cm3, where the planning organ moved by the fit would be {:.3f} cm3",
        sides, exported_cm3, expected_cm3));
  else if (!checks["volume_kept"].get<bool>())
    out.warnings.push_back(fmt::format(
        "export: the exported organ is {:.3f} cm3 on the CT grid and {:.3f} cm3 on average over "
        "it and {} copies of it moved by parts of a voxel; the planning organ moved by the fit "
        "would be {:.3f} cm3 (tolerance {:.3f} cm3)",
        exported_cm3, compared_cm3, kGridShifts, expected_cm3, tolerance_cm3));
  // Slices both organs cut whose contour count differs (a slice split in two, merged, or
  // with a hole or an island in it).
  const std::vector<geometry::ContourCountChange> changes =
      geometry::contour_count_changes(geometry::slice_contours(planning, 1), exported_contours);
  nlohmann::json differ = nlohmann::json::array();
  for (const geometry::ContourCountChange& c : changes)
    differ.push_back({{"slice", c.k}, {"planning", c.before}, {"exported", c.after}});
  checks["slices_with_another_contour_count"] = differ;
  // One-pixel islands and holes the planning organ does not have at their pre-images:
  // below what the grid resolves, so a defect of the export, never a change of shape (a
  // slice whose contours merge or split under a bend is; it is listed above, not warned
  // about). The repair leaves none; this checks that it did.
  nlohmann::json specks = nlohmann::json::array();
  std::string named;
  for (const geometry::SliceSpecks& s : geometry::slice_specks(exported, planned.explains(organ))) {
    specks.push_back({{"slice", s.k}, {"islands", s.islands}, {"holes", s.holes}});
    if (specks.size() <= 5)
      named += fmt::format("{}slice {} ({} island(s), {} hole(s))", named.empty() ? "" : ", ", s.k,
                           s.islands, s.holes);
  }
  checks["slices_with_one_pixel_specks"] = specks;
  if (!specks.empty())
    out.warnings.push_back(fmt::format(
        "export: {} slice(s) of the exported organ have one-pixel islands or holes the planning "
        "organ does not have where they came from: {}{}",
        specks.size(), named, specks.size() > 5 ? ", ..." : ""));
  // The deformation's volume ratio over the exported organ's voxels.
  double lo = 1e300, hi = -1e300;
  long long changed = 0, n = 0;
  const geometry::ImageGeometry& g = exported.geometry;
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j) {
      fitting::Deformation::CellCache cell;  // the row's voxels in order
      for (int i = 0; i < g.size[0]; ++i) {
        if (exported.at(i, j, k) != 1) continue;
        const double v =
            organ.deformation().volume_ratio(g.index_to_physical(Eigen::Vector3d(i, j, k)), cell);
        lo = std::min(lo, v), hi = std::max(hi, v), ++n;
        changed += std::abs(v - 1) > 0.01;
      }
    }
  checks["jacobian"] = {{"organ_min", lo},
                        {"organ_max", hi},
                        {"organ_share_changed_over_1pct", n > 0 ? 1.0 * changed / n : 0.0},
                        {"lattice_min", organ.deformation().min_volume_ratio()},
                        {"lattice_max", organ.deformation().max_volume_ratio()}};
  out.summary["checks"] = checks;
}

/// The CT's grid, or one of `spacing_mm` over its box (same origin and axes).
geometry::ImageGeometry field_grid(const geometry::ImageGeometry& ct, double spacing_mm) {
  if (!(spacing_mm > 0)) return ct;
  geometry::ImageGeometry g = ct;
  for (int d = 0; d < 3; ++d) {
    const double extent = (ct.size[static_cast<size_t>(d)] - 1) * ct.spacing_mm[d];
    g.size[static_cast<size_t>(d)] = static_cast<int>(std::floor(extent / spacing_mm + 1e-9)) + 1;
    g.spacing_mm[d] = spacing_mm;
  }
  return g;
}

/// The deformation on `grid`: v(q) = phi^-1(q) - q (3 floats per voxel), and, when
/// asked, det(grad phi) (one float per voxel).
void sample_deformation(const fitting::Deformation& phi, const geometry::ImageGeometry& grid,
                        std::vector<float>* field, std::vector<float>* jacobian) {
  const long long total = grid.voxel_count();
  if (field) field->assign(static_cast<size_t>(3 * total), 0.0f);
  if (jacobian) jacobian->assign(static_cast<size_t>(total), 1.0f);
#pragma omp parallel for collapse(2) schedule(static)
  for (int k = 0; k < grid.size[2]; ++k)
    for (int j = 0; j < grid.size[1]; ++j) {
      fitting::Deformation::CellCache cell;  // the row's voxels in order
      for (int i = 0; i < grid.size[0]; ++i) {
        const Eigen::Vector3d q = grid.index_to_physical(Eigen::Vector3d(i, j, k));
        const size_t v = static_cast<size_t>(grid.linear_index(i, j, k));
        if (field) {
          const Eigen::Vector3d d = phi.pull_back(q) - q;
          for (int a = 0; a < 3; ++a)
            (*field)[3 * v + static_cast<size_t>(a)] = static_cast<float>(d[a]);
        }
        if (jacobian) (*jacobian)[v] = static_cast<float>(phi.volume_ratio(q, cell));
      }
    }
}
}  // namespace

/// sigma(x) at every voxel centre: computed on a grid of l/4 over the points' box grown
/// by 5 l (sigma varies over l) and interpolated trilinearly; beyond that box, where no
/// point informs it (exp(-12.5) of the prior), its value far from every point where the
/// prior is widest (far_sd_mm: never narrower than the truth there).
std::vector<float> sigma_on_grid(const fitting::SurfaceUncertainty& u,
                                 const geometry::ImageGeometry& g) {
  const double far = u.far_sd_mm(), l = u.options().length_mm;
  geometry::Aabb box = u.points_box();
  box.min_mm.array() -= 5 * l, box.max_mm.array() += 5 * l;
  const geometry::ImageGeometry coarse = geometry::grid_covering(box, l / 4, 0);
  std::vector<double> values(static_cast<size_t>(coarse.voxel_count()));
#pragma omp parallel for schedule(dynamic)
  for (int k = 0; k < coarse.size[2]; ++k)
    for (int j = 0; j < coarse.size[1]; ++j)
      for (int i = 0; i < coarse.size[0]; ++i)
        values[static_cast<size_t>(coarse.linear_index(i, j, k))] =
            u.sd_mm(coarse.index_to_physical(Eigen::Vector3d(i, j, k)));
  std::vector<float> out(static_cast<size_t>(g.voxel_count()), static_cast<float>(far));
  const geometry::IndexRange range = geometry::index_range(g, box, 0);
#pragma omp parallel for schedule(dynamic)
  for (int k = range.lo[2]; k <= range.hi[2]; ++k)
    for (int j = range.lo[1]; j <= range.hi[1]; ++j)
      for (int i = range.lo[0]; i <= range.hi[0]; ++i) {
        const Eigen::Vector3d c =
            coarse.physical_to_index(g.index_to_physical(Eigen::Vector3d(i, j, k)));
        const Eigen::Vector3d base = c.array().floor();
        const bool inside =
            (base.array() >= 0).all() &&
            (base.array() + 1 < Eigen::Array3d(coarse.size[0], coarse.size[1], coarse.size[2]))
                .all();
        if (!inside) continue;  // the box's rim: the value far from every point
        double v = 0;
        geometry::for_each_trilinear_corner(c - base, [&](int di, int dj, int dk, double w) {
          v += w * values[static_cast<size_t>(coarse.linear_index(
                       static_cast<int>(base.x()) + di, static_cast<int>(base.y()) + dj,
                       static_cast<int>(base.z()) + dk))];
        });
        out[static_cast<size_t>(g.linear_index(i, j, k))] = static_cast<float>(v);
      }
  return out;
}

PendingExport prepare_export(const fitting::EmbeddedBody& organ, double rho,
                             const dicom::CtSeries* ct, const ExportRequest& r) {
  PendingExport out;
  out.summary = nlohmann::json::object();
  const bool on_ct = r.on_ct_grid(), fields = r.deformation_files();
  // The organ's level where the organ itself is written (not for its deformation alone).
  if (on_ct || !r.mesh.empty()) {
    const geometry::SignedDistance::VolumeLevels levels = organ.levels();
    out.summary["organ_level_mm"] = levels.level_mm;
    out.summary["organ_level_by_slice_phase_mm"] = levels.by_slice_phase_mm;
  }
  const bool vectors = !r.displacement_field.empty() || !r.registration.empty();
  Progress progress("export", (on_ct ? 3 : 0) + (fields ? 1 : 0) + (r.mesh.empty() ? 0 : 1));
  int done = 0;
  if (r.needs_ct() && !ct)
    throw InputError(
        "export: an RT Structure Set, label map, deformation field or uncertainty map needs the "
        "planning CT");
  // What a REG object's Vector Grid Data holds is said before the field is sampled (a 0.25
  // mm grid over a CT's box is hundreds of millions of points, gigabytes of floats), not by
  // the writer after it.
  if (fields && !r.registration.empty()) {
    const geometry::ImageGeometry grid = field_grid(ct->geometry, r.field_spacing_mm);
    if (grid.voxel_count() > dicom::kMostRegistrationGridPoints)
      throw InputError(
          fmt::format("{}: the field's grid of {} x {} x {} points ({:g} mm) is more than a DICOM "
                      "registration's Vector Grid Data holds ({} points, 4 GB): choose a coarser "
                      "export.field_spacing_mm (organfit export --field-spacing)",
                      r.registration.string(), grid.size[0], grid.size[1], grid.size[2],
                      grid.spacing_mm.minCoeff(), dicom::kMostRegistrationGridPoints));
  }
  if (on_ct) {
    auto mask = std::make_shared<geometry::LabelVolume>(organ.on_grid(ct->geometry));
    progress.update(++done, "the organ on the planning CT's grid");
    out.organ_on_ct = mask;
    if (mask->count(1) == 0) {  // the points, most likely, in other coordinates
      const geometry::Aabb now = organ.bounds(), then = organ.reference().geometry.bounds_mm();
      throw InputError(fmt::format(
          "export: the fitted organ lies wholly outside the planning CT's field of view, {:.0f} "
          "mm from where the planning organ was: are the points in the planning CT's patient "
          "coordinates?",
          (0.5 * (now.min_mm + now.max_mm) - 0.5 * (then.min_mm + then.max_mm)).norm()));
    }
    // The planning organ on the same grid; phi is one-to-one (a folding one is never
    // exported), so the sampled organ's extra pieces, cavities and one-pixel specks are
    // the grid's, not the fit's: undone before anything is written.
    const fitting::EmbeddedBody planning_body(organ.shared_reference(), organ.shared_distance(),
                                              std::make_shared<const fitting::Deformation>());
    const PlanningOnGrid planning(planning_body.on_grid(ct->geometry));
    const geometry::TopologyRepair repair =
        geometry::restore_topology(*mask, planning.topology, planning.explains(organ));
    auto contours = geometry::slice_contours(*mask, 1);
    progress.update(++done, "its contours");
    out.summary["roi"] = r.roi_name;
    out.summary["contours"] = contours.size();
    out.summary["volume_on_ct_grid_cm3"] = mask->volume_mm3(1) / 1000.0;
    check_organ(organ, *mask, planning, contours, repair, out);
    progress.update(++done, "its checks against the planning organ");
    if (!r.rtstruct.empty()) {
      auto rois = std::make_shared<std::vector<dicom::RtstructRoi>>();
      rois->push_back({r.roi_name, r.roi_colour, std::move(contours), type_or_organ(r.roi_type)});
      out.summary["roi_colour"] = r.roi_colour;
      out.summary["roi_interpreted_type"] = rois->back().interpreted_type;
      nlohmann::json copied = nlohmann::json::array();
      if (r.copy_rois_from) {
        for (const auto& roi : r.copy_rois_from->rois) {
          if (roi.name == r.skip_roi) continue;  // the fitted ROI replaces its source
          if (roi.name == r.roi_name) {  // two ROIs of one name: a planning system picks one
            out.warnings.push_back(fmt::format(
                "export: ROI '{}' not copied: the fitted ROI has its name (export.roi_name, "
                "or export --roi-name, names it otherwise)",
                roi.name));
            continue;
          }
          dicom::RoiOnSlices placed = dicom::roi_on_slices(roi, *ct);
          if (placed.skipped > 0)
            out.warnings.push_back(fmt::format(
                "export: ROI '{}': {} contour(s) not copied (not CLOSED_PLANAR or on no "
                "slice of the CT)",
                roi.name, placed.skipped));
          if (placed.contours.empty()) continue;
          dicom::RtstructRoi copy{roi.name, roi.colour, std::move(placed.contours),
                                  type_or_organ(roi.interpreted_type)};
          copy.generation_algorithm = "";  // copied: not ours to call AUTOMATIC
          rois->push_back(std::move(copy));
          copied.push_back(roi.name);
        }
      }
      out.summary["copied_rois"] = copied;
      out.files.push_back(r.rtstruct.filename().string());
      const std::filesystem::path file = r.rtstruct;
      dicom::RtstructWriteOptions options;
      options.fixed_uids_and_dates = r.fixed_uids;
      out.writes_.push_back([file, rois, ct, options](nlohmann::json&) {
        dicom::write_rtstruct(file, *ct, *rois, options);
      });
    }
    if (!r.labels.empty()) {
      out.files.push_back(r.labels.filename().string());
      const std::filesystem::path file = r.labels;
      out.writes_.push_back(
          [file, mask](nlohmann::json&) { itkbridge::write_label_volume(file, *mask); });
    }
  }
  if (!r.uncertainty.empty()) {
    if (!r.sigma) throw InputError(r.uncertainty.string() + ": there is no fit to say it of");
    auto sigma = std::make_shared<std::vector<float>>(sigma_on_grid(*r.sigma, ct->geometry));
    out.files.push_back(r.uncertainty.filename().string());
    const std::filesystem::path file = r.uncertainty;
    out.summary["uncertainty"] = {{"file", file.filename().string()},
                                  {"maps", "each voxel to sigma (mm) of the surface there"}};
    const geometry::ImageGeometry grid = ct->geometry;
    out.writes_.push_back([file, sigma, grid](nlohmann::json&) {
      itkbridge::write_float_volume(file, grid, *sigma);
    });
  }
  if (fields) {
    const geometry::ImageGeometry grid = field_grid(ct->geometry, r.field_spacing_mm);
    auto field = std::make_shared<std::vector<float>>();
    auto jacobian = std::make_shared<std::vector<float>>();
    try {
      sample_deformation(organ.deformation(), grid, vectors ? field.get() : nullptr,
                         r.jacobian.empty() ? nullptr : jacobian.get());
    } catch (const std::bad_alloc&) {  // the grid, not the run, is what to change
      field.reset(), jacobian.reset();
      const double floats = (vectors ? 3.0 : 0.0) + (r.jacobian.empty() ? 0.0 : 1.0);
      throw InputError(fmt::format(
          "export: the deformation's grid of {} x {} x {} points ({:g} mm; {:.1f} GB of floats) "
          "is more than this run's memory holds: choose a coarser export.field_spacing_mm "
          "(organfit export --field-spacing)",
          grid.size[0], grid.size[1], grid.size[2], grid.spacing_mm.minCoeff(),
          4.0 * floats * static_cast<double>(grid.voxel_count()) / 1e9));
    }
    progress.update(++done, "the deformation on its grid");
    out.summary["field_grid"] = {
        {"size", {grid.size[0], grid.size[1], grid.size[2]}},
        {"spacing_mm", {grid.spacing_mm.x(), grid.spacing_mm.y(), grid.spacing_mm.z()}}};
    if (!r.displacement_field.empty()) {
      out.files.push_back(r.displacement_field.filename().string());
      const std::filesystem::path file = r.displacement_field;
      out.summary["displacement_field"] = {{"file", file.filename().string()},
                                           {"maps", "today's point q to phi^-1(q) - q (mm)"}};
      out.writes_.push_back([file, field, grid](nlohmann::json&) {
        itkbridge::write_vector_volume(file, grid, *field);
      });
    }
    if (!r.registration.empty()) {
      out.files.push_back(r.registration.filename().string());
      const std::filesystem::path file = r.registration;
      out.summary["registration"] = {{"file", file.filename().string()},
                                     {"grid", {grid.size[0], grid.size[1], grid.size[2]}}};
      dicom::RegistrationWriteOptions options;
      options.fixed_uids_and_dates = r.fixed_uids;
      // The field's last use (written after the displacement field): moved into the writer,
      // which lets it go once GDCM has copied it.
      out.writes_.push_back([file, field, grid, ct, options](nlohmann::json&) {
        dicom::write_deformable_registration(file, *ct, grid, std::move(*field), options);
      });
    }
    if (!r.jacobian.empty()) {
      out.files.push_back(r.jacobian.filename().string());
      const std::filesystem::path file = r.jacobian;
      out.summary["jacobian_file"] = file.filename().string();
      out.writes_.push_back([file, jacobian, grid](nlohmann::json&) {
        itkbridge::write_float_volume(file, grid, *jacobian);
      });
    }
  }
  if (!r.mesh.empty()) {
    // The organ on a grid of rho, independent of the CT: windowed-sinc smoothing removes
    // the voxel steps.
    const geometry::ImageGeometry fine = geometry::grid_covering(organ.bounds(), rho, rho);
    auto body = std::make_shared<geometry::LabelVolume>(organ.on_grid(fine));
    progress.update(++done, "the organ on the mesh's grid");
    out.organ_on_mesh_grid = body;
    out.summary["model_volume_mm3"] = body->volume_mm3(1);
    out.files.push_back(r.mesh.filename().string());
    const std::filesystem::path file = r.mesh;
    const auto sigma = r.sigma;
    out.writes_.push_back([file, body, sigma](nlohmann::json& summary) {
      const meshing::SurfaceReport m =
          sigma ? meshing::write_surface(
                      *body, file, "sigma_mm",
                      [&sigma](const Eigen::Vector3d& x) { return sigma->sd_mm(x); })
                : meshing::write_surface(*body, file);
      summary["mesh"] = {{"file", file.filename().string()},
                         {"triangles", m.triangles},
                         {"boundary_edges", m.boundary_edges},
                         {"non_manifold_edges", m.non_manifold_edges},
                         {"outward", m.outward},
                         {"enclosed_volume_mm3", m.enclosed_volume_mm3},
                         {"area_mm2", m.area_mm2}};
    });
  }
  return out;
}

ExportRequest export_request_from(const config::Scene& scene, const std::filesystem::path& staging,
                                  const std::string& organ_name, const OrganLook& look) {
  ExportRequest request;
  auto in_out = [&](const char* key) {
    const std::string& file = scene.text("export", key);
    return file.empty() ? std::filesystem::path() : staging / file;
  };
  request.rtstruct = in_out("rtstruct");
  request.labels = in_out("labels");
  request.mesh = in_out("mesh");
  request.displacement_field = in_out("displacement_field");
  request.jacobian = in_out("jacobian");
  request.uncertainty = in_out("uncertainty");
  request.registration = in_out("registration");
  request.field_spacing_mm = scene.number("export", "field_spacing_mm");
  request.roi_name = scene.text("export", "roi_name");
  request.fixed_uids = scene.flag("export", "fixed_uids");
  if (request.roi_name.empty()) request.roi_name = fitted_roi_name(organ_name);
  request.roi_colour = look.colour;
  request.roi_type = look.interpreted_type;
  if (const Eigen::Vector3d c = scene.vec3("export", "roi_color");
      c != Eigen::Vector3d(-1, -1, -1)) {
    for (int i = 0; i < 3; ++i)
      request.roi_colour[static_cast<size_t>(i)] = static_cast<int>(std::lround(c[i]));
  }
  return request;
}

}  // namespace organfit::pipeline
