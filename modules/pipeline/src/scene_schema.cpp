#include "organfit/pipeline/scene_schema.h"

#include <fmt/format.h>

#include <Eigen/LU>
#include <algorithm>
#include <initializer_list>

#include "organfit/dicomnet/node.h"
#include "organfit/pipeline/fit_stage.h"

namespace organfit::pipeline {
namespace {

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
              "pelvis: body, bones, bladder, rectum, a 35 cm3 prostate")
      .integer("seed", 1, 0, none, "seed of the CT noise (the anatomy is fixed)")
      .integer("columns", 320, 8, 2048, "voxels along x")
      .integer("rows", 320, 8, 2048, "voxels along y")
      .integer("slices", 56, 8, 2000, "slices along z, centred on the prostate")
      .number("pixel_mm", 1.25, "mm", 0.1, 10.0, "in-plane voxel spacing")
      .number("slice_mm", 2.5, "mm", 0.1, 20.0, "slice spacing and thickness")
      .number("noise_hu", 12.0, "HU", 0.0, 500.0, "standard deviation of the CT noise");

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
      .used_when({{"organ.source", {"rtstruct"}}})
      .vec3("seed_mm", Vector3d(0, 0, 0), "mm", none,
            "seed inside the organ, patient coordinates (source: seed)")
      .used_when({{"organ.source", {"seed"}}})
      .number("hu_low", 20.0, "HU", -1024.0, 3071.0, "lowest HU grown into (source: seed)")
      .used_when({{"organ.source", {"seed"}}})
      .number("hu_high", 80.0, "HU", -1024.0, 3071.0, "highest HU grown into (source: seed)")
      .used_when({{"organ.source", {"seed"}}})
      .integer("smoothing_iterations", 5, 0, 100,
               "curvature-flow iterations before growing (source: seed)")
      .used_when({{"organ.source", {"seed"}}})
      .integer("opening_radius_voxels", 1, 0, 10,
               "morphological opening that cuts thin leaks (source: seed)")
      .used_when({{"organ.source", {"seed"}}})
      .number("search_box_mm", 200.0, "mm", 0.0, 2000.0,
              "side of the cube around the seed the organ is grown in; 0 = the whole CT (source: "
              "seed)")
      .used_when({{"organ.source", {"seed"}}});

  s.section("body", "an analytic organ shape, for scenes without CT")
      .choice("shape", "ellipsoid", {"ellipsoid", "box", "egg", "lung"},
              "shape: egg = prostate-like (narrower apex at -x), lung = ellipsoid with a notch")
      .vec3("size_mm", Vector3d(24, 19, 15), "mm", 0.0, "full extent along x, y, z (diameters)",
            true)
      .vec3("centre_mm", Vector3d(0, 0, 0), "mm", none, "centre, in patient coordinates");

