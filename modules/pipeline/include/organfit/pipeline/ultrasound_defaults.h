#pragma once
// The ultrasound simulator's defaults as a scene states them: tissue classes' echogenicity
// and a transrectal probe. Apart from the ultrasound stage so that the scene schema, which
// declares them as keys' defaults, needs no ITK (the fuzzing build compiles it with clang).
#include "organfit/ultrasound/simulator.h"

namespace organfit::pipeline {

/// The simulator's settings for tissue classes (echogenicity per class; the organ is 7)
/// and a transrectal probe (its face 12 mm from its centre): the scene's defaults.
ultrasound::SimulatorOptions tissue_class_simulator_options();

/// A transrectal probe's pose relative to the prostate's centre (mm, patient LPS): 38 mm
/// posterior, the beam anterior, the image's lateral direction along x.
ultrasound::ProbePose transrectal_probe_pose();

}  // namespace organfit::pipeline
