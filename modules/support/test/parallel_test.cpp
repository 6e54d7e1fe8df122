// parallel_for_each: every piece once, on threads; the first exception passed on after
// every piece has ended.
#include "organfit/support/parallel.h"

#include <gtest/gtest.h>
#include <omp.h>

#include <atomic>
#include <chrono>
#include <set>
#include <stdexcept>
#include <thread>
#include <vector>

namespace organfit {
namespace {

TEST(ParallelForEach, CallsEveryPieceOnceOnThreads) {
  std::vector<std::atomic<int>> calls(1000);
  std::vector<int> thread_of(calls.size());
  std::atomic<int> started{0};
  omp_set_num_threads(2);
  parallel_for_each(static_cast<int>(calls.size()), [&](int i) {
    ++started;
    // The first piece holds its thread until another piece has started (at most 10 s):
    // that one ran on the other thread.
    for (int wait = 0; i == 0 && started.load() < 2 && wait < 10000; ++wait)
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    ++calls[static_cast<size_t>(i)];
    thread_of[static_cast<size_t>(i)] = omp_get_thread_num();
  });
  for (const auto& c : calls)
    EXPECT_EQ(c.load(), 1);
  EXPECT_EQ(std::set<int>(thread_of.begin(), thread_of.end()).size(), 2u);  // both threads
  parallel_for_each(0, [](int) { FAIL() << "no piece to call"; });
}

TEST(ParallelForEach, PassesOnAnExceptionAfterEveryPieceHasEnded) {
  std::atomic<int> ended{0};
  EXPECT_THROW(parallel_for_each(64,
                                 [&](int i) {
                                   ++ended;
                                   if (i % 16 == 5) throw std::runtime_error("piece failed");
                                 }),
               std::runtime_error);
  EXPECT_EQ(ended.load(), 64);
}

}  // namespace
}  // namespace organfit