  s.section("model", "the particle model: cohesion (paper eq. 1-4), fill and relaxation")
      .number("radius_mm", 1.85, "mm", 0.0, 100.0,
              "particle radius rho; the LJ equilibrium distance r0 is 2 rho", true)
      .used_when({{"model.particles", {"0"}}})
      .integer("particles", 0, 0, 20000000,
               "about this many particles instead of radius_mm: the radius follows the body's "
               "volume (0: radius_mm sets it)")
      .number("cohesion_energy", 1.0, "E", 0.0, none, "well depth E0 of the LJ potential", true)
      .integer("exponent_m", 6, 1, 63, "attractive exponent m of the LJ law")
      .integer("exponent_n", 12, 2, 64, "repulsive exponent n of the LJ law (n > m)")
      .number("cutoff_r0", 2.5, "r0", 1.0, 5.0, "cutoff of the pair force, in r0", true)
      .number("floor_r0", 0.5, "r0", 0.0, 0.95,
              "below this distance the repulsion is linearised (finite forces)", true)
      .number("mass", 1.0, "M", 0.0, none, "mass of one particle", true)
      .number("damping_ratio", 0.5, "", 0.0, none,
              "damping K_a as a fraction of the critical 2 sqrt(k M) of one pair")
      .number("pair_damping", 0.0, "M/s", 0.0, none,
              "momentum-conserving pairwise damping coefficient (0 = off)")
      .number("neighbour_skin_r0", 0.3, "r0", 0.0, 2.0, "Verlet skin of the neighbour list", true)
      .number("time_step_fraction", 0.1, "", 0.0, 0.9,
              "time step as a fraction of the stability limit 2 sqrt(M/k)", true)
      .integer("relax_steps", 5000, 0, 10000000,
               "most steps of the damped relaxation after filling")
      .number("relax_tolerance", 1e-6, "E", 0.0, none,
              "relaxation ends when kinetic energy per particle falls below this", true)
      .flag("skeleton", true, "tie the particles to a medial skeleton that keeps the global shape")
      .number("skeleton_stiffness", 0.2, "k", 0.0, none,
              "skeleton stiffness k_s as a fraction of the LJ stiffness k = m n E0 / r0^2", true)
      .number("skeleton_node_spacing_r0", 3.0, "r0", 0.0, none,
              "distance between skeleton nodes on the medial axis", true)
      .number("skeleton_overlap_r0", 0.5, "r0", 0.0, none,
              "a particle also joins nodes this much farther than its nearest one");
  s.section("points", "attractive points: generated on a known deformation of the body, or read")
      .choice("source", "generate", {"generate", "file", "ultrasound"},
              "generate on the deformed body (truth known), read from points.file, or segment the "
              "'ultrasound'")
      .input_path("file",
                  "points in mm: CSV x,y,z[,confidence], or the vertices of a .ply/.vtk/.vtp "
                  "(source: file)",
                  false)
      .used_when({{"points.source", {"file"}}})
      .integer("count", 87, 1, 100000, "number of points to generate")
      .used_when({{"points.source", {"generate", "ultrasound"}}})
      .number("noise_mm", 0.5, "mm", 0.0, 20.0, "Gaussian noise added to generated points")
      .used_when({{"points.source", {"generate"}}})
      .number("outlier_fraction", 0.0, "", 0.0, 0.5,
              "fraction of generated points moved 5-15 mm off")
      .used_when({{"points.source", {"generate"}}})
      .choice("coverage", "full", {"full", "half"}, "surface the points cover (half: the +y side)")
      .used_when({{"points.source", {"generate"}}})
      .number("stretch", 1.0, "", 0.5, 2.0,
              "volume-preserving stretch along x of the true deformation")
      .used_when({{"points.source", {"generate"}}})
      .used_when({{"points.source", {"ultrasound"}}, {"ultrasound.source", {"simulate"}}})
      .number("bend_mm", 0.0, "mm", -30.0, 30.0,
              "sideways (y) displacement of the ends in the true deformation")
      .used_when({{"points.source", {"generate"}}})
      .used_when({{"points.source", {"ultrasound"}}, {"ultrasound.source", {"simulate"}}})
      .number("twist_deg", 0.0, "deg", -90.0, 90.0,
              "turn of the ends about the x axis in the true deformation")
      .used_when({{"points.source", {"generate"}}})
      .used_when({{"points.source", {"ultrasound"}}, {"ultrasound.source", {"simulate"}}})
      .number("indent_mm", 0.0, "mm", -20.0, 20.0,
              "Gaussian column shift along y (rectal filling: < 0 moves it anteriorly)")
      .used_when({{"points.source", {"generate"}}})
      .used_when({{"points.source", {"ultrasound"}}, {"ultrasound.source", {"simulate"}}})
      .number("push_mm", 0.0, "mm", -20.0, 20.0,
              "Gaussian column shift along z (bladder push: < 0 moves it inferiorly)")
      .used_when({{"points.source", {"generate"}}})
      .used_when({{"points.source", {"ultrasound"}}, {"ultrasound.source", {"simulate"}}})
      .number("bump_sigma_mm", 8.0, "mm", 1.0, 100.0, "width of the indent and push bumps", true)
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
      .vec3("probe_offset_mm", Vector3d(0, 38, 0), "mm", none,
            "probe position from the organ's centre (simulate)")
      .used_when({{"ultrasound.source", {"simulate"}}})
      .vec3("probe_axis", Vector3d(0, -1, 0), "", none,
            "beam direction (simulate; default: anterior, transrectal)")
      .used_when({{"ultrasound.source", {"simulate"}}})
      .vec3("probe_lateral", Vector3d(1, 0, 0), "", none,
            "image's lateral direction, perpendicular to the axis")
      .used_when({{"ultrasound.source", {"simulate"}}})
      .number("probe_radius_mm", 12.0, "mm", 0.0, 50.0,
              "imaging starts this far from the probe's centre (its face; it displaces rectal gas)")
      .used_when({{"ultrasound.source", {"simulate"}}})
      .number("max_depth_mm", 70.0, "mm", 10.0, 300.0,
              "imaging depth from the probe's centre (simulate)")
      .used_when({{"ultrasound.source", {"simulate"}}})
      .number("half_angle_deg", 50.0, "deg", 5.0, 80.0,
              "half-angle of the field of view (simulate)")
      .used_when({{"ultrasound.source", {"simulate"}}})
      .number("speckle", 1.0, "", 0.0, 1.0,
              "speckle level: 0 none, 1 fully developed Rayleigh (simulate)")
      .used_when({{"ultrasound.source", {"simulate"}}})
      .number("voxel_mm", 0.5, "mm", 0.1, 5.0, "voxel size of the simulated volume", true)
      .used_when({{"ultrasound.source", {"simulate"}}})
      .integer("rays", 2000, 16, 100000, "edge-search rays from the organ's centre")
      .number("band_mm", 8.0, "mm", 1.0, 100.0,
              "search band around the model's surface along each ray")
      .number("smoothing_mm", 1.0, "mm", 0.0, 10.0,
              "Gaussian speckle reduction before the edge search")
      .number("mad_threshold", 3.0, "", 1.0, 20.0,
              "a ray's boundary radius this many MADs off its neighbours' is rejected")
      .text("save_volume", "",
            "file name inside --out for the ultrasound volume used (.mha, .nrrd; empty: none)");

