#pragma once
// The report stage: gathers what report.html shows from the run's stages.
#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "organfit/dicom/ct_series.h"
#include "organfit/evaluation/synthetic.h"
#include "organfit/fitting/embedded_body.h"
#include "organfit/fitting/surface_uncertainty.h"
#include "organfit/particles/state.h"

namespace organfit::pipeline {

struct ReportContext {
  nlohmann::json run;  ///< run.json as it will be written
  std::string scene_yaml, history_csv;
  const dicom::CtSeries* ct = nullptr;            ///< null: no CT views
  const geometry::Shape* planning = nullptr;      ///< the organ before the fit (its contour)
  const fitting::EmbeddedBody* fitted = nullptr;  ///< the organ after the fit (fitting::organ_body)
  double rho_mm = 0;                              ///< the particles' radius: the 3D view's voxel
  /// The fitted organ as the export made it, on the CT's grid and on the grid of rho
  /// (pipeline::PendingExport); null: made here from `fitted`.
  const geometry::LabelVolume* fitted_on_ct = nullptr;
  const geometry::LabelVolume* fitted_on_mesh_grid = nullptr;
  std::vector<Eigen::Vector3d> points_mm;
  std::vector<double> residuals_mm;
  /// The fit's uncertainty (null: none): the 3D view and the fitted contours coloured by it.
  const fitting::SurfaceUncertainty* uncertainty = nullptr;
  bool show_patient = false;  ///< the scene asked for name and ID
};

/// The report page. Views: the CT planes through the fitted organ's centroid, cropped to
/// both contours plus 25 mm.
std::string build_report(const ReportContext& context);

}  // namespace organfit::pipeline
