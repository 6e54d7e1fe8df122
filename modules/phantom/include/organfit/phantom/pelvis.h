#pragma once
// A synthetic male pelvis CT with known organs, for tests and the default scene.
//
// Analytic anatomy in patient coordinates (DICOM LPS, mm: +x patient left, +y posterior,
// +z superior), the prostate centred at the origin:
//   body outline (ellipse 350 x 230 mm), subcutaneous fat, muscle, a pelvic bone ring
//   (pubis in front at the prostate's level, sacrum behind above it, sciatic notches),
//   femoral heads and necks (cortical shell, cancellous inside), and inside the pelvic
//   cavity, in fat: the bladder (urine) resting on the prostate's base, the rectum
//   (wall, gas in its anterior lumen, faeces) 5 mm behind it, and a chestnut-shaped
//   prostate of about 35 cm3.
// CT values follow real scans, with the prostate's low soft-tissue contrast: prostate
// 42 HU against rectal wall 38, muscle 55 and urine 12 HU, fat -95. Each voxel averages
// its tissues (3 x 3 x 3 samples where tissues meet: partial volume), then Gaussian noise
// is added, drawn from the seed and the voxel's index (the same for any thread count).
// The true labels are the structures at voxel centres; true contours are traced on a
// finer in-plane grid, as a physician's drawing would be, not from the labels.
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "organfit/geometry/image_geometry.h"
#include "organfit/geometry/slice_contours.h"

namespace organfit::phantom {

/// Labels of the true label volume (0 = air outside the body).
enum PelvisLabel : std::uint8_t {
  kAir = 0,
  kSoftTissue = 1,  ///< fat and other tissue inside the body outline
  kMuscle = 2,
  kPelvicBone = 3,
  kFemurLeft = 4,
  kFemurRight = 5,
  kBladder = 6,
  kRectum = 7,  ///< wall and lumen (gas, faeces)
  kProstate = 8,
};

/// One structure of the phantom's RT Structure Set.
struct PelvisStructure {
  std::uint8_t label = 0;  ///< kAir stands for the body outline (every label but air)
  std::string name;        ///< ROI name, e.g. "Prostate"
  std::array<int, 3> colour{255, 0, 0};
  std::string interpreted_type;  ///< EXTERNAL, ORGAN
};

/// The structures written to the phantom's RT Structure Set, in ROI order.
const std::vector<PelvisStructure>& pelvis_structures();

struct PelvisOptions {
  std::uint64_t seed = 1;  ///< noise; the anatomy is the same for every seed
  int columns = 320;       ///< voxels along x (i)
  int rows = 320;          ///< voxels along y (j)
  int slices = 56;         ///< slices along z (k), centred on the prostate
  double pixel_mm = 1.25;  ///< in-plane spacing
  double slice_mm = 2.5;   ///< slice spacing and thickness
  double noise_hu = 12.0;  ///< standard deviation of the Gaussian noise
};

struct PelvisPhantom {
  geometry::ImageGeometry geometry;  ///< axial, identity direction
  std::vector<float> hu;             ///< Hounsfield units, i fastest
  geometry::LabelVolume labels;      ///< true labels at voxel centres (PelvisLabel)
  Eigen::Vector3d prostate_centre_mm = Eigen::Vector3d::Zero();
};

/// Builds the phantom. Throws std::invalid_argument on sizes below 8 voxels or
/// non-positive spacing.
PelvisPhantom make_pelvis_phantom(const PelvisOptions& options);

/// The tissue's label at a point (mm), from the analytic anatomy.
std::uint8_t pelvis_label_at(const Eigen::Vector3d& p_mm);

/// The true cross-sections of `structure` on each slice of `labels` (the phantom's true
/// labels, which bound where to look), traced from the analytic anatomy at `supersample`
/// times the in-plane resolution (vertex error below pixel / (2 supersample)). Contours'
/// k index the slices.
std::vector<geometry::SliceContour> pelvis_true_contours(const geometry::LabelVolume& labels,
                                                         const PelvisStructure& structure,
                                                         int supersample = 4);

}  // namespace organfit::phantom