  s.section("fit", "deform the model onto the attractive points (paper s.3)")
      .choice("method", "spread", {"paper", "spread"},
              "paper = the literal method with METHOD s.8's fixes; spread = ours (docs/method.md)")
      .flag("measure_truth", true,
            "measure the fit against the known deformation the points came from (run.json "
            "truth; 0.5 mm voxels over the organ: tens of seconds for a lung)")
      .used_when({{"points.source", {"generate"}}})
      .used_when({{"points.source", {"ultrasound"}}, {"ultrasound.source", {"simulate"}}})
      .number("residual_tolerance_mm", 0.5, "mm", 0.0, none,
              "converged when the mean data residual is at most this", true)
      .number("residual_max_tolerance_mm", 0.0, "mm", 0.0, none,
              "... and the 95th percentile at most this (0 = the particle radius)")
      .integer("max_steps", 20000, 1, 100000000, "step budget")
      .number("max_wall_s", 60.0, "s", 0.0, none, "wall-time budget", true)
      .integer("record_every", 20, 1, 100000, "steps between history rows")
      .number("damping_ratio", 0.5, "", 0.0, none, "damping during the fit, fraction of critical",
              true)
      .number("kinetic_tolerance", 1e-4, "E", 0.0, none,
              "settled when KE per particle is below this", true)
      .number("alpha", 2.0, "", 1.0, 20.0, "fall-off exponent alpha_k of eq. 5")
      .used_when({{"fit.method", {"paper"}}})
      .number("influence_radius_min_r0", 1.2, "r0", 0.0, none, "influence radius at contact", true)
      .used_when({{"fit.method", {"paper"}}})
      .number("influence_growth", 0.5, "", 0.0, none, "extra influence radius per mm of distance")
      .used_when({{"fit.method", {"paper"}}})
      .number("influence_radius_max_r0", 4.0, "r0", 0.0, none, "bound on the influence radius",
              true)
      .used_when({{"fit.method", {"paper"}}})
      .number("total_force_factor", 3.0, "", 1.0, none, "a point's total force <= this x F_max_k")
      .used_when({{"fit.method", {"paper"}}})
      .number("outlier_distance_mm", 0.0, "mm", 0.0, none,
              "reject points farther than this from the model (0 = half its diameter)")
      .used_when({{"fit.method", {"paper"}}})
      .number("skin_voxel_r0", 0.5, "r0", 0.0, none, "voxel size of skin detection (0.5 r0 = rho)",
              true)
      .number("max_global_stretch", 1.5, "", 1.0, 10.0,
              "spread: refuse points that ask the whole organ to stretch more than this")
      .used_when({{"fit.method", {"spread"}}})
      .number("unseen_change_sd_mm", 1.7, "mm", 0.0, 50.0,
              "the uncertainty's prior: how far the surface may change locally where no point "
              "is (1.7 mm: the prostate between fractions, Nakazawa et al. 2015)",
              true)
      .number("global_shear_field_mm", 10.0, "mm", 0.0, 100.0,
              "spread: width of the smooth shears the global map may add (0 = none)")
      .used_when({{"fit.method", {"spread"}}});
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
          "field_spacing_mm", 0.0, "mm", 0.0, 50.0,
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
      .flag("fixed_uids", false,
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

}  // namespace

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
      scene.fail("model", "radius_mm",
                 "the model needs a body to fill: add an 'organ' or a 'body' section");
    }
    if (scene.integer("model", "particles") == 1)  // 0 is "radius_mm sets it"
      scene.fail("model", "particles", "a model needs at least 2 particles");
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
    for (const char* key : {"rtstruct", "labels", "mesh", "model", "displacement_field",
                            "registration", "jacobian", "uncertainty"}) {
      const std::string& name = scene.text("export", key);
      if (name.find('/') != std::string::npos || name == "." || name == "..")
        scene.fail("export", key, "a file name inside --out, without folders");
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
  if (scene.has_section("fit")) {
    if (!has_model) scene.fail("fit", "method", "a fit needs a 'model' (or 'planning') section");
    if (!scene.has_section("points")) scene.fail("fit", "method", "a fit needs a 'points' section");
  }
  check_network_rules(scene);
}

config::Scene load_and_check_scene(const std::filesystem::path& file,
                                   const std::vector<std::string>& overrides) {
  config::Scene scene = config::load_scene(file, scene_schema(), overrides);
  check_scene_rules(scene);
  return scene;
}

}  // namespace organfit::pipeline
