#include "organfit/itkbridge/tps.h"

#include <gtest/gtest.h>

#include <cmath>

#include "organfit/support/error.h"

namespace organfit::itkbridge {
namespace {

TEST(ThinPlateSpline, InterpolatesItsLandmarksAndRefusesTooFew) {
  std::vector<std::array<double, 3>> src, dst;
  for (int i = 0; i < 12; ++i) {
    const double a = 0.5 * i;
    src.push_back({10 * std::cos(a), 10 * std::sin(a), 2.0 * (i % 3)});
    dst.push_back({11 * std::cos(a), 10 * std::sin(a) + 1, 2.0 * (i % 3) + 0.1 * i});
  }
  const ThinPlateSpline tps(src, dst);
  for (size_t i = 0; i < src.size(); ++i) {
    const auto q = tps.apply(src[i]);
    for (int d = 0; d < 3; ++d)
      EXPECT_NEAR(q[d], dst[i][d], 1e-6);
  }
  EXPECT_THROW(ThinPlateSpline({{0, 0, 0}}, {{1, 1, 1}}), InputError);
}

}  // namespace
}  // namespace organfit::itkbridge
