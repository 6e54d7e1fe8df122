#pragma once
// The scene schema of organfit: every key a scene may use, declared once, in
// src/scene_schema.cpp. `organfit schema` prints it. A key that sets a field of a
// stage's option struct is bound to it (config/binding.h): its default is the struct's.
#include <string>
#include <vector>

#include "organfit/config/binding.h"
#include "organfit/config/scene.h"
#include "organfit/evaluation/synthetic.h"
#include "organfit/fitting/organ_fit.h"
#include "organfit/phantom/pelvis.h"
#include "organfit/segmentation/segment.h"
#include "organfit/ultrasound/boundary_points.h"
#include "organfit/ultrasound/simulator.h"

namespace organfit::pipeline {

/// The scene keys bound to option structs, by section: each stage reads its struct with
/// them (`keys::fit_paper().read(scene)`).
namespace keys {
const config::Binding<fitting::OrganFitOptions>& fit();                 ///< fit
const config::Binding<fitting::PaperForceParams>& fit_paper();          ///< fit.paper
const config::Binding<fitting::AffineFitOptions>& fit_spread_global();  ///< fit.spread, global_*
const config::Binding<fitting::SpreadForceParams>& fit_spread_local();  ///< fit.spread, the rest
const config::Binding<fitting::ModelSettings>& model();                 ///< model
const config::Binding<phantom::PelvisOptions>& phantom();               ///< phantom
const config::Binding<segmentation::SeedOptions>& organ_seed();         ///< organ, source: seed
const config::Binding<evaluation::SamplingOptions>& points_sampling();  ///< points: noise
const config::Binding<evaluation::Deformation>& points_deformation();   ///< points: the truth
/// ultrasound, simulate: read over tissue_class_simulator_options (its defaults)
const config::Binding<ultrasound::SimulatorOptions>& ultrasound_simulator();
const config::Binding<ultrasound::BoundaryOptions>& ultrasound_boundary();  ///< the edge search
}  // namespace keys

/// The schema (built once, lives for the process).
const config::Schema& scene_schema();

/// Loads a scene file and applies the rules that tie keys together (m < n, ...).
/// Throws InputError "file:line: key: reason".
config::Scene load_and_check_scene(const std::filesystem::path& file,
                                   const std::vector<std::string>& overrides = {});

/// The cross-key rules alone (for scenes parsed from text in tests).
void check_scene_rules(const config::Scene& scene);

/// An entry of --out that a run of a scene writes.
struct SceneOutput {
  enum class Format { kAny, kImage, kMesh };  ///< its writer's: any name, ITK's, VTK's
  std::string name;                           ///< the entry (a folder ends in '/')
  std::string section, key;  ///< the key that names it; empty for the run's own entries
  std::string what;          ///< the run's own entry: what it is ("the run's record")
  Format format = Format::kAny;
};

/// The entries a run of `scene` writes: the run's own first (run.json, resolved.yaml,
/// history.csv with a fit, phantom/ with a phantom, cache/ with a DICOM node), then those its
/// keys name (export's files, ultrasound.save_volume, report.file; not the empty ones).
std::vector<SceneOutput> scene_outputs(const config::Scene& scene);

}  // namespace organfit::pipeline
