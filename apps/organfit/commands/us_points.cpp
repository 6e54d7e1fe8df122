// `organfit us-points`: boundary points of an ultrasound input, in CT coordinates, as CSV.
//   a 3D volume (.mha, .mhd, .nrrd, .nii[.gz])          -> rays in 3D from the centre
//   a tracked sweep (sequence metafile with Seq_Frame fields; poses in it or in --tracker)
//   DICOM ultrasound (.dcm; its pixel size from its ultrasound region, or --pixel-mm)
//                                                        -> rays in each frame's plane
// The region of interest is a ball (--centre, --radius) in the output coordinates; by
// default the middle of the image (half depth) and a third of its smaller extent.
#include <fmt/format.h>

#include <CLI/CLI.hpp>
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "commands.h"
#include "organfit/dicom/ct_series.h"
#include "organfit/dicom/us_image.h"
#include "organfit/itkbridge/itk_images.h"
#include "organfit/pipeline/points_file.h"
#include "organfit/support/atomic_file.h"
#include "organfit/support/error.h"
#include "organfit/support/output_folder.h"
#include "organfit/support/resources.h"
#include "organfit/ultrasound/boundary_points.h"
#include "organfit/ultrasound/sequence_metafile.h"

namespace fs = std::filesystem;

namespace organfit::app {
namespace {

struct UsPointsCommand {
  std::filesystem::path input, tracker, out;
  std::filesystem::path ct;          ///< the CT the registration maps into: declared in the CSV
  std::vector<double> calibration;   ///< 16 numbers, row-major: image (mm) -> probe
  std::vector<double> registration;  ///< 16 numbers, row-major: tracker/volume -> CT (rigid)
  std::string transform;             ///< tracked transform name (default: the file's own)
  double pixel_mm = 0;               ///< DICOM without a calibrated region
  std::vector<double> centre_mm;     ///< x,y,z
  double radius_mm = 0;              ///< 0: a third of the image's smaller extent
  int count = 87, rays = 2000;
};

Eigen::Matrix4d matrix_of(const std::vector<double>& v, const char* option) {
  if (v.empty()) return Eigen::Matrix4d::Identity();
  if (v.size() != 16)
    throw InputError(
        fmt::format("us-points: {} takes 16 numbers (a 4x4 matrix, row by row)", option));
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c)
      m(r, c) = v[static_cast<size_t>(4 * r + c)];
  if (!m.allFinite())
    throw InputError(fmt::format("us-points: {} has a non-finite number", option));
  return m;
}

bool has_sequence_fields(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::string line;
  for (int n = 0; n < 400 && std::getline(in, line); ++n) {
    if (line.rfind("Seq_Frame", 0) == 0) return true;
    if (line.rfind("ElementDataFile", 0) == 0) return false;
  }
  return false;
}

std::string lower_extension(const fs::path& p) {
  std::string name = p.filename().string();
  for (auto& c : name)
    c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return name;
}

bool ends_with(const std::string& s, const std::string& e) {
  return s.size() >= e.size() && s.compare(s.size() - e.size(), e.size(), e) == 0;
}

/// Runs it; returns the summary printed as JSON. Throws InputError on bad input and
/// TargetNotMetError when no boundary point is found (nothing written then).
nlohmann::json run_us_points(const UsPointsCommand& c) {
  Stopwatch clock;
  const Eigen::Matrix4d calibration = matrix_of(c.calibration, "--calibration");
  const Eigen::Matrix4d registration = matrix_of(c.registration, "--registration");
  if (c.out.empty()) throw InputError("us-points: --out POINTS.csv is required");
  const fs::path out_folder = c.out.parent_path().empty() ? fs::path(".") : c.out.parent_path();
  check_output_location(out_folder, {c.input, c.tracker, c.ct}, "--out", OutputKind::kFile);
  std::error_code ec;
  if (!fs::exists(c.input, ec)) throw InputError(c.input.string() + ": no such file");
  const std::string name = lower_extension(c.input);
  ultrasound::BoundaryOptions o;
  o.rays = c.rays;
  o.target_count = c.count;
  nlohmann::json summary = {{"input", c.input.filename().string()}};
  ultrasound::BoundaryResult found;
  auto set_roi = [&](const Eigen::Vector3d& default_centre, double default_radius) {
    o.centre_mm = c.centre_mm.size() == 3
                      ? Eigen::Vector3d(c.centre_mm[0], c.centre_mm[1], c.centre_mm[2])
                      : default_centre;
    o.r_max_mm = c.radius_mm > 0 ? c.radius_mm : default_radius;
    o.r_min_mm = std::min(2.0, 0.2 * o.r_max_mm);
    summary["centre_mm"] = {o.centre_mm.x(), o.centre_mm.y(), o.centre_mm.z()};
    summary["radius_mm"] = o.r_max_mm;
  };
  auto sweep_points = [&](const ultrasound::TrackedSweep& sweep) {
    try {
      return ultrasound::sweep_boundary_points(sweep, o);
    } catch (const std::invalid_argument& e) {
      throw InputError(c.input.string() + ": " + e.what());
    }
  };
  auto sweep_roi = [&](const ultrasound::TrackedSweep& sweep) {
    const auto& f = sweep.frames[sweep.frames.size() / 2];
    const Eigen::Vector4d mid =
        f.pixel_to_ct_mm * Eigen::Vector4d(0.5 * f.width, 0.5 * f.height, 0, 1);
    const double w = f.pixel_to_ct_mm.block<3, 1>(0, 0).norm() * f.width,
                 h = f.pixel_to_ct_mm.block<3, 1>(0, 1).norm() * f.height;
    set_roi(mid.head<3>(), std::min(w, h) / 3);
  };
  if (ends_with(name, ".dcm")) {
    const dicom::UsImage us = dicom::read_us_image(c.input, c.pixel_mm);
    ultrasound::TrackedSweep sweep;
    Eigen::Matrix4d scale = Eigen::Matrix4d::Identity();
    scale(0, 0) = us.pixel_mm_x, scale(1, 1) = us.pixel_mm_y;
    for (int f = 0; f < us.frames; ++f) {
      ultrasound::TrackedFrame frame;
      frame.index = f;
      frame.width = us.width, frame.height = us.height;
      const size_t n = static_cast<size_t>(us.width) * us.height;
      frame.pixels.assign(us.grey.begin() + static_cast<long>(f * n),
                          us.grey.begin() + static_cast<long>((f + 1) * n));
      frame.pixel_to_ct_mm = registration * calibration * scale;
      sweep.frames.push_back(std::move(frame));
    }
    // Default region: the middle of the calibrated region.
    const Eigen::Vector4d mid = sweep.frames.front().pixel_to_ct_mm *
                                Eigen::Vector4d(0.5 * (us.region[0] + us.region[2]),
                                                0.5 * (us.region[1] + us.region[3]), 0, 1);
    set_roi(mid.head<3>(), std::min((us.region[2] - us.region[0]) * us.pixel_mm_x,
                                    (us.region[3] - us.region[1]) * us.pixel_mm_y) /
                               3);
    summary["kind"] = "dicom";
    summary["photometric"] = us.photometric;
    summary["pixel_mm"] = {us.pixel_mm_x, us.pixel_mm_y};
    summary["pixel_size_from"] =
        us.calibrated && c.pixel_mm <= 0 ? "ultrasound region" : "--pixel-mm";
    summary["frames"] = us.frames;
    found = sweep_points(sweep);
  } else if ((ends_with(name, ".mha") || ends_with(name, ".mhd")) && has_sequence_fields(c.input)) {
    const ultrasound::SequenceMetafile video = ultrasound::read_sequence_metafile(c.input);
    std::optional<ultrasound::SequenceMetafile> tracker;
    if (!c.tracker.empty()) tracker = ultrasound::read_sequence_metafile(c.tracker, false);
    ultrasound::SweepOptions so;
    so.transform = c.transform;
    so.image_to_probe = calibration;
    so.tracker_to_ct = registration;
    const ultrasound::TrackedSweep sweep =
        ultrasound::assemble_sweep(video, tracker ? &*tracker : nullptr, so);
    sweep_roi(sweep);
    summary["kind"] = "tracked sweep";
    summary["frames"] = video.frames.size();
    summary["frames_used"] = sweep.frames.size();
    summary["frames_skipped"] = {{"image_status", sweep.skipped_image_status},
                                 {"transform_status", sweep.skipped_transform_status},
                                 {"no_pose", sweep.skipped_no_pose}};
    found = sweep_points(sweep);
  } else {
    if (!c.tracker.empty())
      throw InputError(c.input.string() + ": --tracker applies to a tracked sweep, not a volume");
    const itkbridge::ScalarImage volume = itkbridge::read_scalar_image(c.input);
    const auto& g = volume.geometry;
    const Eigen::Vector3d mid =
        g.index_to_physical(0.5 * Eigen::Vector3d(g.size[0] - 1, g.size[1] - 1, g.size[2] - 1));
    const Eigen::Vector3d extent =
        g.spacing_mm.cwiseProduct(Eigen::Vector3d(g.size[0], g.size[1], g.size[2]));
    // The ROI is given in output (CT) coordinates; the search runs in the volume's own.
    set_roi((registration * mid.homogeneous()).head<3>(), extent.minCoeff() / 3);
    o.centre_mm = (registration.inverse() * o.centre_mm.homogeneous()).head<3>();
    summary["kind"] = "volume";
    summary["size"] = {g.size[0], g.size[1], g.size[2]};
    try {
      found = ultrasound::boundary_points(g, volume.values, nullptr, o);
    } catch (const std::invalid_argument& e) {
      throw InputError(c.input.string() + ": " + e.what());
    }
    for (auto& p : found.points)
      p.p_mm = (registration * p.p_mm.homogeneous()).head<3>();
  }
  summary["rays"] = found.rays;
  summary["rays_with_a_boundary"] = found.rays_in_view;
  summary["rejected_by_neighbours"] = found.rejected;
  summary["weak_edges"] = found.weak;
  summary["points"] = found.points.size();
  summary["wall_s"] = clock.elapsed_s();
  if (found.points.empty())
    throw TargetNotMetError(
        c.input.string() + ": no boundary points found in the region of interest (centre " +
        summary["centre_mm"].dump() + " mm, radius " + fmt::format("{:g}", o.r_max_mm) + " mm)");
  std::string csv;
  if (!c.ct.empty()) {  // the CT these coordinates are in, for a run to check
    const dicom::CtSeries ct = dicom::read_ct_series(c.ct);
    csv += pipeline::points_ct_comment({ct.series_instance_uid, ct.frame_of_reference_uid});
  }
  csv += "x_mm,y_mm,z_mm,confidence\n";
  for (const auto& p : found.points)
    csv += fmt::format("{:.3f},{:.3f},{:.3f},{:.3f}\n", p.p_mm.x(), p.p_mm.y(), p.p_mm.z(),
                       p.confidence);
  CreatedFolders folders(out_folder);
  write_file_atomically(c.out, csv);
  folders.keep();
  summary["out"] = c.out.string();
  return summary;
}

}  // namespace

