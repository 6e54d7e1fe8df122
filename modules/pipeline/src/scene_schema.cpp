#include "organfit/pipeline/scene_schema.h"

#include <fmt/format.h>

#include <Eigen/LU>
#include <algorithm>
#include <initializer_list>
#include <map>
#include <string>
#include <string_view>

#include "organfit/dicomnet/node.h"
#include "organfit/itkbridge/itk_images.h"
#include "organfit/meshing/plain_mesh.h"
#include "organfit/pipeline/export_stage.h"
#include "organfit/pipeline/fit_stage.h"
#include "organfit/pipeline/model_stage.h"
#include "organfit/pipeline/ultrasound_defaults.h"

namespace organfit::pipeline {
namespace keys {

const config::Binding<fitting::OrganFitOptions>& fit() {
  using O = fitting::OrganFitOptions;
  constexpr auto none = std::nullopt;
  static const auto b =
      config::Binding<O>("fit")
          .number("residual_tolerance_mm", &O::residual_tolerance_mm, "mm", 0.0, none,
                  "the points' noise: converged when the mean data residual is at most this; the "
                  "global map keeps the share of its change the points show beyond it",
                  true)
          .number("residual_max_tolerance_mm", &O::residual_max_tolerance_mm, "mm", 0.0, none,
                  "... and the 95th percentile at most this (0 = the particle radius, or 2.46 x "
                  "the mean's tolerance where larger: what points of that noise give)")
          .integer("max_steps", &O::max_steps, 1, 100000000, "step budget")
          .number("max_wall_s", &O::max_wall_s, "s", 0.0, none, "wall-time budget", true)
          .integer("record_every", &O::record_every, 1, 100000, "steps between history rows")
          .number("damping_ratio", &O::damping_ratio, "", 0.0, none,
                  "damping during the fit, fraction of critical", true)
          .number("kinetic_tolerance", &O::kinetic_tolerance, "E", 0.0, none,
                  "settled when KE per particle is below this", true)
          .number("skin_voxel_r0", &O::skin_voxel_r0, "r0", 0.0, none,
                  "voxel size of skin detection (0.5 r0 = rho)", true)
          .number("unseen_change_sd_mm", &O::unseen_change_sd_mm, "mm", 0.0, 50.0,
                  "the uncertainty's prior: how far the surface may change locally where no "
                  "point is (1.7 mm: the prostate between fractions, Nakazawa et al. 2015)",
                  true)
          .number("unseen_motion_sd_mm", &O::unseen_motion_sd_mm, "mm", 0.0, 500.0,
                  "the uncertainty's prior: how far the whole organ may have moved since "
                  "planning where the points do not tell (4 mm: the prostate between fractions, "
                  "1.5 to 4.1 mm SD per axis, Langen and Jones 2001)",
                  true)
          .number("volume_tolerance_pct", &O::volume_tolerance_pct, "%", 0.0, 100.0,
                  "the organ's volume change a fit may make (either way): beyond it the spread "
                  "fit's local stage is undone, and the run warns",
                  true);
  return b;
}

const config::Binding<fitting::PaperForceParams>& fit_paper() {
  using O = fitting::PaperForceParams;
  constexpr auto none = std::nullopt;
  static const auto b =
      config::Binding<O>("fit.paper")
          .number("alpha", &O::alpha, "", 1.0, 20.0, "fall-off exponent alpha_k of eq. 5")
          .number("influence_radius_min_r0", &O::influence_radius_min_r0, "r0", 0.0, none,
                  "influence radius at contact", true)
          .number("influence_growth", &O::influence_growth, "", 0.0, none,
                  "extra influence radius per mm of distance")
          .number("influence_radius_max_r0", &O::influence_radius_max_r0, "r0", 0.0, none,
                  "bound on the influence radius (>= influence_radius_min_r0)", true)
          .number("total_force_factor", &O::total_force_factor, "", 1.0, none,
                  "a point's total force <= this x F_max_k")
          .number("outlier_distance_mm", &O::outlier_distance_mm, "mm", 0.0, none,
                  "reject points farther than this from the model (0 = half its diameter)")
          .number("first_shell_r0", &O::first_shell_r0, "r0", 1.0, 2.0,
                  "W(i), the force cap's neighbour count, counts neighbours within this");
  return b;
}

const config::Binding<fitting::AffineFitOptions>& fit_spread_global() {
  using O = fitting::AffineFitOptions;
  static const auto b =
      config::Binding<O>("fit.spread")
          .number("max_global_stretch", &O::max_stretch, "", 1.0, 10.0,
                  "refuse points that ask the whole organ to stretch more than this (or less "
                  "than its inverse)")
          .number("global_max_shear", &O::max_shear_mm, "", 0.0, 10.0,
                  "... or whose shears, shear fields or flow move the surface by more than this "
                  "x the body's size",
                  true)
          .number("max_global_shift_mm", &O::max_shift_mm, "mm", 0.0, 1000.0,
                  "... or that move the whole organ (its surface's mean move) further than this: "
                  "points in other coordinates or units",
                  true)
          .number("global_shear_field_mm", &O::field_sigma_mm, "mm", 0.0, 100.0,
                  "width and spacing of the smooth shear fields the global map may add (0 = "
                  "none; else at least 1 mm)")
          .number("global_field_stiffness", &O::field_stiffness, "", 0.0, 100.0,
                  "pull of the fields' heights towards none (a prior sd of 0.5 mm / sqrt(this))")
          .number("global_flow_mm", &O::flow_sigma_mm, "mm", 0.0, 100.0,
                  "node spacing of an incompressible flow the global map may add, for changes "
                  "of shape no shear makes (a cube into a lung; 0 = none; else at least 1 mm)")
          .integer("global_iterations", &O::iterations, 1, 1000,
                   "iterations of the global map's robust fit")
          .number("global_outlier_mads", &O::outlier_mads, "", 0.0, 100.0,
                  "points beyond the median residual + this x 1.4826 MAD get no weight", true)
          .number("global_point_to_point", &O::point_to_point, "", 0.0, 10.0,
                  "weight of the point-to-point term beside point-to-plane")
          .number("global_regularisation", &O::regularisation, "", 0.0, 1.0,
                  "pull of the affine part towards the identity, relative to the points' spread")
          .number("global_regularisation_alternative", &O::regularisation_alternative, "", 0.0, 1.0,
                  "a second pull also tried, the better fit kept (0 = none)")
          .number("global_shear_regularisation", &O::shear_regularisation, "", 0.0, 1.0,
                  "pull of the quadratic shears towards none")
          .number("global_equally_good_dof", &O::equally_good_dof, "", 0.0, 1000.0,
                  "fits within this / (points) of the best's mean square are equally good; the "
                  "one changing the shape least is kept")
          .number("global_distance_scale_mm", &O::distance_scale_mm, "mm", 0.0, 50.0,
                  "robust scale of the fit on the signed distance (Geman-McClure)", true)
          .number("global_few_points_shear_stiffness", &O::few_points_shear_stiffness, "", 0.0,
                  1000.0,
                  "with fewer points than the map's 21 unknowns, the shears are also fitted this "
                  "much stiffer (0 = not)");
  return b;
}

const config::Binding<fitting::SpreadForceParams>& fit_spread_local() {
  using O = fitting::SpreadForceParams;
  constexpr auto none = std::nullopt;
  static const auto b =
      config::Binding<O>("fit.spread")
          .number("local_stiffness", &O::stiffness_fraction, "k", 0.0, 10.0,
                  "a patch's stiffness kappa, as a fraction of the LJ stiffness m n E0 / r0^2",
                  true)
          .number("local_patch_sigma_r0", &O::patch_sigma_r0, "r0", 0.0, 20.0,
                  "Gaussian width of a point's patch", true)
          .number("local_patch_radius_r0", &O::patch_radius_r0, "r0", 0.0, 50.0,
                  "bound of a point's patch", true)
          .flag("local_hold_volume", &O::hold_volume,
                "take the patches' net outward push back over the skin (keeps the volume)")
          .flag("local_hold_pose", &O::hold_pose,
                "take the local stage's net force and torque back over the whole body (the "
                "organ's position and turn stay the global stage's)")
          .number("outlier_distance_mm", &O::outlier_distance_mm, "mm", 0.0, none,
                  "reject points farther than this from the model (0 = half its diameter)")
          .number("consistency_threshold", &O::consistency_threshold, "", 0.0, 100.0,
                  "reject a point whose residual is this many times its neighbours' scatter "
                  "off theirs (0 = no such test)")
          .integer("consistency_neighbours", &O::consistency_neighbours, 1, 1000,
                   "neighbours of a point for that test")
          .number("consistency_noise_mm", &O::consistency_noise_mm, "mm", 0.0, 50.0,
                  "the residuals' noise in that test (0 = half the particle radius)");
  return b;
}

const config::Binding<fitting::ModelSettings>& model() {
  using O = fitting::ModelSettings;
  constexpr auto none = std::nullopt;
  static const auto b =
      config::Binding<O>("model")
          .number("radius_mm", &O::radius_mm, "mm", 0.0, 100.0,
                  "particle radius rho; the LJ equilibrium distance r0 is 2 rho (0: it follows "
                  "the body's volume, for model.particles)")
          .number("cohesion_energy", &O::cohesion_energy, "E", 0.0, none,
                  "well depth E0 of the LJ potential", true)
          .integer("exponent_m", &O::exponent_m, 1, 63, "attractive exponent m of the LJ law")
          .integer("exponent_n", &O::exponent_n, 2, 64,
                   "repulsive exponent n of the LJ law (n > m)")
          .number("cutoff_r0", &O::cutoff_r0, "r0", 1.0, 5.0, "cutoff of the pair force, in r0",
                  true)
          .number("floor_r0", &O::floor_r0, "r0", 0.0, 0.95,
                  "below this distance the repulsion is linearised (finite forces)", true)
          .number("mass", &O::mass, "M", 0.0, none, "mass of one particle", true)
          .number("damping_ratio", &O::damping_ratio, "", 0.0, none,
                  "damping K_a as a fraction of the critical 2 sqrt(k M) of one pair")
          .number("pair_damping", &O::pair_damping, "M/s", 0.0, none,
                  "momentum-conserving pairwise damping coefficient (0 = off)")
          .number("neighbour_skin_r0", &O::neighbour_skin_r0, "r0", 0.0, 2.0,
                  "Verlet skin of the neighbour list", true)
          .number("time_step_fraction", &O::time_step_fraction, "", 0.0, 0.9,
                  "time step as a fraction of the stability limit 2 sqrt(M/k)", true)
          .integer("relax_steps", &O::relax_steps, 0, 10000000,
                   "most steps of the relaxation (FIRE) after filling")
          .number("relax_tolerance", &O::relax_tolerance, "E", 0.0, none,
                  "relaxation ends when the rms force per particle is K_a sqrt(2 this / M) or less "
                  "(the damping's force on a particle of this kinetic energy)",
                  true)
          .flag("skeleton", &O::skeleton,
                "tie the particles to a medial skeleton that keeps the global shape")
          .number("skeleton_stiffness", &O::skeleton_stiffness, "k", 0.0, none,
                  "skeleton stiffness k_s as a fraction of the LJ stiffness k = m n E0 / r0^2",
                  true)
          .number("skeleton_node_spacing_r0", &O::skeleton_node_spacing_r0, "r0", 0.0, none,
                  "distance between skeleton nodes on the medial axis", true)
          .number("skeleton_overlap_r0", &O::skeleton_overlap_r0, "r0", 0.0, none,
                  "a particle also joins nodes this much farther than its nearest one");
  return b;
}

const config::Binding<phantom::PelvisOptions>& phantom() {
  using O = phantom::PelvisOptions;
  constexpr auto none = std::nullopt;
  static const auto b =
      config::Binding<O>("phantom")
          .integer("seed", &O::seed, 0, none, "seed of the CT noise (the anatomy is fixed)")
          .integer("columns", &O::columns, 8, 2048, "voxels along x")
          .integer("rows", &O::rows, 8, 2048, "voxels along y")
          .integer("slices", &O::slices, 8, 2000, "slices along z, centred on the prostate")
          .number("pixel_mm", &O::pixel_mm, "mm", 0.1, 10.0, "in-plane voxel spacing")
          .number("slice_mm", &O::slice_mm, "mm", 0.1, 20.0, "slice spacing and thickness")
          .number("noise_hu", &O::noise_hu, "HU", 0.0, 500.0, "standard deviation of the CT noise");
  return b;
}

const config::Binding<segmentation::SeedOptions>& organ_seed() {
  using O = segmentation::SeedOptions;
  constexpr auto none = std::nullopt;
  const std::vector<config::UseCondition> seed = {{"organ.source", {"seed"}}};
  static const auto b =
      config::Binding<O>("organ")
          .vec3("seed_mm", &O::seed_mm, "mm", none,
                "seed inside the organ, patient coordinates (source: seed)")
          .used_when(seed)
          .number("hu_low", &O::hu_low, "HU", -1024.0, 3071.0,
                  "lowest HU grown into (source: seed)")
          .used_when(seed)
          .number("hu_high", &O::hu_high, "HU", -1024.0, 3071.0,
                  "highest HU grown into (source: seed)")
          .used_when(seed)
          .integer("smoothing_iterations", &O::smoothing_iterations, 0, 100,
                   "curvature-flow iterations before growing (source: seed)")
          .used_when(seed)
          .integer("opening_radius_voxels", &O::opening_radius_voxels, 0, 10,
                   "morphological opening that cuts thin leaks (source: seed)")
          .used_when(seed)
          .number("search_box_mm", &O::search_box_mm, "mm", 0.0, 2000.0,
                  "side of the cube around the seed the organ is grown in; 0 = the whole CT "
                  "(source: seed)")
          .used_when(seed);
  return b;
}

const config::Binding<evaluation::SamplingOptions>& points_sampling() {
  using O = evaluation::SamplingOptions;
  static const auto b = config::Binding<O>("points")
                            .number("noise_mm", &O::noise_mm, "mm", 0.0, 20.0,
                                    "Gaussian noise added to generated points")
                            .used_when({{"points.source", {"generate"}}})
                            .number("outlier_fraction", &O::outlier_fraction, "", 0.0, 0.5,
                                    "fraction of generated points moved 5-15 mm off")
                            .used_when({{"points.source", {"generate"}}});
  return b;
}

const config::Binding<evaluation::Deformation>& points_deformation() {
  using O = evaluation::Deformation;
  // The true deformation: of the generated points, or of the simulated ultrasound.
  const std::vector<config::UseCondition> generate = {{"points.source", {"generate"}}};
  const std::vector<config::UseCondition> simulate = {{"points.source", {"ultrasound"}},
                                                      {"ultrasound.source", {"simulate"}}};
  static const auto b =
      config::Binding<O>("points")
          .number("stretch", &O::stretch, "", 0.5, 2.0,
                  "volume-preserving stretch along x of the true deformation")
          .used_when(generate)
          .used_when(simulate)
          .number("bend_mm", &O::bend_mm, "mm", -30.0, 30.0,
                  "sideways (y) displacement of the ends in the true deformation")
          .used_when(generate)
          .used_when(simulate)
          .number("indent_mm", &O::indent_mm, "mm", -20.0, 20.0,
                  "Gaussian column shift along y (rectal filling: < 0 moves it anteriorly)")
          .used_when(generate)
          .used_when(simulate)
          .number("push_mm", &O::push_mm, "mm", -20.0, 20.0,
                  "Gaussian column shift along z (bladder push: < 0 moves it inferiorly)")
          .used_when(generate)
          .used_when(simulate)
          .number("bump_sigma_mm", &O::bump_sigma_mm, "mm", 1.0, 100.0,
                  "width of the indent and push bumps", true)
          .used_when(generate)
          .used_when(simulate);
  return b;
}

const config::Binding<ultrasound::SimulatorOptions>& ultrasound_simulator() {
  using O = ultrasound::SimulatorOptions;
  const std::vector<config::UseCondition> simulate = {{"ultrasound.source", {"simulate"}}};
  static const auto b =
      config::Binding<O>("ultrasound")
          .number("probe_radius_mm", &O::probe_radius_mm, "mm", 0.0, 50.0,
                  "imaging starts this far from the probe's centre (its face; it displaces "
                  "rectal gas)")
          .used_when(simulate)
          .number("max_depth_mm", &O::max_depth_mm, "mm", 10.0, 300.0,
                  "imaging depth from the probe's centre (simulate)")
          .used_when(simulate)
          .number("speckle", &O::speckle, "", 0.0, 1.0,
                  "speckle level: 0 none, 1 fully developed Rayleigh (simulate)")
          .used_when(simulate)
          .number("voxel_mm", &O::voxel_mm, "mm", 0.1, 5.0, "voxel size of the simulated volume",
                  true)
          .used_when(simulate);
  return b;
}

const config::Binding<ultrasound::BoundaryOptions>& ultrasound_boundary() {
  using O = ultrasound::BoundaryOptions;
  static const auto b =
      config::Binding<O>("ultrasound")
          .integer("rays", &O::rays, 16, 100000, "edge-search rays from the organ's centre")
          .number("band_mm", &O::band_mm, "mm", 1.0, 100.0,
                  "search band around the model's surface along each ray")
          .number("smoothing_mm", &O::smoothing_mm, "mm", 0.0, 10.0,
                  "Gaussian speckle reduction before the edge search")
          .number("mad_threshold", &O::mad_threshold, "", 1.0, 20.0,
                  "a ray's boundary radius this many MADs off its neighbours' is rejected");
  return b;
}

}  // namespace keys

namespace {

/// The finest shear fields and flow nodes of the global map (mm), 0 aside (none).
constexpr double kLeastGlobalBasisMm = 1.0;

config::Schema build_schema() {
  using Eigen::Vector3d;
  constexpr auto none = std::nullopt;
  config::Schema s;

  s.section("scene", "what this run is: name, seed, threads", /*always_present=*/true)
      .text("name", "", "name shown in run.json and the report (default: the file's stem)")
      .text("description", "", "one line saying what the scene does")
      .integer("seed", 1, 0, none, "seed of every random choice (same seed, same result)")
      .integer("threads", 0, 0, 256, "worker threads; 0 = all cores")
      .number("max_wall_s", 0.0, "s", 0.0, none,
              "wall-time budget of the whole run, every stage included (0 = none); past it the "
              "run stops, writes nothing and exits 3");

  s.section("planning", "start from a saved planning model instead of building one (a session)")
      .input_path("model", "model file written by a planning scene's export.model");

  s.section("phantom",
            "a synthetic planning CT with known organs, written to OUT/phantom/ and read as the CT")
      .choice("kind", "pelvis", {"pelvis"},
              "pelvis: body, bones, bladder, rectum, a 35 cm3 prostate");
  keys::phantom().declare(s);

  s.section("ct",
            "the planning CT: a DICOM folder (other objects in it are ignored), or a series "
            "pulled from a DICOM node")
      .input_path("folder", "folder holding the CT series (or ct.node)", false)
      .text("node", "",
            "DICOM node to pull the CT from instead: AET@host:port (C-FIND, then C-GET into "
            "OUT/cache/ct/)")
      .text("study_uid", "", "Study Instance UID of the CT on ct.node")
      .text("patient_id", "",
            "or the Patient ID on ct.node: its CT series are listed by C-FIND (never logged)")
      .text("series_uid", "",
            "Series Instance UID to use when the folder, the study or the patient holds several "
            "CT series")
      .text("series_description", "", "or the Series Description to use (ct.folder)");

  s.section("organ",
            "the organ on the planning CT: imported from an RT Structure Set, or grown from a seed")
      .choice("source", "rtstruct", {"rtstruct", "seed"},
              "rtstruct: a physician's contour (organ.rtstruct, organ.roi); seed: region growing "
              "from organ.seed_mm")
      .input_path("rtstruct",
                  "the RT Structure Set file (default with a phantom: its true structures)", false)
      .used_when({{"organ.source", {"rtstruct"}}})
      .text("roi", std::nullopt,
            "the organ's ROI name: the one imported, or the name given to the segmented organ")
      .integer("roi_number", 0, 0, none,
               "ROI Number to import when several ROIs share the name (0: by name alone)")
      .used_when({{"organ.source", {"rtstruct"}}})
      .text("node", "",
            "DICOM node to pull the RT Structure Set from instead of organ.rtstruct: "
            "AET@host:port (the CT's study is searched; C-GET into OUT/cache/rtstruct/)")
      .used_when({{"organ.source", {"rtstruct"}}})
      .text("series_uid", "",
            "Series Instance UID of the structure set on organ.node (default: the study's only "
            "RTSTRUCT series)")
      .used_when({{"organ.source", {"rtstruct"}}});
  keys::organ_seed().declare(s);

  s.section("body", "an analytic organ shape, for scenes without CT")
      .choice("shape", "ellipsoid", {"ellipsoid", "box", "egg", "lung"},
              "shape: egg = prostate-like (narrower apex at -x), lung = ellipsoid with a notch")
      .vec3("size_mm", Vector3d(24, 19, 15), "mm", 0.0, "full extent along x, y, z (diameters)",
            true)
      .vec3("centre_mm", Vector3d(0, 0, 0), "mm", none, "centre, in patient coordinates");

  s.section("model", "the particle model: cohesion (paper eq. 1-4), fill and relaxation")
      .integer("particles", pipeline::kDefaultParticleCount, 2, pipeline::kMostParticles,
               "about this many particles, whatever the organ's size: the radius follows its "
               "volume (the default's accuracy and time: docs/benchmarks.md)")
      .used_when({{"model.radius_mm", {"0"}}});
  keys::model().declare(s);
  s.section("points", "attractive points: generated on a known deformation of the body, or read")
      .choice("source", "generate", {"generate", "file", "ultrasound"},
              "generate on the deformed body (truth known), read from points.file, or segment the "
              "'ultrasound'")
      .input_path("file",
                  "points in mm: CSV x,y,z[,confidence], 3D Slicer's markups (.fcsv), or the "
                  "vertices of a .ply/.vtk/.vtp (source: file)",
                  false)
      .used_when({{"points.source", {"file"}}})
      .integer("count", evaluation::SamplingOptions{}.count, 1, 100000,
               "number of points to generate")
      .used_when({{"points.source", {"generate", "ultrasound"}}});
  keys::points_sampling().declare(s);
  s.choice("coverage", evaluation::SamplingOptions{}.half_coverage ? "half" : "full",
           {"full", "half"}, "surface the points cover (half: the +y side)")
      .used_when({{"points.source", {"generate"}}});
  keys::points_deformation().declare(s);
  s.number("twist_deg", evaluation::Deformation{}.twist_rad * 180 / M_PI, "deg", -90.0, 90.0,
           "turn of the ends about the x axis in the true deformation")
      .used_when({{"points.source", {"generate"}}})
      .used_when({{"points.source", {"ultrasound"}}, {"ultrasound.source", {"simulate"}}})
      .choice("target_shape", "same", {"same", "ellipsoid", "box", "egg", "lung"},
              "sample a different shape than the body (same = the body, deformed)")
      .used_when({{"points.source", {"generate"}}})
      .vec3("target_size_mm", Eigen::Vector3d(40, 30, 60), "mm", 0.0,
            "target_shape's proportions; scaled to the body's volume", true)
      .used_when({{"points.source", {"generate"}}});

  s.section("ultrasound",
            "the day's ultrasound, segmented into attractive points (points.source: ultrasound)")
      .choice("source", "simulate", {"simulate", "volume", "sweep", "dicom"},
              "simulate: B-mode of the planning CT with the organ deformed by "
              "points.stretch/bend_mm (truth "
              "known); volume: a 3D image; sweep: a tracked 2D sweep (PLUS sequence metafile); "
              "dicom: DICOM US")
      .input_path("file",
                  "the ultrasound input (volume .mha/.nrrd/.nii, sequence metafile, or .dcm)",
                  false)
      .used_when({{"ultrasound.source", {"volume", "sweep", "dicom"}}})
      .input_path("tracker",
                  "sequence metafile with the probe's poses, matched by timestamp (source: sweep)",
                  false)
      .used_when({{"ultrasound.source", {"sweep"}}})
      .text("transform", "",
            "tracked transform name (default: the file's own, e.g. ProbeToTrackerTransform)")
      .used_when({{"ultrasound.source", {"sweep"}}})
      .matrix4("calibration", "image (mm) to probe: the probe's calibration (sweep, dicom)")
      .used_when({{"ultrasound.source", {"sweep", "dicom"}}})
      .matrix4("registration",
               "tracker (or volume) to CT patient coordinates; rigid (volume, sweep, dicom)")
      .used_when({{"ultrasound.source", {"volume", "sweep", "dicom"}}})
      .number("pixel_mm", 0.0, "mm", 0.0, 10.0,
              "pixel size of a DICOM image without a calibrated region (0: from it)")
      .used_when({{"ultrasound.source", {"dicom"}}})
      .vec3("probe_offset_mm", transrectal_probe_pose().position_mm, "mm", none,
            "probe position from the organ's centre (simulate)")
      .used_when({{"ultrasound.source", {"simulate"}}})
      .vec3("probe_axis", transrectal_probe_pose().axis, "", none,
            "beam direction (simulate; default: anterior, transrectal)")
      .used_when({{"ultrasound.source", {"simulate"}}})
      .vec3("probe_lateral", transrectal_probe_pose().lateral, "", none,
            "image's lateral direction, perpendicular to the axis")
      .used_when({{"ultrasound.source", {"simulate"}}})
      .number("half_angle_deg", tissue_class_simulator_options().lateral_half_angle_deg, "deg", 5.0,
              80.0, "half-angle of the field of view (simulate)")
      .used_when({{"ultrasound.source", {"simulate"}}});
  keys::ultrasound_simulator().declare(s, tissue_class_simulator_options());
  keys::ultrasound_boundary().declare(s);
  s.text("save_volume", "",
         "file name inside --out for the ultrasound volume used (.mha, .nrrd; empty: none)");

  s.section("fit", "deform the model onto the attractive points (paper s.3)")
      .choice("method", "spread", {"paper", "spread"},
              "paper = the literal method with METHOD s.8's fixes (fit.paper); spread = ours "
              "(fit.spread, docs/method.md)")
      .flag("measure_truth", true,
            "measure the fit against the known deformation the points came from (run.json "
            "truth; 0.5 mm voxels over the organ: tens of seconds for a lung)")
      .used_when({{"points.source", {"generate"}}})
      .used_when({{"points.source", {"ultrasound"}}, {"ultrasound.source", {"simulate"}}});
  keys::fit().declare(s);
  s.subsection("paper", "the paper's attractive force (eq. 5-6, METHOD s.8's fixes)",
               {{"fit.method", {"paper"}}});
  keys::fit_paper().declare(s);
  s.subsection("spread",
               "our method: a volume-preserving global map, then local patches (docs/method.md)",
               {{"fit.method", {"spread"}}});
  keys::fit_spread_global().declare(s);
  keys::fit_spread_local().declare(s);
  s.section("network", "organfit on the DICOM network: for ct.node, organ.node, export.send_to")
      .text("aet", dicomnet::NetworkOptions{}.calling_aet,
            "our own AE title, as the nodes know us (1-16 characters)")
      .number("timeout_s", dicomnet::NetworkOptions{}.timeout_s, "s", 0.0, 600.0,
              "connecting, negotiating and each message: a node slower than this has failed", true);
  s.section("export", "what to write for the planning system, on the planning CT's grid")
      .text("rtstruct", "", "DICOM RT Structure Set file name inside --out (empty: none)")
      .text("labels", "", "label map file name inside --out: .nrrd, .mha, .nii(.gz) (empty: none)")
      .text("mesh", "", "surface mesh file name inside --out: .stl, .vtp, .ply, .obj (empty: none)")
      .text("displacement_field", "",
            "deformation field file name inside --out, .mha or .nrrd, on the planning CT's grid: "
            "phi^-1(q) - q in mm, as plastimatch warp --xf reads it (empty: none)")
      .text("registration", "",
            "DICOM Deformable Spatial Registration file name inside --out: the same field, "
            "on the planning CT's grid and Frame of Reference (empty: none)")
      .number(
          "field_spacing_mm", ExportRequest{}.field_spacing_mm, "mm", 0.0, 50.0,
          "grid of the displacement field, registration and Jacobian: 0, the planning CT's; "
          "else this spacing on every axis over the CT's box (warp with plastimatch --fixed CT)")
      .text("jacobian", "",
            "det(grad phi) file name inside --out, .nrrd or .mha, on the planning CT's grid "
            "(empty: none)")
      .text("uncertainty", "",
            "sigma file name inside --out, .nrrd or .mha, on the planning CT's grid: the "
            "standard deviation (mm) of where the true surface may lie (run.json "
            "fit.uncertainty; needs a fit; empty: none)")
      .text("roi_name", "", "name of the exported ROI (default: the organ's ROI name + _fit)")
      .vec3("roi_color", Eigen::Vector3d(-1, -1, -1), "", -1.0,
            "display colour R, G, B (0-255) of the exported ROI; [-1, -1, -1]: the source ROI's")
      .flag("copy_other_rois", false,
            "copy the organ's structure set's other ROIs into the exported one (not the "
            "fitted ROI's source, which it replaces)")
      .flag("fixed_uids", ExportRequest{}.fixed_uids,
            "derive the RT Structure Set's UIDs from the CT's and fix its dates (tests)")
      .text("model", "",
            "model file name inside --out (empty: none): the model as built, or as fitted, "
            "for session scenes (planning.model) and organfit export")
      .text("send_to", "",
            "DICOM node the written RT Structure Set and registration are sent to by C-STORE "
            "once the run has succeeded: AET@host:port (empty: none)");
  s.section("report", "report.html: one self-contained page a physicist reads at a glance")
      .text("file", "report.html", "report file name inside --out")
      .flag("show_patient", false,
            "show the CT's patient name and ID in the report (also needs --show-phi)");
  return s;
}

/// A node's address, checked as the scene is (the node itself is only asked at run time).
void check_node(const config::Scene& scene, const char* section, const char* key) {
  try {
    dicomnet::parse_node(scene.text(section, key), std::string(section) + "." + key);
  } catch (const InputError& e) {
    const std::string m = e.what();
    scene.fail(section, key, m.substr(m.find(": ") + 2));
  }
}

/// The DICOM node keys: a node replaces a folder or file (never both), names what to pull,
/// and the network section is there only when a node is used.
void check_network_rules(const config::Scene& scene) {
  auto node_given = [&scene](const char* section, const char* key) {
    return scene.has_section(section) && scene.is_given(section, key);
  };
  const bool ct_node = node_given("ct", "node");
  if (scene.has_section("ct")) {
    if (ct_node == scene.is_given("ct", "folder"))
      scene.fail("ct", ct_node ? "node" : "folder",
                 ct_node ? "the CT comes from ct.folder or from ct.node, not both"
                         : "name the CT's folder (ct.folder) or a DICOM node (ct.node)");
    if (ct_node) {
      check_node(scene, "ct", "node");
      if (!scene.is_given("ct", "study_uid") && !scene.is_given("ct", "patient_id"))
        scene.fail("ct", "node", "name the CT's study (ct.study_uid) or patient (ct.patient_id)");
      if (scene.is_given("ct", "series_description"))
        scene.fail("ct", "series_description",
                   "chooses among a folder's series; on a node, name ct.series_uid");
    } else {
      for (const char* key : {"study_uid", "patient_id"})
        if (scene.is_given("ct", key)) scene.fail("ct", key, "used only with ct.node");
    }
  }
  const bool organ_node = node_given("organ", "node");
  if (organ_node) {
    check_node(scene, "organ", "node");
    if (scene.is_given("organ", "rtstruct"))
      scene.fail("organ", "node",
                 "the structure set comes from organ.rtstruct or organ.node, not both");
    if (!scene.has_section("ct"))
      scene.fail("organ", "node",
                 "the structure set is looked for in the study of the ct section's CT");
  } else if (node_given("organ", "series_uid")) {
    scene.fail("organ", "series_uid", "used only with organ.node");
  }
  const bool send = node_given("export", "send_to");
  if (send) {
    check_node(scene, "export", "send_to");
    if (scene.text("export", "rtstruct").empty() && scene.text("export", "registration").empty())
      scene.fail("export", "send_to",
                 "sends export.rtstruct and export.registration, neither of which is written");
  }
  if (scene.has_section("network")) {
    if (!ct_node && !organ_node && !send)
      scene.fail("network", "",
                 "no DICOM node is used (ct.node, organ.node, export.send_to): remove the "
                 "section");
    try {
      dicomnet::check_ae_title(scene.text("network", "aet"), "network.aet");
    } catch (const InputError& e) {
      const std::string m = e.what();
      scene.fail("network", "aet", m.substr(m.find(": ") + 2));
    }
  }
}

/// The keys that name an output, with their writer's formats.
struct OutputKey {
  const char* section;
  const char* key;
  SceneOutput::Format format;
};
constexpr OutputKey kOutputKeys[] = {{"export", "rtstruct", SceneOutput::Format::kAny},
                                     {"export", "labels", SceneOutput::Format::kImage},
                                     {"export", "mesh", SceneOutput::Format::kMesh},
                                     {"export", "model", SceneOutput::Format::kAny},
                                     {"export", "displacement_field", SceneOutput::Format::kImage},
                                     {"export", "registration", SceneOutput::Format::kAny},
                                     {"export", "jacobian", SceneOutput::Format::kImage},
                                     {"export", "uncertainty", SceneOutput::Format::kImage},
                                     {"ultrasound", "save_volume", SceneOutput::Format::kImage},
                                     {"report", "file", SceneOutput::Format::kAny}};

/// Each output its own visible name in --out: two outputs of one name, or one with the name
/// of the run's own files, leave one of them (a model named run.json was overwritten by the
/// run's record, exit 0); a hidden one is not replaced by the next run into the folder. And
/// a name its writer knows the format of, said before the run (m.STL was refused after the
/// fit, when the mesh was written).
void check_output_names(const config::Scene& scene) {
  const std::vector<SceneOutput> outputs = scene_outputs(scene);
  std::map<std::string, const SceneOutput*> taken;
  for (const SceneOutput& o : outputs) {
    std::string name = o.name;
    if (!name.empty() && name.back() == '/') name.pop_back();
    if (o.key.empty()) {  // the run's own (first): names a key may not take
      taken.emplace(name, &o);
      continue;
    }
    const char* section = o.section.c_str();
    const char* key = o.key.c_str();
    const std::string format =
        o.format == SceneOutput::Format::kImage  ? itkbridge::image_file_name_problem(name)
        : o.format == SceneOutput::Format::kMesh ? meshing::mesh_file_name_problem(name)
                                                 : std::string();
    if (!format.empty()) scene.fail(section, key, name + ": " + format);
    if (name.front() == '.')
      scene.fail(section, key, "a visible file name in --out (not starting with '.')");
    const auto [it, fresh] = taken.emplace(name, &o);
    if (!fresh) {
      const SceneOutput& other = *it->second;
      scene.fail(section, key,
                 fmt::format("'{}' is already {}'s name in --out", name,
                             other.key.empty() ? other.what : other.section + "." + other.key));
    }
  }
}

}  // namespace

std::vector<SceneOutput> scene_outputs(const config::Scene& scene) {
  std::vector<SceneOutput> out = {{"run.json", "", "", "the run's record"},
                                  {"resolved.yaml", "", "", "the resolved scene"}};
  if (scene.has_section("fit")) out.push_back({"history.csv", "", "", "the fit's history"});
  if (scene.has_section("phantom")) out.push_back({"phantom/", "", "", "the phantom's folder"});
  if ((scene.has_section("ct") && scene.is_given("ct", "node")) ||
      (scene.has_section("organ") && scene.is_given("organ", "node")))
    out.push_back({"cache/", "", "", "the DICOM node's cache"});
  for (const OutputKey& k : kOutputKeys)
    if (scene.has_section(k.section) && !scene.text(k.section, k.key).empty())
      out.push_back({scene.text(k.section, k.key), k.section, k.key, "", k.format});
  return out;
}

const config::Schema& scene_schema() {
  static const config::Schema schema = build_schema();
  return schema;
}

void check_scene_rules(const config::Scene& scene) {
  if (scene.has_section("export")) {
    const Eigen::Vector3d c = scene.vec3("export", "roi_color");
    const bool source = c == Eigen::Vector3d(-1, -1, -1);
    if (!source && ((c.array() < 0).any() || (c.array() > 255).any() ||
                    (c.array() != c.array().round()).any()))
      scene.fail("export", "roi_color",
                 "three integers from 0 to 255 (or [-1, -1, -1] for the source ROI's colour)");
  }
  if (scene.has_section("planning")) {
    for (const char* section : {"phantom", "organ", "body", "model"})
      if (scene.has_section(section))
        scene.fail(
            section, "",
            fmt::format("a session starts from planning.model: it has no '{}' section", section));
  }
  if (scene.has_section("model")) {
    const auto m = scene.integer("model", "exponent_m");
    const auto n = scene.integer("model", "exponent_n");
    if (m >= n) {
      scene.fail(
          "model", scene.is_given("model", "exponent_n") ? "exponent_n" : "exponent_m",
          fmt::format("the repulsive exponent n ({}) must exceed the attractive m ({})", n, m));
    }
    const double rmin = std::pow(double(n + 1) / double(m + 1), 1.0 / double(n - m));
    if (scene.number("model", "cutoff_r0") <= rmin) {
      scene.fail("model", "cutoff_r0",
                 fmt::format("must exceed r_min = {:.4f} r0 for m={}, n={}, else nothing holds "
                             "the body together",
                             rmin, m, n));
    }
    if (!scene.has_section("body") && !scene.has_section("organ")) {
      scene.fail("model", scene.is_given("model", "radius_mm") ? "radius_mm" : "particles",
                 "the model needs a body to fill: add an 'organ' or a 'body' section");
    }
  }
  const bool has_model = scene.has_section("model") || scene.has_section("planning");
  if (scene.has_section("phantom") && scene.has_section("ct"))
    scene.fail("phantom", "kind",
               "a scene has either a 'phantom' or a 'ct' section: the phantom is the CT");
  const bool has_ct = scene.has_section("ct") || scene.has_section("phantom");
  if (scene.has_section("organ")) {
    if (!has_ct) scene.fail("organ", "roi", "an organ needs the 'ct' (or 'phantom') it is on");
    const bool seeded = scene.text("organ", "source") == "seed";
    if (!seeded && !scene.is_given("organ", "rtstruct") && !scene.is_given("organ", "node") &&
        !scene.has_section("phantom"))
      scene.fail("organ", "rtstruct",
                 "source is 'rtstruct' but neither organ.rtstruct nor organ.node is given");
    if (seeded && !scene.is_given("organ", "seed_mm"))
      scene.fail("organ", "seed_mm", "source is 'seed' but organ.seed_mm is not given");
    if (seeded && scene.number("organ", "hu_low") >= scene.number("organ", "hu_high"))
      scene.fail("organ", "hu_high", "must exceed organ.hu_low");
  }
  if (scene.has_section("points")) {
    if (scene.text("points", "source") == "file" && !scene.is_given("points", "file")) {
      scene.fail("points", "source", "source is 'file' but points.file is not given");
    }
    // The file's contents are checked now, before any work (a bad line fails validate).
    if (scene.text("points", "source") == "file")
      (void)read_points_file(scene.path("points", "file"));
    if (scene.text("points", "source") == "ultrasound" && !scene.has_section("ultrasound"))
      scene.fail("points", "source",
                 "source is 'ultrasound' but the scene has no 'ultrasound' section");
    if (scene.text("points", "source") == "generate" && !scene.has_section("body") &&
        !scene.has_section("organ") && !scene.has_section("planning")) {
      scene.fail("points", "source",
                 "generated points need the 'organ' or 'body' they are sampled from");
    }
  }
  if (scene.has_section("export")) {
    auto writes = [&](std::initializer_list<const char*> keys) {
      return std::any_of(keys.begin(), keys.end(),
                         [&](const char* key) { return !scene.text("export", key).empty(); });
    };
    const bool deformation_files = writes({"displacement_field", "registration", "jacobian"});
    // A session finds its planning CT through the model file.
    if (!has_ct && !scene.has_section("planning") &&
        (writes({"rtstruct", "labels"}) || deformation_files))
      scene.fail("export", "rtstruct",
                 "an RTSTRUCT, label map or deformation field is written on the planning CT: "
                 "add a 'ct' section");
    if (!has_model)
      scene.fail("export", "rtstruct", "export needs a 'model' (or 'planning') to export");
    if (!writes({"rtstruct", "labels", "mesh", "model", "uncertainty"}) && !deformation_files)
      scene.fail("export", "rtstruct",
                 "the export section names nothing to write (rtstruct, labels, mesh, "
                 "displacement_field, registration, jacobian, uncertainty or model)");
    if (scene.flag("export", "copy_other_rois") &&
        !(scene.has_section("planning") ||
          (scene.has_section("organ") && scene.text("organ", "source") == "rtstruct")))
      scene.fail("export", "copy_other_rois",
                 "copies from the organ's structure set: needs organ.source rtstruct (or a "
                 "planning model whose organ came from one)");
    if (scene.flag("export", "copy_other_rois") && scene.text("export", "rtstruct").empty())
      scene.fail("export", "copy_other_rois",
                 "copies ROIs into export.rtstruct, which is not given");
    if (scene.is_given("export", "field_spacing_mm") && !deformation_files)
      scene.fail("export", "field_spacing_mm",
                 "sets the grid of export.displacement_field, registration and jacobian, none "
                 "of which is written");
    if (writes({"uncertainty"}) && !scene.has_section("fit"))
      scene.fail("export", "uncertainty", "the uncertainty is the fit's: add a 'fit' section");
    if (writes({"uncertainty"}) && !has_ct && !scene.has_section("planning"))
      scene.fail("export", "uncertainty", "written on the planning CT's grid: add a 'ct' section");
    if (const std::string why = roi_name_problem(scene.text("export", "roi_name")); !why.empty())
      scene.fail("export", "roi_name", why);
    for (const OutputKey& k : kOutputKeys) {
      if (std::string_view(k.section) != "export") continue;
      const std::string& name = scene.text("export", k.key);
      if (name.find('/') != std::string::npos || name == "." || name == "..")
        scene.fail("export", k.key, "a file name inside --out, without folders");
    }
  }
  if (scene.has_section("ultrasound")) {
    const bool simulate = scene.text("ultrasound", "source") == "simulate";
    if (!scene.has_section("points") || scene.text("points", "source") != "ultrasound")
      scene.fail("ultrasound", "source", "the ultrasound is used by points.source: ultrasound");
    if (simulate && !(has_ct && scene.has_section("organ")))
      scene.fail("ultrasound", "source",
                 "simulating needs the planning CT (ct or phantom) and the organ");
    if (!simulate && !scene.is_given("ultrasound", "file"))
      scene.fail("ultrasound", "file",
                 "source is '" + scene.text("ultrasound", "source") +
                     "' but ultrasound.file is not given");
    const Eigen::Matrix4d reg = scene.matrix4("ultrasound", "registration");
    const Eigen::Matrix3d rot = reg.topLeftCorner<3, 3>();
    if ((rot.transpose() * rot - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-3 ||
        rot.determinant() < 0 || reg.row(3) != Eigen::RowVector4d(0, 0, 0, 1))
      scene.fail("ultrasound", "registration",
                 "not a rigid transform (a rotation and a translation, last row 0 0 0 1)");
    const std::string& name = scene.text("ultrasound", "save_volume");
    if (name.find('/') != std::string::npos || name == "." || name == "..")
      scene.fail("ultrasound", "save_volume", "a file name inside --out, without folders");
  }
  if (scene.has_section("report")) {
    const std::string& file = scene.text("report", "file");
    if (file.empty() || file.find('/') != std::string::npos || file == "." || file == "..")
      scene.fail("report", "file", "a file name inside --out, without folders");
    if (scene.flag("report", "show_patient") && !has_ct && !scene.has_section("planning"))
      scene.fail("report", "show_patient", "the patient's name comes from the CT: there is none");
  }
  if (scene.has_section("fit") && scene.text("fit", "method") == "paper") {
    const double low = scene.number("fit.paper", "influence_radius_min_r0");
    const double high = scene.number("fit.paper", "influence_radius_max_r0");
    if (low > high)
      scene.fail("fit.paper",
                 scene.is_given("fit.paper", "influence_radius_max_r0") ? "influence_radius_max_r0"
                                                                        : "influence_radius_min_r0",
                 fmt::format("the influence radius's bound ({} r0) is below its value at contact "
                             "({} r0)",
                             high, low));
  }
  if (scene.has_section("fit") && scene.text("fit", "method") == "spread") {
    // The global map is the organ's change at its own scale; change finer than a millimetre
    // is the local stage's. Fields of 0.02 mm over a prostate took 96 s and 10 GB, 0.01 mm
    // ran out of memory, and a flow of 0.05 mm took 12 GB.
    for (const char* key : {"global_shear_field_mm", "global_flow_mm"})
      if (const double v = scene.number("fit.spread", key); v > 0 && v < kLeastGlobalBasisMm)
        scene.fail("fit.spread", key,
                   fmt::format("{:g} mm is finer than the global map resolves: 0 (none) or at "
                               "least {:g} mm (the local stage fits finer change)",
                               v, kLeastGlobalBasisMm));
  }
  if (scene.has_section("fit")) {
    if (!has_model) scene.fail("fit", "method", "a fit needs a 'model' (or 'planning') section");
    if (!scene.has_section("points")) scene.fail("fit", "method", "a fit needs a 'points' section");
  }
  check_output_names(scene);
  check_network_rules(scene);
}

config::Scene load_and_check_scene(const std::filesystem::path& file,
                                   const std::vector<std::string>& overrides) {
  config::Scene scene = config::load_scene(file, scene_schema(), overrides);
  check_scene_rules(scene);
  return scene;
}

}  // namespace organfit::pipeline
