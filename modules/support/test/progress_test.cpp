#include "organfit/support/progress.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <thread>

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

TEST_F(ProgressTest, AStepWithoutUpdatesStillShowsItsClockRunning) {
  // A long step between two updates (the global fit of a million particles: 7 s) gets
  // lines from the heartbeat at the interval, with the last state and a growing time.
  Progress::set_plain_interval_s(0.05);
  ::testing::internal::CaptureStderr();
  const auto start = std::chrono::steady_clock::now();
  {
    Progress p("fit: preparing", 6);
    p.update(3, "the global map");
    std::this_thread::sleep_for(std::chrono::milliseconds(400));
  }
  const double elapsed_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const std::string err = ::testing::internal::GetCapturedStderr();
  size_t beats = 0;
  for (size_t at = err.find("50% (3/6)"); at != std::string::npos;
       at = err.find("50% (3/6)", at + 1))
    ++beats;
  EXPECT_GE(beats, 3u) << err;  // about 8 in 0.4 s; at least 3 on a loaded machine
  EXPECT_LE(beats, elapsed_s / 0.05 + 1) << err;  // not more often than the interval
  EXPECT_NE(err.find("the global map"), std::string::npos) << err;
  EXPECT_NE(err.find("done\n"), std::string::npos) << err;
}

TEST_F(ProgressTest, UpdatesAtTheIntervalAreNotDoubledByTheHeartbeat) {
  Progress::set_plain_interval_s(0.1);
  ::testing::internal::CaptureStderr();
  const auto start = std::chrono::steady_clock::now();
  {
    Progress p("fit", 1000);
    for (int i = 1; i <= 50; ++i) {  // 0.5 s of updates every 10 ms
      p.update(i);
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
  const double elapsed_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const std::string err = ::testing::internal::GetCapturedStderr();
  const auto lines = static_cast<double>(std::count(err.begin(), err.end(), '\n'));
  EXPECT_GE(lines, 3) << err;
  // One a 0.1 s interval and the done line (about 6), never one per update (50).
  EXPECT_LE(lines, elapsed_s / 0.1 + 2) << err;
}

}  // namespace
}  // namespace organfit
