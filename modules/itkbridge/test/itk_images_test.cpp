#include "organfit/itkbridge/itk_images.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>

#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit::itkbridge {
namespace {

geometry::LabelVolume sample_mask() {
  geometry::ImageGeometry g;
  g.size = {7, 5, 4};
  g.spacing_mm = {0.8, 0.9, 2.5};
  g.origin_mm = {-10, 20, -300};
  g.direction = Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  geometry::LabelVolume m(g);
  m.at(1, 2, 3) = 1;
  m.at(6, 4, 0) = 3;
  return m;
}

TEST(ItkImages, LabelVolumeRoundTripsThroughEachFormatWithItsGeometry) {
  const geometry::LabelVolume m = sample_mask();
  const fs::path dir = fs::temp_directory_path() / ("organfit_itk_" + std::to_string(getpid()));
  fs::create_directories(dir);
  for (const char* name : {"m.nrrd", "m.mha", "m.nii.gz"}) {
    write_label_volume(dir / name, m);
    const geometry::LabelVolume back = read_label_volume(dir / name);
    EXPECT_EQ(back.labels, m.labels) << name;
    EXPECT_EQ(back.geometry.size, m.geometry.size) << name;
    EXPECT_LT((back.geometry.spacing_mm - m.geometry.spacing_mm).norm(), 1e-5) << name;
    EXPECT_LT((back.geometry.origin_mm - m.geometry.origin_mm).norm(), 1e-4) << name;
    EXPECT_LT((back.geometry.direction - m.geometry.direction).norm(), 1e-5) << name;
  }
  // Nothing but the three files: no temporary left behind.
  EXPECT_EQ(std::distance(fs::directory_iterator(dir), fs::directory_iterator()), 3);
  EXPECT_THROW(write_label_volume(dir / "m.xyz", m), InputError);
  EXPECT_THROW(write_label_volume("/nonexistent_dir/m.nrrd", m), InputError);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace organfit::itkbridge
