#include "organfit/support/progress.h"

#include <gtest/gtest.h>

namespace organfit {
namespace {

class ProgressTest : public ::testing::Test {
 protected:
  void SetUp() override {
    Progress::set_force_plain(true);
    Progress::set_plain_interval_s(0.0);
    Progress::set_enabled(true);
  }
  void TearDown() override {
    Progress::set_force_plain(false);
    Progress::set_plain_interval_s(5.0);
    Progress::set_enabled(true);
  }
};

TEST_F(ProgressTest, PlainModeWritesPercentLinesAndADoneLine) {
  ::testing::internal::CaptureStderr();
  {
    Progress p("fit", 200);
    p.update(50, "residual 0.4 mm");
    p.update(100);
  }
  const std::string err = ::testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("fit: 25% (50/200)"), std::string::npos) << err;
  EXPECT_NE(err.find("residual 0.4 mm"), std::string::npos);
  EXPECT_NE(err.find("fit: 50% (100/200)"), std::string::npos);
  EXPECT_NE(err.find("done\n"), std::string::npos);
  EXPECT_EQ(err.find('\r'), std::string::npos);  // no terminal redraws in logs
}

TEST_F(ProgressTest, DisabledProgressPrintsNothing) {
  Progress::set_enabled(false);
  ::testing::internal::CaptureStderr();
  {
    Progress p("relax", 10);
    p.update(5);
  }
  EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");
}

TEST_F(ProgressTest, AQuickStageThatNeverDrewPrintsNothingOnFinish) {
  Progress::set_plain_interval_s(1e9);
  ::testing::internal::CaptureStderr();
  {
    Progress p("relax", 10);
    p.update(10);
  }
  EXPECT_EQ(::testing::internal::GetCapturedStderr(), "");
}

}  // namespace
}  // namespace organfit
