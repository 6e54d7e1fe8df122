// ITK translation unit: plain arrays only.
#include "organfit/itkbridge/tps.h"

#include <itkPointSet.h>
#include <itkThinPlateSplineKernelTransform.h>

#include "organfit/support/error.h"

namespace organfit::itkbridge {

struct ThinPlateSpline::Impl {
  using Transform = itk::ThinPlateSplineKernelTransform<double, 3>;
  Transform::Pointer transform = Transform::New();
};

ThinPlateSpline::ThinPlateSpline(const std::vector<std::array<double, 3>>& source,
                                 const std::vector<std::array<double, 3>>& target)
    : impl_(std::make_unique<Impl>()) {
  if (source.size() != target.size() || source.size() < 4)
    throw InputError(
        "thin-plate spline: needs the same number (at least 4) of source and target landmarks");
  using PointSet = Impl::Transform::PointSetType;
  auto src = PointSet::New(), dst = PointSet::New();
  for (size_t i = 0; i < source.size(); ++i) {
    PointSet::PointType a, b;
    for (int d = 0; d < 3; ++d)
      a[d] = source[i][d], b[d] = target[i][d];
    src->SetPoint(static_cast<PointSet::PointIdentifier>(i), a);
    dst->SetPoint(static_cast<PointSet::PointIdentifier>(i), b);
  }
  impl_->transform->SetSourceLandmarks(src);
  impl_->transform->SetTargetLandmarks(dst);
  try {
    impl_->transform->ComputeWMatrix();
  } catch (const itk::ExceptionObject&) {
    throw InputError("thin-plate spline: the landmarks give a singular system");
  }
}

ThinPlateSpline::~ThinPlateSpline() = default;

std::array<double, 3> ThinPlateSpline::apply(const std::array<double, 3>& p) const {
  Impl::Transform::InputPointType in;
  for (int d = 0; d < 3; ++d)
    in[d] = p[d];
  const auto out = impl_->transform->TransformPoint(in);
  return {out[0], out[1], out[2]};
}

}  // namespace organfit::itkbridge
