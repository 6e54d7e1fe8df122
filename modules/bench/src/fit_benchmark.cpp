#include "organfit/bench/fit_benchmark.h"

#include <fmt/format.h>
#include <omp.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <random>

#include "organfit/bench/fem_cases.h"
#include "organfit/dicom/structure_set.h"
#include "organfit/evaluation/baselines.h"
#include "organfit/fitting/embedded_body.h"
#include "organfit/fitting/global_fit.h"
#include "organfit/fitting/organ_fit.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/itkbridge/tps.h"
#include "organfit/phantom/pelvis.h"
#include "organfit/pipeline/fit_stage.h"
#include "organfit/support/atomic_file.h"
#include "organfit/support/error.h"
#include "organfit/support/interrupt.h"
#include "organfit/support/output_folder.h"
#include "organfit/support/resources.h"

namespace fs = std::filesystem;

namespace organfit::bench {
namespace {

struct ShapeCase {
  std::string name;
  pipeline::ModelStageOptions model;     ///< the radius, and the analytic body without an organ
  std::optional<geometry::Shape> organ;  ///< a mask shape (phantom prostate, real GTV)
};

/// A model of particles of `radius_mm` (the model's defaults otherwise, seed 1) filling
/// an organ, or the analytic body `shape` of `size_mm` about the origin.
pipeline::ModelStageOptions model_of(double radius_mm, const std::string& shape = "",
                                     const Eigen::Vector3d& size_mm = Eigen::Vector3d::Ones()) {
  pipeline::ModelStageOptions o;
  o.settings.radius_mm = radius_mm;
  o.settings.seed = 1;
  o.body_shape = shape;
  o.body_size_mm = size_mm;
  return o;
}

/// The pelvis phantom's prostate (label mask on its CT grid).
geometry::Shape phantom_prostate() {
  const phantom::PelvisPhantom ph = phantom::make_pelvis_phantom(phantom::PelvisOptions{});
  auto mask = std::make_shared<geometry::LabelVolume>(ph.labels.geometry);
  for (size_t v = 0; v < mask->labels.size(); ++v)
    mask->labels[v] = ph.labels.labels[v] == phantom::kProstate;
  return geometry::make_mask_shape(mask);
}

/// The real GTV of ../shared/data/<folder> (ct-sts-004, ct-sts-002; its contours matched
/// by position).
std::optional<geometry::Shape> real_gtv(const fs::path& data,
                                        const std::string& folder = "ct-sts-004") {
  std::error_code ec;
  if (!fs::exists(data / folder / "rtstruct.dcm", ec)) return std::nullopt;
  const dicom::CtSeries ct = dicom::read_ct_series(data / folder / "ct");
  auto roi = dicom::rasterise_roi(dicom::read_rtstruct(data / folder / "rtstruct.dcm"),
                                  "GTV_Mass_CT", ct, folder);
  return geometry::make_mask_shape(std::make_shared<geometry::LabelVolume>(std::move(roi.mask)));
}

struct Row {
  std::string method, shape, family;
  double magnitude_mm = 0;
  int points = 0;
  double noise_mm = 0, outliers = 0;
  double wall_s = 0, msd_mm = 0, hd95_mm = 0, dice = 0, residual_mm = 0;
  /// The organ's volume change (%) by its deformation's Jacobian (EmbeddedBody::volume_ratio,
  /// as run.json's fit.volume_change_pct), and its voxels counted on the truth's lattice
  /// against the organ at rest: on a lattice a box's flat face moves a whole layer of voxels
  /// in or out with where it lies between the lattice's planes (1.7% a face of the 30 mm
  /// cube), which the Jacobian's mean over the organ does not. The count where the
  /// deformation folds (a baseline's can), for which the Jacobian's mean means nothing.
  double volume_change_pct = 0, volume_change_lattice_pct = 0;
  double msd_balls_mm = 0,
         volume_change_balls_pct = 0;  ///< the particles' own body (balls closed by rho)
  bool converged = true;
  int case_id = 0;
  double msd_global_mm = std::numeric_limits<double>::quiet_NaN();  ///< after the global stage
  double msd_undeformed_mm = 0;  ///< the organ left as it was, against the same truth
  /// the truth's own volume change (%): the FEM's (integral of det F); 0 for the analytic
  /// families, which preserve volume exactly
  double truth_volume_change_pct = 0;
  std::string global_fit = "";  ///< which global fit was kept (GlobalMap::found_by)
  /// Ours: the share of the fitted surface within 2 sigma of the truth (all, seen half,
  /// unseen half) and the median sigma on each half (NaN for the others).
  double within_2sd = std::numeric_limits<double>::quiet_NaN(),
         within_2sd_seen = std::numeric_limits<double>::quiet_NaN(),
         within_2sd_unseen = std::numeric_limits<double>::quiet_NaN(),
         sigma_seen_mm = std::numeric_limits<double>::quiet_NaN(),
         sigma_unseen_mm = std::numeric_limits<double>::quiet_NaN();
};

/// One method at one setting of its effort on one case: a point of the work-precision plot.
struct EffortPoint {
  std::string method, effort;
  int case_id = 0;
  double wall_s = 0, msd_mm = 0;
};

/// The cases the issue's targets name: sparse partial data (at most 87 points on half the
/// surface, 0.5 mm noise, no outliers), deformations up to 10 mm.
bool target_case(int points, double noise_mm, double outliers, double magnitude_mm) {
  return points <= 87 && noise_mm == 0.5 && outliers == 0 && magnitude_mm <= 10;
}

double residual_of(const std::vector<fitting::AttractivePoint>& points,
                   const particles::Positions& x, double rho) {
  double sum = 0;
  for (const auto& p : points)
    sum += std::abs((x.colwise() - p.p_mm).colwise().norm().minCoeff() - rho);
  return points.empty() ? 0 : sum / static_cast<double>(points.size());
}

/// The deformation of a family with the given largest displacement (mm).
evaluation::Deformation family_deformation(const std::string& family, double m,
                                           const geometry::Shape& s) {
  evaluation::Deformation d;
  d.centre_mm = s.centre_mm;
  const double half_x = 0.5 * s.size_mm.x(), radius = 0.5 * std::max(s.size_mm.y(), s.size_mm.z());
  if (family == "stretch") d.stretch = 1 + m / half_x;
  if (family == "bend") d.bend_mm = m;
  if (family == "twist") d.twist_rad = m / radius;
  if (family == "indent") d.indent_mm = -m, d.bump_sigma_mm = 0.35 * s.size_mm.minCoeff();
  if (family == "push") d.push_mm = -m, d.bump_sigma_mm = 0.35 * s.size_mm.minCoeff();
  if (family == "shift") d.shift_mm = m * Eigen::Vector3d(1, -2, 2) / 3;
  if (family == "rotate")
    d.rotation_rad = m / (0.5 * s.size_mm.maxCoeff()) * Eigen::Vector3d(2, 1, -2) / 3;
  d.half_length_mm = half_x * d.stretch;
  return d;
}

/// The median wall time and median MSD of each (method, effort) over the cases, in
/// order of increasing wall time per method: the work-precision curves.
struct CurvePoint {
  std::string effort;
  double wall_s, msd_mm;
};
std::map<std::string, std::vector<CurvePoint>> work_precision_curves(
    const std::vector<EffortPoint>& effort) {
  std::map<std::pair<std::string, std::string>, std::pair<std::vector<double>, std::vector<double>>>
      by_setting;
  for (const auto& e : effort)
    if (std::isfinite(e.msd_mm) && std::isfinite(e.wall_s)) {
      auto& [t, m] = by_setting[{e.method, e.effort}];
      t.push_back(e.wall_s), m.push_back(e.msd_mm);
    }
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
    return v[v.size() / 2];
  };
  std::map<std::string, std::vector<CurvePoint>> curves;
  for (const auto& [key, tm] : by_setting)
    curves[key.first].push_back({key.second, median(tm.first), median(tm.second)});
  for (auto& [method, c] : curves)
    std::sort(c.begin(), c.end(),
              [](const CurvePoint& l, const CurvePoint& r) { return l.wall_s < r.wall_s; });
  return curves;
}

std::string svg_work_precision(const std::vector<Row>& all_rows,
                               const std::vector<EffortPoint>& effort) {
  // Rows without a finite error (a baseline that emptied the organ: MSD infinite) cannot
  // be placed on log axes; the table and results.csv still have them.
  std::vector<Row> rows;
  for (const auto& r : all_rows)
    if (std::isfinite(r.msd_mm) && std::isfinite(r.wall_s)) rows.push_back(r);
  if (rows.empty())
    return R"(<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10"></svg>)"
           "\n";
  const std::map<std::string, const char*> colours = {{"spread", "#1f77b4"},
                                                      {"paper", "#ff7f0e"},
                                                      {"tps", "#2ca02c"},
                                                      {"cpd", "#d62728"},
                                                      {"icp", "#9467bd"}};
  const auto curves = work_precision_curves(effort);
  double tmin = 1e9, tmax = 1e-9, emin = 1e9, emax = 1e-9;
  auto include = [&](double wall_s, double msd_mm) {
    tmin = std::min(tmin, std::max(wall_s, 1e-4)), tmax = std::max(tmax, wall_s);
    emin = std::min(emin, std::max(msd_mm, 1e-2)), emax = std::max(emax, msd_mm);
  };
  for (const auto& r : rows)
    include(r.wall_s, r.msd_mm);
  for (const auto& [method, c] : curves)
    for (const auto& p : c)
      include(p.wall_s, p.msd_mm);
  const double lt0 = std::floor(std::log10(tmin)),
               lt1 = std::ceil(std::log10(tmax)) + (tmax == tmin);
  const double le0 = std::floor(std::log10(emin) * 2) / 2,
               le1 = std::ceil(std::log10(emax) * 2) / 2 + 0.5;
  const double w = 640, h = 420, l = 70, r = 130, t = 20, b = 50;
  auto X = [&](double s) {
    return l + (w - l - r) * (std::log10(std::max(s, 1e-4)) - lt0) / (lt1 - lt0);
  };
  auto Y = [&](double e) {
    return t + (h - t - b) * (1 - (std::log10(std::max(e, 1e-2)) - le0) / (le1 - le0));
  };
  std::string svg = fmt::format(
      R"x(<svg xmlns="http://www.w3.org/2000/svg" width="{}" height="{}" viewBox="0 0 {} {}"><rect x="{}" y="{}" width="{}" height="{}" fill="#fafafa" stroke="#888"/>)x",
      w, h, w, h, l, t, w - l - r, h - t - b);
  for (double e = lt0; e <= lt1 + 1e-9; e += 1)
    svg += fmt::format(
        R"x(<text x="{:.1f}" y="{}" font-size="11" text-anchor="middle">1e{:.0f}</text>)x",
        X(std::pow(10, e)), h - b + 16, e);
  for (double e = le0; e <= le1 + 1e-9; e += 0.5)
    svg +=
        fmt::format(R"x(<text x="{}" y="{:.1f}" font-size="11" text-anchor="end">{:.2g}</text>)x",
                    l - 4, Y(std::pow(10, e)) + 4, std::pow(10, e));
  svg += fmt::format(
      R"x(<text x="{}" y="{}" font-size="12" text-anchor="middle">wall time per fit (s, log)</text>)x",
      l + (w - l - r) / 2, h - 12);
  svg += fmt::format(
      R"x(<text x="16" y="{0}" font-size="12" transform="rotate(-90 16 {0})" text-anchor="middle">mean surface distance (mm, log)</text>)x",
      t + (h - t - b) / 2);
  int legend = 0;
  for (const auto& [method, colour] : colours) {
    std::vector<double> ts, es;
    for (const auto& row : rows)
      if (row.method == method) {
        svg += fmt::format(
            R"x(<circle cx="{:.1f}" cy="{:.1f}" r="3" fill="{}" fill-opacity="0.45"/>)x",
            X(row.wall_s), Y(row.msd_mm), colour);
        ts.push_back(row.wall_s), es.push_back(row.msd_mm);
      }
    if (ts.empty()) continue;
    // The method's curve: the medians of each setting of its effort, joined.
    const auto it = curves.find(method);
    if (it != curves.end()) {
      std::string path;
      for (const auto& c : it->second) {
        path += fmt::format("{}{:.1f},{:.1f}", path.empty() ? "" : " ", X(c.wall_s), Y(c.msd_mm));
        svg += fmt::format(
            R"x(<rect x="{:.1f}" y="{:.1f}" width="10" height="10" fill="{}" stroke="black"/><text x="{:.1f}" y="{:.1f}" font-size="9">{}</text>)x",
            X(c.wall_s) - 5, Y(c.msd_mm) - 5, colour, X(c.wall_s) + 7, Y(c.msd_mm) - 6, c.effort);
      }
      svg += fmt::format(R"x(<polyline points="{}" fill="none" stroke="{}" stroke-width="2"/>)x",
                         path, colour);
    }
    svg += fmt::format(
        R"x(<rect x="{}" y="{}" width="12" height="12" fill="{}"/><text x="{}" y="{}" font-size="12">{}</text>)x",
        w - r + 14, t + 20 * legend, colour, w - r + 32, t + 20 * legend + 11, method);
    ++legend;
  }
  svg += fmt::format(
      R"x(<text x="{}" y="{}" font-size="11">dots: cases;</text><text x="{}" y="{}" font-size="11">squares: medians</text><text x="{}" y="{}" font-size="11">per setting</text>)x",
      w - r + 14, t + 20 * legend + 11, w - r + 14, t + 20 * legend + 25, w - r + 14,
      t + 20 * legend + 39);
  return svg + "</svg>\n";
}

}  // namespace

