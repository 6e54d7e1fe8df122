#include "organfit/fitting/robust.h"

#include <gtest/gtest.h>

#include <cmath>

namespace organfit::fitting {
namespace {

TEST(OutlierCutoff, MedianPlusScaledMad) {
  // median 3, |v - 3| = {2, 1, 0, 1, 97}: MAD 1.
  EXPECT_NEAR(outlier_cutoff({1, 2, 3, 4, 100}, 3.0), 3.0 + 3 * 1.4826, 1e-12);
  EXPECT_TRUE(std::isinf(outlier_cutoff({}, 3.0)));
  EXPECT_NEAR(outlier_cutoff({5, 5, 5, 5}, 2.0, 0.5), 5.0 + 2 * 1.4826 * 0.5, 1e-12);
}

}  // namespace
}  // namespace organfit::fitting
