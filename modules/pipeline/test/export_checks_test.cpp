// The export's checks of the organ on the CT's grid (export_stage.h): its volume against
// the planning organ's moved by the fit, where the CT's field of view cut the planning
// organ and the fit draws in what lay beyond it.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>

#include "organfit/dicom/ct_series.h"
#include "organfit/fitting/embedded_body.h"
#include "organfit/pipeline/export_stage.h"

namespace organfit::pipeline {
namespace {

// A cylinder of 10 mm radius along z through the whole of a CT of 1 x 1 x 2.5 mm voxels
// (30 slices: the CT cut it at both ends), its particles on a lattice of 3 mm within it,
// moved by a volume-preserving map that shortens it by 10% along z (and widens it by
// 1/sqrt(0.9)) about the CT's middle. Today's end slices come from beyond the field of view
// (where the organ goes on as deep as it is on the CT's last plane: a dome): counted on
// every grid and left out of the comparison, today's organ from within the field of view is
// the planning organ's volume; counted with it, the copies' mean was 24.86 cm3 against an
// expected 24.26 (tolerance 0.45), and the volume "not kept".
TEST(ExportChecks, CountTheOrganDrawnInFromBeyondTheFieldOfView) {
  dicom::CtSeries ct;
  ct.geometry.size = {40, 40, 30};
  ct.geometry.spacing_mm = Eigen::Vector3d(1, 1, 2.5);
  ct.geometry.origin_mm = Eigen::Vector3d(-19.5, -19.5, 0);
  const geometry::ImageGeometry& g = ct.geometry;
  auto mask = std::make_shared<geometry::LabelVolume>(g);
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i)
        mask->at(i, j, k) = g.index_to_physical(Eigen::Vector3d(i, j, k)).head<2>().norm() <= 10;
  std::vector<Eigen::Vector3d> sites;
  for (double z = 1.5; z < 72; z += 3)
    for (double y = -9; y <= 9; y += 3)
      for (double x = -9; x <= 9; x += 3)
        if (std::hypot(x, y) <= 8.5) sites.emplace_back(x, y, z);
  particles::Positions x0(3, static_cast<Eigen::Index>(sites.size()));
  for (size_t s = 0; s < sites.size(); ++s)
    x0.col(static_cast<Eigen::Index>(s)) = sites[s];

  fitting::GlobalMap map;
  const double c = 0.9, middle_z = 0.5 * (g.size[2] - 1) * g.spacing_mm.z();
  map.affine.a = Eigen::Vector3d(1 / std::sqrt(c), 1 / std::sqrt(c), c).asDiagonal();
  map.affine.t = Eigen::Vector3d(0, 0, (1 - c) * middle_z);
  particles::Positions placed(3, x0.cols());
  for (Eigen::Index s = 0; s < x0.cols(); ++s)
    placed.col(s) = map.apply(x0.col(s));
  const fitting::EmbeddedBody organ(mask, map, placed, placed, fitting::embedding_support_mm(3));

  ExportRequest request;
  request.labels = "organ.nrrd";
  request.roi_name = "Organ_fit";
  const PendingExport out = prepare_export(organ, 1.5, &ct, request);
  const nlohmann::json& checks = out.summary["checks"];
  const double planning_cm3 = checks["planning_volume_on_ct_grid_cm3"].get<double>();
  const double beyond_cm3 = checks["from_beyond_ct_cm3"].get<double>();
  // On the CT's grid, one slice's worth (0.87 cm3 today) of dome at each end: the slice
  // 2.8 mm beyond, 6.3 mm in radius there.
  EXPECT_GT(beyond_cm3, 0.4);
  EXPECT_LT(beyond_cm3, 1.2);
  EXPECT_NEAR(checks["expected_volume_on_ct_grid_cm3"].get<double>(), planning_cm3 + beyond_cm3,
              1e-9);
  // The CT's grid alone is 6% off (a slice of 30 at each end, by its phase): the copies'
  // mean of today's organ from within the field of view is the planning organ's.
  const nlohmann::json& shifted = checks["volume_on_shifted_grids"];
  ASSERT_TRUE(shifted.is_object()) << checks.dump();
  EXPECT_NEAR(shifted["mean_cm3"].get<double>(), planning_cm3, 0.005 * planning_cm3);
  EXPECT_TRUE(checks["volume_kept"].get<bool>()) << checks.dump();
  ASSERT_EQ(out.warnings.size(), 1u);
  EXPECT_NE(out.warnings[0].find("came onto the CT's grid from beyond its field of view "
                                 "(inferior 0."),
            std::string::npos)
      << out.warnings[0];
  EXPECT_NE(out.warnings[0].find("superior 0."), std::string::npos) << out.warnings[0];
}

}  // namespace
}  // namespace organfit::pipeline