nlohmann::json run_fit_benchmark(const FitBenchOptions& o) {
  if (o.out.empty()) throw InputError("bench fit: --out DIR is required");
  const std::vector<std::string> all_methods = {"spread", "paper", "tps", "cpd", "icp"};
  for (const auto& m : o.methods)
    if (std::find(all_methods.begin(), all_methods.end(), m) == all_methods.end())
      throw InputError("bench fit: --methods: unknown method '" + m +
                       "' (spread, paper, tps, cpd, icp)");
  std::vector<std::string> methods;  // in the table's order
  for (const auto& m : all_methods)
    if (o.methods.empty() || std::find(o.methods.begin(), o.methods.end(), m) != o.methods.end())
      methods.push_back(m);
  if (o.threads > 0) omp_set_num_threads(o.threads);
  Stopwatch total;

  std::vector<ShapeCase> shapes = {
      {"phantom_prostate", model_of(1.92), phantom_prostate()},
      {"cube", model_of(1.75, "box", Eigen::Vector3d(30, 30, 30)), std::nullopt}};
  std::vector<std::string> families = {"stretch", "bend", "twist", "indent", "push"};
  // The GTVs of ct-sts-004 and ct-sts-002 (where ../shared/data has them), after the shapes.
  auto add_real_gtvs = [&shapes] {
    for (const std::string sts : {"004", "002"})
      if (auto gtv = real_gtv(ORGANFIT_SHARED_DATA_DIR_STRING, "ct-sts-" + sts))
        shapes.push_back({"real_gtv_sts" + sts, model_of(3.0), std::move(gtv)});
  };
  std::vector<double> magnitudes = {5, 10};
  std::vector<int> counts = {87};
  std::vector<double> noises = {0.5}, outliers = {0.0};
  if (o.sessions && o.quick) throw InputError("bench fit: --sessions excludes --quick");
  if (o.fem && (o.quick || o.sessions))
    throw InputError("bench fit: --fem excludes --quick and --sessions");
  if (o.fem) {
    shapes.erase(shapes.begin() + 1);  // the cube: no organ a probe presses
    add_real_gtvs();
    families = {"fem_probe", "fem_bladder"};
    magnitudes = {2, 5, 8, 12};
  } else if (o.sessions) {
    // The real GTVs too (cases 71 on): an organ on 3.27 mm slices, whose staircase no
    // analytic shape has, where noise alone can move a fit most.
    add_real_gtvs();
    families = {"shift", "rotate", "stretch", "bend", "twist", "indent", "push"};
    magnitudes = {0, 0.5, 1, 2, 5};
  } else if (!o.quick) {
    shapes.push_back({"egg", model_of(1.92, "egg", Eigen::Vector3d(50, 40, 34)), std::nullopt});
    shapes.push_back({"lung", model_of(1.9, "lung", Eigen::Vector3d(40, 30, 60)), std::nullopt});
    if (auto gtv = real_gtv(ORGANFIT_SHARED_DATA_DIR_STRING))
      shapes.push_back({"real_gtv_sts004", model_of(3.0), std::move(gtv)});
    magnitudes = {2, 5, 10, 15};
    counts = {20, 50, 87, 200};
    noises = {0, 0.5, 1.0};
    outliers = {0, 0.05};
  }
  // --sample N: a seeded, uniform subset of the grid's cases (each keeps its number and
  // seed from the whole grid, so a sampled case is the same case as in a full run).
  const long long grid_cases =
      static_cast<long long>(shapes.size() * families.size() * magnitudes.size() * counts.size() *
                             noises.size() * outliers.size());
  std::vector<char> selected(static_cast<size_t>(grid_cases) + 1, 1);
  if (!o.cases.empty()) {
    if (o.sample > 0 || o.targets)
      throw InputError("bench fit: --cases excludes --sample and --targets");
    std::fill(selected.begin(), selected.end(), 0);
    for (long long c : o.cases) {
      if (c < 1 || c > grid_cases)
        throw InputError(fmt::format("bench fit: --cases: no case {} (the {}grid has 1 to {})", c,
                                     o.quick ? "quick " : "", grid_cases));
      selected[static_cast<size_t>(c)] = 1;
    }
  } else if (o.targets && o.sample > 0) {
    throw InputError("bench fit: --targets excludes --sample");
  } else if (o.sample > 0 && o.sample < grid_cases) {
    std::vector<long long> ids(static_cast<size_t>(grid_cases));
    for (long long i = 0; i < grid_cases; ++i)
      ids[static_cast<size_t>(i)] = i + 1;
    std::mt19937_64 rng(20261122);
    std::shuffle(ids.begin(), ids.end(), rng);
    std::fill(selected.begin(), selected.end(), 0);
    for (long long i = 0; i < o.sample; ++i)
      selected[static_cast<size_t>(ids[static_cast<size_t>(i)])] = 1;
  }
  // The folder only once the options are known to be good: a refused run leaves nothing.
  check_output_location(o.out, {}, "--out");
  CreatedFolders folder(o.out, /*with_contents=*/true);
  std::vector<Row> rows;
  std::vector<EffortPoint> effort;
  std::string curves = "case,method,step,wall_s,residual_mean_mm,volume_change_pct\n";
  int case_id = 0, cases_run = 0;
  nlohmann::json fem_meshes = nlohmann::json::array();  // the FEM solves (--fem)
  for (const auto& shape : shapes) {
    const pipeline::ModelStageResult model =
        pipeline::run_model_stage(shape.model, shape.organ ? &*shape.organ : nullptr);
    fitting::organ_body(
        model);  // makes the planning organ's cache, which every case's clone shares
    const double rho = model.model->radius_mm();
    const fitting::SurfaceSamples full = fitting::reference_surface(model.reference, 1);
    // ~400 surface samples for the baselines (CPD's M x M system).
    const Eigen::Index stride = std::max<Eigen::Index>(1, full.points.cols() / 400);
    Eigen::Matrix3Xd surface(3, (full.points.cols() + stride - 1) / stride);
    for (Eigen::Index j = 0, k = 0; j < full.points.cols(); j += stride, ++k)
      surface.col(k) = full.points.col(j);
    const double voxel = evaluation::kTruthVoxelMm;
    const double v0 = geometry::particle_body_volume_mm3(model.state.x, rho, voxel, rho);
    const auto reference = std::make_shared<const geometry::LabelVolume>(model.reference);
    const double support = fitting::embedding_support_mm(model.lattice_spacing_mm);
    // The reference moved by a displacement of the particles; its signed distance (two
    // distance transforms of its grid) made once for the shape, not for every organ.
    const auto reference_distance =
        std::make_shared<const geometry::SignedDistance>(*reference, false);
    auto carried = [&](const fitting::GlobalMap& map, const particles::Positions& placed_at,
                       const particles::Positions& now) {
      return fitting::EmbeddedBody(
          reference, reference_distance,
          std::make_shared<const fitting::Deformation>(map, placed_at, now, support));
    };
    // The organ at rest is the reference body: its own voxel count, which is the volume
    // inside the 0.5 level of its trilinear interpolation (exact for a box's faces). On
    // another grid a box's face moves a whole layer of voxels in or out with the grid's
    // origin (the 30 mm cube: -1.2% to +3.4% on voxels of 0.5 and 0.875 mm).
    const double v0_embedded = model.reference.volume_mm3(1);
    // The Jacobian's volume measure on the grid every fit measures its organ on.
    const double volume_voxel = fitting::volume_voxel_mm(rho, v0_embedded);
    std::map<std::string, FemCases> fem;  // per load, made when a case first needs it
    for (const auto& family : families)
      for (double magnitude : magnitudes)
        for (int count : counts)
          for (double noise : noises)
            for (double outlier : outliers) {
              throw_if_interrupted();
              ++case_id;
              if (!selected[static_cast<size_t>(case_id)] ||
                  (o.targets && !target_case(count, noise, outlier, magnitude)))
                continue;
              evaluation::Deformation d = family_deformation(family, magnitude, model.shape);
              double truth_volume_change_pct = 0;
              if (family.rfind("fem_", 0) == 0) {
                const std::string load = family.substr(4);
                if (!fem.count(load)) {
                  fem[load] = fem_cases(model.shape, shape.name, load, magnitudes,
                                        o.fem_cache.empty() ? default_fem_cache() : o.fem_cache);
                  fem_meshes.push_back({{"shape", shape.name},
                                        {"load", load},
                                        {"mesh", fem[load].mesh},
                                        {"magnitudes_made", fem[load].cases.size()},
                                        {"solve_wall_s", fem[load].solve_wall_s},
                                        {"folder", fem[load].folder.string()}});
                }
                const auto& made = fem[load].cases;
                const auto fc_at = std::find_if(made.begin(), made.end(), [&](const FemCase& c) {
                  return c.magnitude_mm == magnitude;
                });
                if (fc_at == made.end()) continue;  // the FEM found no solution this far
                const FemCase& fc = *fc_at;
                d = evaluation::Deformation{};
                d.field = fc.field;
                truth_volume_change_pct = fc.volume_change_pct;
              }
              ++cases_run;
              evaluation::SamplingOptions so;
              so.count = count, so.noise_mm = noise, so.outlier_fraction = outlier,
              so.half_coverage = true;
              so.seed = static_cast<unsigned>(case_id);
              // The points alone: the fit stage's own truth report (run.json) would measure
              // what is measured below a second time.
              pipeline::PointsStageResult pts;
              pts.points = evaluation::sample_deformed_surface(model.shape, d, so);
              const evaluation::InsideTest inside = evaluation::deformed_body(model.shape, d);
              const geometry::Aabb bounds = pipeline::deformed_bounds(model.shape, d);
              // The true organ, sampled once for every body of the case compared with it.
              evaluation::KnownBody truth(inside, bounds, voxel);
              // The organ left as it was: what do-no-harm compares with.
              const double msd_undeformed =
                  truth.compare(carried(fitting::GlobalMap{}, model.state.x, model.state.x)).msd_mm;
              Eigen::Matrix3Xd xs(3, static_cast<Eigen::Index>(pts.points.size()));
              for (size_t i = 0; i < pts.points.size(); ++i)
                xs.col(static_cast<Eigen::Index>(i)) = pts.points[i].p_mm;
              for (const auto& method : methods) {
                Row row{method, shape.name, family, magnitude, count, noise, outlier};
                row.case_id = case_id;
                row.msd_undeformed_mm = msd_undeformed;
                row.truth_volume_change_pct = truth_volume_change_pct;
                std::string default_effort =
                    method == "spread" ? "global and local stages" : "default";
                double global_wall_s = std::numeric_limits<double>::quiet_NaN();
                particles::Positions moved;
                fitting::GlobalMap global_map;
                particles::Positions placed = model.state.x;
                if (method == "spread" || method == "paper") {
                  // The scene's defaults (the option structs' own), but a 20 s budget and
                  // stretches up to 2x for the grid's.
                  fitting::OrganFitOptions fit_options;
                  fit_options.max_wall_s = 20;
                  fitting::SpreadFitOptions spread{fit_options, {}, {}};
                  spread.global.max_stretch = 2.0;
                  fitting::FittedOrgan fit;
                  try {
                    fit = method == "spread"
                              ? fitting::fit_spread(fitting::copy_model(model), pts.points, spread)
                              : fitting::fit_paper(fitting::copy_model(model), pts.points,
                                                   {fit_options, {}});
                  } catch (const fitting::ModelBrokeError& e) {
                    fit.model = fitting::copy_model(model);  // counted as not converged
                    spdlog::debug("bench fit: {}: {}", method, e.what());
                  }
                  const fitting::FitReport& report = fit.report;
                  row.wall_s = report.fit.wall_s;
                  row.converged = !report.refused && report.fit.converged;
                  if (report.global) global_wall_s = report.global->wall_s;
                  moved = fit.model.state.x;
                  if (fit.model.placed.cols() == moved.cols())
                    global_map = fit.model.global_map, placed = fit.model.placed;
                  if (method == "spread" && report.uncertainty && report.deformation) {
                    const pipeline::UncertaintyOnSurface on = pipeline::uncertainty_on_surface(
                        model.shape, *report.deformation, *report.uncertainty);
                    const nlohmann::json c =
                        pipeline::uncertainty_coverage(on, inside, bounds, voxel);
                    row.within_2sd = c["within_2sd_share"].get<double>();
                    row.within_2sd_seen = c["seen_within_2sd_share"].get<double>();
                    row.within_2sd_unseen = c["unseen_within_2sd_share"].get<double>();
                    row.sigma_seen_mm = on.summary["seen"]["median_mm"].get<double>();
                    row.sigma_unseen_mm = on.summary["unseen"]["median_mm"].get<double>();
                  }
                  for (const auto& h : report.fit.history)
                    curves +=
                        fmt::format("{},{},{},{:.6f},{:.6f},{:.6f}\n", case_id, method, h.step,
                                    h.wall_s, h.residual_mean_mm, h.volume_change_pct);
                } else {
                  // Work-precision: each baseline also at less effort (and TPS at more),
                  // its organ measured as below; the default's own row follows.
                  auto organ_msd = [&](const evaluation::PointMap& f) {
                    particles::Positions x(3, model.state.x.cols());
                    for (Eigen::Index j = 0; j < x.cols(); ++j)
                      x.col(j) = f(model.state.x.col(j));
                    return truth.compare(carried(fitting::GlobalMap{}, model.state.x, x)).msd_mm;
                  };
                  evaluation::PointMap map;
                  if (method == "icp" || method == "cpd") {
                    // The baseline at a number of iterations; the default's last.
                    std::function<evaluation::PointMap(int)> run;
                    std::vector<int> iterations;
                    if (method == "icp") {
                      run = [&](int n) { return evaluation::similarity_icp(surface, xs, n); };
                      iterations = {3, 10, 30};
                      if (o.defaults_only) iterations = {30};
                    } else {
                      evaluation::CpdOptions co;
                      co.w = outlier > 0 ? 0.2 : 0.1;
                      run = [&, co](int n) {
                        evaluation::CpdOptions at = co;
                        at.iterations = n;
                        return evaluation::coherent_point_drift(surface, xs, at);
                      };
                      iterations = {15, 50, co.iterations};
                      if (o.defaults_only) iterations = {co.iterations};
                    }
                    for (size_t k = 0; k < iterations.size(); ++k) {
                      Stopwatch clock;
                      const evaluation::PointMap f = run(iterations[k]);
                      const double t = clock.elapsed_s();
                      if (k + 1 < iterations.size()) {
                        effort.push_back({method, fmt::format("{} iterations", iterations[k]),
                                          case_id, t, organ_msd(f)});
                      } else {
                        map = f, row.wall_s = t;
                        default_effort = fmt::format("{} iterations", iterations[k]);
                      }
                    }
                  } else {
                    // Thin-plate spline from closest-point pairs, iterated: 5 rounds by
                    // default; the spline after 1, 2 and 10 rounds too (the time of a run
                    // stopped there: the measuring is not counted).
                    Eigen::Matrix3Xd current = surface;
                    std::shared_ptr<itkbridge::ThinPlateSpline> tps;
                    auto spline_map = [](std::shared_ptr<itkbridge::ThinPlateSpline> f) {
                      return [f](const Eigen::Vector3d& p) -> Eigen::Vector3d {
                        if (!f) return p;
                        const auto q = f->apply({p.x(), p.y(), p.z()});
                        return {q[0], q[1], q[2]};
                      };
                    };
                    double spent = 0;
                    for (int round = 1; round <= (o.defaults_only ? 5 : 10); ++round) {
                      Stopwatch clock;
                      std::vector<std::array<double, 3>> src, dst;
                      std::vector<char> used(static_cast<size_t>(surface.cols()), 0);
                      for (Eigen::Index i = 0; i < xs.cols(); ++i) {
                        Eigen::Index at = 0;
                        (current.colwise() - xs.col(i)).colwise().squaredNorm().minCoeff(&at);
                        if (used[static_cast<size_t>(at)])
                          continue;  // one landmark per surface sample
                        used[static_cast<size_t>(at)] = 1;
                        src.push_back({surface(0, at), surface(1, at), surface(2, at)});
                        dst.push_back({xs(0, i), xs(1, i), xs(2, i)});
                      }
                      bool failed = false;
                      try {
                        tps = std::make_shared<itkbridge::ThinPlateSpline>(src, dst);
                      } catch (const InputError&) {
                        failed = true;  // the last good spline stays
                      }
                      for (Eigen::Index j = 0; !failed && j < surface.cols(); ++j) {
                        const auto q = tps->apply({surface(0, j), surface(1, j), surface(2, j)});
                        current.col(j) = Eigen::Vector3d(q[0], q[1], q[2]);
                      }
                      spent += clock.elapsed_s();
                      if (round == 5) map = spline_map(tps), row.wall_s = spent;
                      if (!o.defaults_only && (round == 1 || round == 2 || round == 10))
                        effort.push_back({method,
                                          fmt::format("{} round{}", round, round > 1 ? "s" : ""),
                                          case_id, spent, organ_msd(spline_map(tps))});
                    }
                    default_effort = "5 rounds";
                  }
                  moved.resize(3, model.state.x.cols());
                  for (Eigen::Index j = 0; j < moved.cols(); ++j)
                    moved.col(j) = map(model.state.x.col(j));
                }
                // Every method is measured on the organ it carries: the reference moved by its
                // displacement of the particles (fitting/embedded_body.h), the particle fits
                // with their global map; the balls' body is kept for comparison.
                if (placed.cols() != moved.cols())
                  placed = moved, global_map = fitting::GlobalMap{};
                const fitting::EmbeddedBody organ = carried(global_map, placed, moved);
                const auto cmp = truth.compare(organ);
                if (method == "spread" && placed.cols() == moved.cols()) {
                  const fitting::EmbeddedBody global_only = carried(global_map, placed, placed);
                  row.msd_global_mm = truth.compare(global_only).msd_mm;
                  row.global_fit = std::string(global_map.found_by) +
                                   (global_map.fields.empty() ? "" : " + shear fields");
                  if (std::isfinite(global_wall_s))
                    effort.push_back(
                        {method, "global stage", case_id, global_wall_s, row.msd_global_mm});
                }
                row.msd_mm = cmp.msd_mm, row.hd95_mm = cmp.hd95_mm, row.dice = cmp.dice;
                row.volume_change_lattice_pct = 100 * (cmp.volume_a_mm3 / v0_embedded - 1);
                // The Jacobian's mean holds for a map onto its image, one that does not fold
                // (a baseline's can): the count where it folds.
                row.volume_change_pct =
                    organ.deformation().folds()
                        ? row.volume_change_lattice_pct
                        : 100 * (organ.volume_ratio(organ.on_grid(geometry::grid_covering(
                                     organ.bounds(), volume_voxel, volume_voxel))) -
                                 1);
                const auto balls = truth.compare(moved, rho);
                row.msd_balls_mm = balls.msd_mm;
                row.volume_change_balls_pct =
                    100 * (geometry::particle_body_volume_mm3(moved, rho, voxel, rho) / v0 - 1);
                row.residual_mm = residual_of(pts.points, moved, rho);
                effort.push_back({method, default_effort, case_id, row.wall_s, row.msd_mm});
                rows.push_back(row);
              }
              std::string errors;
              for (size_t k = rows.size() - methods.size(); k < rows.size(); ++k)
                errors += fmt::format("{}{} {:.2f} mm", errors.empty() ? "" : ", ", rows[k].method,
                                      rows[k].msd_mm);
              spdlog::info("bench fit: case {} ({} {} {} mm, {} points): {}", case_id, shape.name,
                           family, magnitude, count, errors);
            }
  }

  std::string csv =
      "method,shape,family,magnitude_mm,points,noise_mm,outliers,wall_s,msd_mm,hd95_mm,dice,volume_"
      "change_pct,residual_mm,"
      "converged,msd_balls_mm,volume_change_balls_pct,msd_global_mm,case,global_fit,msd_"
      "undeformed_mm,within_2sd,within_2sd_seen,within_2sd_unseen,sigma_seen_mm,sigma_unseen_mm,"
      "truth_volume_change_pct,volume_change_lattice_pct\n";
  for (const auto& r : rows)
    csv += fmt::format(
        "{},{},{},{},{},{},{},{:.4f},{:.4f},{:.4f},{:.4f},{:.4f},{:.4f},{},{:.4f},{:.4f},{:.4f},{},"
        "{},{:.4f},{:.4f},{:.4f},{:.4f},{:.4f},{:.4f},{:.3e},{:.4f}"
        "\n",
        r.method, r.shape, r.family, r.magnitude_mm, r.points, r.noise_mm, r.outliers, r.wall_s,
        r.msd_mm, r.hd95_mm, r.dice, r.volume_change_pct, r.residual_mm, r.converged ? 1 : 0,
        r.msd_balls_mm, r.volume_change_balls_pct, r.msd_global_mm, r.case_id, r.global_fit,
        r.msd_undeformed_mm, r.within_2sd, r.within_2sd_seen, r.within_2sd_unseen, r.sigma_seen_mm,
        r.sigma_unseen_mm, r.truth_volume_change_pct, r.volume_change_lattice_pct);
  write_file_atomically(o.out / "results.csv", csv);
  write_file_atomically(o.out / "curves.csv", curves);
  std::string effort_csv = "method,effort,case,wall_s,msd_mm\n";
  for (const auto& e : effort)
    effort_csv +=
        fmt::format("{},{},{},{:.4f},{:.4f}\n", e.method, e.effort, e.case_id, e.wall_s, e.msd_mm);
  write_file_atomically(o.out / "work_precision.csv", effort_csv);
  write_file_atomically(o.out / "work_precision.svg", svg_work_precision(rows, effort));

  // RESULTS.md: medians per method, and the issue's targets on the sparse partial cases.
  auto median = [](std::vector<double> v) {
    if (v.empty()) return std::nan("");
    std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
    return v[v.size() / 2];
  };
  nlohmann::json summary = {
      {"benchmark", "fit"},       {"cases", cases_run},  {"defaults_only", o.defaults_only},
      {"grid_cases", grid_cases}, {"rows", rows.size()}, {"out", o.out.string()}};
  std::string md = fmt::format(
      "# organfit bench fit{}{}\n\n{} cases{} x {} methods; points on the posterior half of the "
      "deformed surface. Metrics: fit_benchmark.h. The particle fits use the scene defaults "
      "but fit.spread.max_global_stretch: 2 (the grid stretches the cube up to 2x).\n\n",
      std::string(o.quick ? " --quick" : "") + (o.sessions ? " --sessions" : "") +
          (o.fem ? " --fem" : "") + (o.defaults_only ? " --defaults-only" : ""),
      o.sample > 0 ? fmt::format(" --sample {}", o.sample) : "", cases_run,
      cases_run < grid_cases
          ? fmt::format(" (a seeded uniform sample of the grid's {})", grid_cases)
          : "",
      methods.size());
  md +=
      "| method | median MSD (mm) | median HD95 (mm) | median Dice | median |volume change| (%) | "
      "median wall (s) | converged |\n|---|---|---|---|---|---|---|\n";
  for (const auto& m : methods) {
    std::vector<double> msd, hd, dice, vol, wall;
    int conv = 0, n = 0;
    for (const auto& r : rows)
      if (r.method == m)
        msd.push_back(r.msd_mm), hd.push_back(r.hd95_mm), dice.push_back(r.dice),
            vol.push_back(std::abs(r.volume_change_pct)), wall.push_back(r.wall_s),
            conv += r.converged, ++n;
    md += fmt::format("| {} | {:.2f} | {:.2f} | {:.3f} | {:.2f} | {:.3f} | {}/{} |\n", m,
                      median(msd), median(hd), median(dice), median(vol), median(wall), conv, n);
    summary[m] = {{"median_msd_mm", median(msd)},
                  {"median_hd95_mm", median(hd)},
                  {"median_volume_change_pct", median(vol)},
                  {"median_wall_s", median(wall)}};
  }
  md +=
      "\n## Per family, magnitude <= 10 mm, median MSD (mm)\n\n| family | spread | paper | tps | "
      "cpd | icp |\n|---|---|---|---|---|---|\n";
  for (const auto& f : families) {
    md += "| " + f;
    for (const auto& m : methods) {
      std::vector<double> v;
      for (const auto& r : rows)
        if (r.method == m && r.family == f && r.magnitude_mm <= 10) v.push_back(r.msd_mm);
      md += fmt::format(" | {:.2f}", median(v));
    }
    md += " |\n";
  }
  // Targets: sparse partial data (<= 87 points, half the surface, 0.5 mm noise), <= 10 mm.
  int n = 0, meet_msd = 0, meet_hd = 0, meet_vol = 0;
  for (const auto& r : rows)
    if (r.method == "spread" && target_case(r.points, r.noise_mm, r.outliers, r.magnitude_mm))
      ++n, meet_msd += r.msd_mm <= 1.0, meet_hd += r.hd95_mm <= 2.5,
          meet_vol += std::abs(r.volume_change_pct) <= 1.0;
  md += fmt::format(
      "\n## Targets (ours, sparse partial data: <= 87 points on half the surface, 0.5 mm noise, <= "
      "10 mm)\n\n"
      "- MSD <= 1.0 mm: {}/{} cases\n- HD95 <= 2.5 mm: {}/{} cases\n- |volume change| <= 1%: {}/{} "
      "cases\n",
      meet_msd, n, meet_hd, n, meet_vol, n);
  // Side by side on the same cases: ours against TPS and CPD, with the wall times.
  std::map<std::string, std::vector<double>> ratio, wall_ratio, ratio_equal_time;
  std::map<std::string, int> half, smaller_volume, cases, half_equal_time;
  std::map<std::pair<std::string, int>, std::vector<const EffortPoint*>> settings;
  for (const auto& e : effort)
    settings[{e.method, e.case_id}].push_back(&e);
  // A baseline's error at ours' wall time: its best over the settings it can run within
  // it, or its fastest setting's when none is that fast (in its favour).
  auto at_wall_time = [&](const std::string& method, int case_number, double wall_s) {
    double best = std::numeric_limits<double>::infinity(), fastest_wall = best, fastest = best;
    for (const EffortPoint* e : settings[{method, case_number}]) {
      if (e->wall_s <= wall_s) best = std::min(best, e->msd_mm);
      if (e->wall_s < fastest_wall) fastest_wall = e->wall_s, fastest = e->msd_mm;
    }
    return std::isfinite(best) ? best : fastest;
  };
  for (size_t i = 0; i < rows.size(); ++i) {
    const Row& r = rows[i];
    if (r.method != "spread" || !target_case(r.points, r.noise_mm, r.outliers, r.magnitude_mm))
      continue;
    for (size_t j = i + 1; j < rows.size() && j < i + methods.size(); ++j) {
      const Row& b = rows[j];
      if (b.method != "tps" && b.method != "cpd") continue;
      ratio[b.method].push_back(r.msd_mm / std::max(b.msd_mm, 1e-9));
      wall_ratio[b.method].push_back(r.wall_s / std::max(b.wall_s, 1e-9));
      half[b.method] += r.msd_mm <= 0.5 * b.msd_mm;
      const double theirs = at_wall_time(b.method, b.case_id, r.wall_s);
      ratio_equal_time[b.method].push_back(r.msd_mm / std::max(theirs, 1e-9));
      half_equal_time[b.method] += r.msd_mm <= 0.5 * theirs;
      smaller_volume[b.method] += std::abs(r.volume_change_pct) < std::abs(b.volume_change_pct);
      ++cases[b.method];
    }
  }
  md +=
      "\n## Side by side (same cases): ours against the baselines\n\n| baseline | median MSD ratio "
      "(ours / theirs) | "
      "cases with ours <= half theirs | cases with a smaller volume change | median wall-time "
      "ratio (ours / theirs) "
      "| at ours' wall time: median MSD ratio | ... cases with ours <= half theirs "
      "|\n|---|---|---|---|---|---|---|\n";
  for (const std::string b : {"tps", "cpd"}) {
    md += fmt::format("| {} | {:.2f} | {}/{} | {}/{} | {:.2f} | {:.2f} | {}/{} |\n", b,
                      median(ratio[b]), half[b], cases[b], smaller_volume[b], cases[b],
                      median(wall_ratio[b]), median(ratio_equal_time[b]), half_equal_time[b],
                      cases[b]);
    summary["versus_" + b] = {{"median_msd_ratio", median(ratio[b])},
                              {"msd_at_most_half", half[b]},
                              {"smaller_volume_change", smaller_volume[b]},
                              {"cases", cases[b]},
                              {"median_wall_ratio", median(wall_ratio[b])}};
    if (!o.defaults_only)  // with one setting per baseline there is no curve to read it from
      summary["versus_" + b]["at_equal_wall_time"] = {
          {"median_msd_ratio", median(ratio_equal_time[b])},
          {"msd_at_most_half", half_equal_time[b]}};
  }
  md += o.defaults_only
            ? "\nWith --defaults-only each baseline ran at its default setting alone, so the "
              "columns at ours' wall time compare with that setting.\n"
            : "\nAt ours' wall time, a baseline's error is its best over the settings of its "
              "effort that run within that time (TPS: 1, 2, 5, 10 rounds; CPD: 15, 50, 150 "
              "iterations), or its fastest setting's when none does.\n";
  md +=
      "\nFiles: results.csv (one row per case and method, each at its default setting), "
      "work_precision.csv (one row per case, method and setting of its effort), curves.csv (the "
      "particle fits' residual and volume against wall time), work_precision.svg (one curve per "
      "method through the medians of its settings).\n";
  // Do no harm: per method, the cases whose MSD exceeds the undeformed organ's + 0.1 mm;
  // ours against TPS on the same case.
  {
    nlohmann::json harm = nlohmann::json::object();
    md +=
        "\n## Do no harm (MSD above the undeformed organ's + 0.1 mm)\n\n| method | cases | "
        "worse than undeformed + 0.1 mm | median MSD - undeformed (mm) |\n|---|---|---|---|\n";
    for (const auto& m : methods) {
      int worse = 0, total_m = 0;
      std::vector<double> excess;
      for (const auto& r : rows)
        if (r.method == m)
          ++total_m, worse += r.msd_mm > r.msd_undeformed_mm + 0.1,
              excess.push_back(r.msd_mm - r.msd_undeformed_mm);
      md += fmt::format("| {} | {} | {} | {:+.3f} |\n", m, total_m, worse, median(excess));
      harm[m] = {{"cases", total_m},
                 {"worse_than_undeformed_plus_0_1mm", worse},
                 {"median_msd_minus_undeformed_mm", median(excess)}};
    }
    int worse_than_tps = 0, pairs = 0;
    for (const auto& r : rows)
      if (r.method == "spread")
        for (const auto& b : rows)
          if (b.method == "tps" && b.case_id == r.case_id)
            ++pairs, worse_than_tps += r.msd_mm > b.msd_mm;
    if (pairs > 0) {
      harm["spread_worse_than_tps"] = worse_than_tps;
      md += fmt::format("\nOurs above TPS's MSD: {} of {} cases.\n", worse_than_tps, pairs);
    }
    summary["do_no_harm"] = harm;
  }
  // The uncertainty's calibration (ours): the true surface within 2 sigma on at least 90%
  // of the surface, per case; sigma larger where the points did not see.
  {
    std::vector<double> all, seen, unseen, unseen_over_seen;
    int calibrated = 0, larger_unseen = 0;
    for (const auto& r : rows)
      if (r.method == "spread" && std::isfinite(r.within_2sd)) {
        all.push_back(r.within_2sd), seen.push_back(r.within_2sd_seen),
            unseen.push_back(r.within_2sd_unseen);
        calibrated += r.within_2sd >= 0.9;
        larger_unseen += r.sigma_unseen_mm > r.sigma_seen_mm;
        unseen_over_seen.push_back(r.sigma_unseen_mm / r.sigma_seen_mm);
      }
    if (!all.empty()) {
      summary["uncertainty"] = {
          {"cases", all.size()},
          {"within_2sd_at_least_90pct", calibrated},
          {"sigma_larger_where_unseen", larger_unseen},
          {"median_within_2sd", median(all)},
          {"min_within_2sd", *std::min_element(all.begin(), all.end())},
          {"median_seen_within_2sd", median(seen)},
          {"median_unseen_within_2sd", median(unseen)},
          {"min_unseen_within_2sd", *std::min_element(unseen.begin(), unseen.end())},
          {"median_sigma_unseen_over_seen", median(unseen_over_seen)}};
      md += fmt::format(
          "\n## Uncertainty (ours): the true surface within 2 sigma\n\n{} cases: within 2 sigma "
          "on at least 90% of the surface in {}; share within 2 sigma median {:.3f} (least "
          "{:.3f}), seen half {:.3f}, unseen half {:.3f} (least {:.3f}); sigma larger on the "
          "unseen half in {} (median ratio {:.2f}).\n",
          all.size(), calibrated, median(all), *std::min_element(all.begin(), all.end()),
          median(seen), median(unseen), *std::min_element(unseen.begin(), unseen.end()),
          larger_unseen, median(unseen_over_seen));
    }
  }
  // The FEM cases: per load and magnitude, ours against the organ left as it was, TPS and
  // the paper's method, beside the FEM's own volume change.
  if (o.fem) {
    nlohmann::json per = nlohmann::json::array();
    md +=
        "\n## FEM ground truth (GetFEM, incompressible neo-Hookean; testdata/fem/fem_cases.py)\n\n"
        "| load | magnitude (mm) | cases | FEM volume change (%, largest) | median MSD (mm): "
        "none / ours / TPS / paper | median HD95 (mm): ours / TPS | ours' median volume "
        "change (%) | ours above none + 0.1 mm |\n|---|---|---|---|---|---|---|---|\n";
    for (const auto& f : families)
      for (double mag : magnitudes) {
        std::map<std::string, std::vector<double>> msd, hd, vol;
        std::vector<double> none;
        double fem_change = 0;
        int harm_cases = 0, n_cases = 0;
        for (const auto& r : rows) {
          if (r.family != f || r.magnitude_mm != mag) continue;
          msd[r.method].push_back(r.msd_mm), hd[r.method].push_back(r.hd95_mm),
              vol[r.method].push_back(r.volume_change_pct);
          if (r.method == "spread")
            ++n_cases, none.push_back(r.msd_undeformed_mm),
                harm_cases += r.msd_mm > r.msd_undeformed_mm + 0.1;
          fem_change = std::max(fem_change, std::abs(r.truth_volume_change_pct));
        }
        if (none.empty()) continue;
        md += fmt::format(
            "| {} | {:g} | {} | {:.1e} | {:.2f} / {:.2f} / {:.2f} / {:.2f} | {:.2f} / {:.2f} | "
            "{:+.2f} | {} |\n",
            f.substr(4), mag, n_cases, fem_change, median(none), median(msd["spread"]),
            median(msd["tps"]), median(msd["paper"]), median(hd["spread"]), median(hd["tps"]),
            median(vol["spread"]), harm_cases);
        per.push_back({{"load", f.substr(4)},
                       {"magnitude_mm", mag},
                       {"cases", n_cases},
                       {"fem_volume_change_pct_largest", fem_change},
                       {"median_msd_undeformed_mm", median(none)},
                       {"median_msd_mm",
                        {{"spread", median(msd["spread"])},
                         {"tps", median(msd["tps"])},
                         {"paper", median(msd["paper"])}}},
                       {"spread_worse_than_undeformed_plus_0_1mm", harm_cases}});
      }
    summary["fem"] = per;
    summary["fem_solves"] = fem_meshes;
  }
  write_file_atomically(o.out / "RESULTS.md", md);
  summary["targets"] = {{"cases", n},
                        {"msd_le_1mm", meet_msd},
                        {"hd95_le_2_5mm", meet_hd},
                        {"volume_le_1pct", meet_vol}};
  summary["wall_s"] = total.elapsed_s();
  folder.keep();
  return summary;
}

}  // namespace organfit::bench
