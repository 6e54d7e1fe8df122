#include "organfit/pipeline/ultrasound_defaults.h"

namespace organfit::pipeline {

ultrasound::SimulatorOptions tissue_class_simulator_options() {
  ultrasound::SimulatorOptions so;
  // Echogenicity: anechoic fluid, hyperechoic fat, a hypoechoic gland.
  so.echogenicity.fill(0.5f);
  so.echogenicity[1] = 0.0f, so.echogenicity[2] = 0.9f, so.echogenicity[3] = 0.04f,
  so.echogenicity[4] = 0.5f;
  so.echogenicity[5] = 0.7f, so.echogenicity[6] = 1.0f, so.echogenicity[7] = 0.3f;
  so.organ_label = 7;
  so.probe_radius_mm = 12;  // a transrectal probe's face: it displaces the rectal gas
  return so;
}

ultrasound::ProbePose transrectal_probe_pose() {
  ultrasound::ProbePose pose;
  pose.position_mm = Eigen::Vector3d(0, 38, 0);  // in the rectum, posterior of the prostate
  pose.axis = Eigen::Vector3d(0, -1, 0);         // the beam anterior
  pose.lateral = Eigen::Vector3d(1, 0, 0);
  return pose;
}

}  // namespace organfit::pipeline
