#include "organfit/support/resources.h"

#include <gtest/gtest.h>

#include <cstddef>
#include <optional>
#include <string>
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

TEST(RequestHugePages, AskedOnlyWhereTheKernelGivesThemOnRequestAndNobodyAnswered) {
  const std::string madvise = "always [madvise] never";
  EXPECT_EQ(huge_page_tunables(nullptr, madvise), "glibc.malloc.hugetlb=1");
  EXPECT_EQ(huge_page_tunables("", madvise), "glibc.malloc.hugetlb=1");
  // The user's other tunables are kept.
  EXPECT_EQ(huge_page_tunables("glibc.malloc.arena_max=2", madvise),
            "glibc.malloc.arena_max=2:glibc.malloc.hugetlb=1");
  // Answered already (by the user, or by the run that started this one): as it is.
  EXPECT_EQ(huge_page_tunables("glibc.malloc.hugetlb=0", madvise), std::nullopt);
  EXPECT_EQ(huge_page_tunables("glibc.malloc.arena_max=2:glibc.malloc.hugetlb=1", madvise),
            std::nullopt);
  // Given anyway, never given, or no such file (another kernel): nothing to ask.
  EXPECT_EQ(huge_page_tunables(nullptr, "[always] madvise never"), std::nullopt);
  EXPECT_EQ(huge_page_tunables(nullptr, "always madvise [never]"), std::nullopt);
  EXPECT_EQ(huge_page_tunables(nullptr, ""), std::nullopt);
}

TEST(OpenMpSpinCount, ShortenedUnlessTheUserOrAnEarlierStartSetIt) {
  EXPECT_EQ(openmp_spin_count(nullptr, nullptr), "10000");
  EXPECT_EQ(openmp_spin_count("ACTIVE", nullptr), std::nullopt);
  EXPECT_EQ(openmp_spin_count("passive", nullptr), std::nullopt);
  EXPECT_EQ(openmp_spin_count(nullptr, "300000"), std::nullopt);
  EXPECT_EQ(openmp_spin_count(nullptr, ""), std::nullopt);  // set, if empty: as it is
}

}  // namespace
}  // namespace organfit