Command add_us_points(CLI::App& app) {
  auto usp = std::make_shared<UsPointsCommand>();
  auto* us_points = app.add_subcommand(
      "us-points", "Boundary points of an ultrasound volume, tracked sweep or DICOM image (CSV)");
  us_points
      ->add_option("--us", usp->input,
                   "Ultrasound input: volume (.mha .nrrd .nii), sequence metafile, or .dcm")
      ->required();
  us_points->add_option("--tracker", usp->tracker,
                        "Sequence metafile with the probe poses (matched by timestamp)");
  us_points->add_option("--transform", usp->transform,
                        "Tracked transform name (default: the file's own)");
  us_points
      ->add_option("--calibration", usp->calibration, "Image (mm) to probe, 16 numbers row by row")
      ->delimiter(',')
      ->expected(16);
  us_points
      ->add_option("--registration", usp->registration, "Tracker/volume to CT, 16 numbers (rigid)")
      ->delimiter(',')
      ->expected(16);
  us_points
      ->add_option("--pixel-mm", usp->pixel_mm,
                   "Pixel size of a DICOM image without calibrated region")
      ->check(CLI::PositiveNumber);
  us_points
      ->add_option("--centre", usp->centre_mm,
                   "Region of interest centre X,Y,Z (mm, output coordinates)")
      ->delimiter(',')
      ->expected(3);
  us_points->add_option("--radius", usp->radius_mm, "Region of interest radius (mm)")
      ->check(CLI::PositiveNumber);
  us_points->add_option("--count", usp->count, "Points to keep (0: all)")
      ->check(CLI::Range(0, 100000));
  us_points->add_option("--rays", usp->rays, "Search rays (3D volumes)")
      ->check(CLI::Range(16, 100000));
  us_points->add_option("--ct", usp->ct,
                        "The CT folder --registration maps into: its series is declared in the "
                        "CSV, and a run refuses the points with another planning CT");
  us_points->add_option("-o,--out", usp->out, "Points CSV (x_mm,y_mm,z_mm,confidence)")->required();
  return {us_points, [usp] {
            std::cout << run_us_points(*usp).dump() << "\n";
            return 0;
          }};
}

}  // namespace organfit::app
