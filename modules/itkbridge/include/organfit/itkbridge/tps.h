#pragma once
// ITK's thin-plate spline (itk::ThinPlateSplineKernelTransform, 3D, U(r) = r) on plain
// arrays, for the evaluation's baseline. No Eigen here (see plain_image.h).
#include <array>
#include <memory>
#include <vector>

namespace organfit::itkbridge {

/// The spline taking `source` landmarks to `target` landmarks (same count, >= 4, not all
/// in a plane); apply() moves any point. Throws InputError on bad landmarks.
class ThinPlateSpline {
 public:
  ThinPlateSpline(const std::vector<std::array<double, 3>>& source,
                  const std::vector<std::array<double, 3>>& target);
  ~ThinPlateSpline();
  ThinPlateSpline(const ThinPlateSpline&) = delete;
  ThinPlateSpline& operator=(const ThinPlateSpline&) = delete;
  std::array<double, 3> apply(const std::array<double, 3>& p) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace organfit::itkbridge
