#include "organfit/support/resources.h"

#include <gtest/gtest.h>

#include <cstddef>
#include <vector>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

// A sanitizer's allocator stands in for glibc's: nothing of this to see there.
#if defined(__SANITIZE_ADDRESS__)
#define ORGANFIT_OWN_ALLOCATOR 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define ORGANFIT_OWN_ALLOCATOR 1
#endif
#endif

namespace organfit {
namespace {

TEST(KeepFreedMemory, ALargeBlockComesFromTheHeapAndStaysThereWhenFreed) {
#if defined(__GLIBC__) && !defined(ORGANFIT_OWN_ALLOCATOR)
  keep_freed_memory();
  constexpr std::size_t kBytes = 64u << 20;  // above glibc's largest mmap threshold, 32 MB
  const struct mallinfo2 before = mallinfo2();
  {
    std::vector<char> block(kBytes, 1);
    volatile char last = block.back();
    (void)last;
    const struct mallinfo2 held = mallinfo2();
    EXPECT_EQ(held.hblkhd, before.hblkhd) << "the block was mapped on its own";
    EXPECT_GE(held.uordblks, before.uordblks + kBytes);
  }
  // Freed, it is kept in the heap (free bytes), not unmapped or trimmed.
  EXPECT_GE(mallinfo2().fordblks, kBytes);
  EXPECT_GE(mallinfo2().arena, before.arena + kBytes);
#else
  GTEST_SKIP() << "glibc's allocator only";
#endif
}

}  // namespace
}  // namespace organfit
