// run_command on a stop: the stop is thrown only once every process of the command's group has
// ended, so that none writes after the caller has removed what it wrote into; one that ignores
// SIGTERM is killed by the watchdog, which then ends the process with the stop's one line. Each
// test runs in a process of its own (a death test): a stop is process-wide.
#include "organfit/support/interrupt.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <new>
#include <string>
#include <thread>

#include "organfit/support/error.h"

namespace fs = std::filesystem;

namespace organfit {
namespace {

fs::path scratch(const std::string& name) {
  const fs::path path =
      fs::temp_directory_path() / ("organfit_interrupt_" + name + std::to_string(::getpid()));
  fs::remove(path);
  return path;
}

/// SIGTERM to this process `seconds` from now (taken by the watchdog: every other thread
/// has it blocked).
void terminate_after(double seconds) {
  std::thread([seconds] {
    std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
    ::kill(::getpid(), SIGTERM);
  }).detach();
}

/// Ends the death test's process: 0 when `ok` and `stop` is the signal's.
[[noreturn]] void end_stopped(const Error& stop, bool ok) {
  mark_finishing();
  std::_Exit(ok && stop.code() == ExitCode::kInterrupted ? 0 : 1);
}

TEST(RunCommandDeathTest, ThrowsTheStopOnlyOnceTheCommandsCleanUpHasEnded) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  const fs::path cleaned = scratch("cleaned");
  EXPECT_EXIT(
      {
        install_interrupt_handlers();
        terminate_after(0.3);
        // dash forks the inner shell (a command follows it) and itself ends at once on
        // SIGTERM; the inner shell cleans up for 0.2 s, then writes `cleaned`.
        try {
          run_command("sh -c 'trap \"sleep 0.2; : > " + cleaned.string() +
                      "; exit 0\" TERM; while :; do sleep 0.05; done'; :");
        } catch (const Error& stop) {
          end_stopped(stop, fs::exists(cleaned));
        }
        std::_Exit(2);  // the command ended by itself: it never does
      },
      ::testing::ExitedWithCode(0), "");
  fs::remove(cleaned);
}

TEST(RunCommandDeathTest, ACommandThatIgnoresTheStopIsKilledAndTheProcessEndsWithOneLine) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(
      {
        install_interrupt_handlers();
        terminate_after(0.3);
        // The inner shell and its sleeps ignore SIGTERM: run_command must not return while
        // they live; the watchdog kills them kStopGrace after the signal and ends the run.
        // (Bounded to 10 s and off this test's pipes, should one outlive a failed test.)
        try {
          run_command(
              "sh -c 'trap \"\" TERM; i=0; while [ $i -lt 200 ]; do sleep 0.05; i=$((i+1)); "
              "done' > /dev/null 2>&1; :");
        } catch (const Error& stop) {
          end_stopped(stop, false);  // returned while its group was alive
        }
        std::_Exit(2);
      },
      ::testing::ExitedWithCode(static_cast<int>(ExitCode::kInterrupted)),
      "^organfit: error: interrupted \\(SIGINT or SIGTERM\\): nothing was written\n$");
}

// An exception that cannot unwind to the command (here out of a thread's function; in a run,
// out of an OpenMP region) ends the process as a stop does: partial outputs removed, one line.
TEST(FailureDeathTest, OutOfMemoryOnAWorkerEndsTheProcessWithOneLineAndExit2) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  const fs::path staging = scratch("oom_staging");
  EXPECT_EXIT(
      {
        install_interrupt_handlers();
        fs::create_directories(staging / "inside");
        std::ofstream(staging / "inside" / "half.nrrd") << "partial";
        const PartialPath partial(staging);
        std::thread([] { throw std::bad_alloc(); }).join();
        std::_Exit(3);  // not reached: the process ends in the handler and the watchdog
      },
      ::testing::ExitedWithCode(static_cast<int>(ExitCode::kBadInput)),
      "^organfit: error: out of memory: the run needed more than .*; nothing was written\n$");
  EXPECT_FALSE(fs::exists(staging));
}

TEST(FailureDeathTest, ACrashEndsTheProcessWithOneLineAndNothingPartialLeft) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "faults are the sanitizer's to report";
#endif
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  const fs::path staging = scratch("crash_staging");
  EXPECT_EXIT(
      {
        install_interrupt_handlers();
        fs::create_directories(staging);
        const PartialPath partial(staging);
        ::raise(SIGSEGV);
        std::_Exit(3);
      },
      ::testing::ExitedWithCode(static_cast<int>(ExitCode::kInternal)),
      "^organfit: internal error: the process crashed \\(a segmentation fault\\).*; nothing "
      "was written\n$");
  EXPECT_FALSE(fs::exists(staging));
}

TEST(FailureDeathTest, ALibraryThatFaultsOnAnInputNamesTheInputAndExits2) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "faults are the sanitizer's to report";
#endif
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(
      {
        install_interrupt_handlers();
        const ReadingInput reading("/data/points.ply", "VTK");
        std::fputs("a library's own complaint\n", stderr);  // kept off stderr
        ::raise(SIGSEGV);
        std::_Exit(3);
      },
      ::testing::ExitedWithCode(static_cast<int>(ExitCode::kBadInput)),
      "^organfit: error: /data/points.ply: malformed input: the VTK library gave up on it\n$");
}

}  // namespace
}  // namespace organfit
