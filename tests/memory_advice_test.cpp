#include "core/memory_advice.h"

#include <gtest/gtest.h>
#include <sys/mman.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace toposlice {
namespace {

// The VmFlags line of the mapping of this process that holds `address` (/proc/self/smaps), or "".
std::string vmFlagsAt(const void* address) {
  const auto at = reinterpret_cast<std::uintptr_t>(address);
  std::ifstream smaps("/proc/self/smaps");
  std::string line;
  bool inside = false;
  while (std::getline(smaps, line)) {
    std::uintptr_t begin = 0, end = 0;
    char dash = 0;
    std::istringstream head(line);
    if (head >> std::hex >> begin >> dash >> end && dash == '-') {
      inside = begin <= at && at < end;
    } else if (inside && line.starts_with("VmFlags:")) {
      return line;
    }
  }
  return "";
}

bool hugePageAdvised(const void* address) {
  return (" " + vmFlagsAt(address) + " ").find(" hg ") != std::string::npos;
}

constexpr std::size_t kHuge = std::size_t{2} << 20;

bool kernelHasHugePages() {
  return std::filesystem::exists("/sys/kernel/mm/transparent_hugepage/enabled");
}

// A fresh anonymous mapping (no advice of its own), unmapped at the end of the test.
struct FreshMapping {
  std::size_t bytes;
  std::byte* data;
  explicit FreshMapping(std::size_t size)
      : bytes(size),
        data(static_cast<std::byte*>(
            mmap(nullptr, size, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0))) {}
  ~FreshMapping() {
    if (data != MAP_FAILED) munmap(data, bytes);
  }
  // Its first 2 MiB boundary.
  std::byte* aligned() const {
    const auto base = reinterpret_cast<std::uintptr_t>(data);
    return data + (((base + kHuge - 1) & ~(kHuge - 1)) - base);
  }
};

// Only the whole 2 MiB pages inside the span are advised (the kernel marks their mapping "hg"): not the
// partial pages at its ends, nor the memory around it.
TEST(MemoryAdvice, OnlyTheWhole2MiBPagesOfASpanAreAdvised) {
  if (!kernelHasHugePages()) GTEST_SKIP() << "this kernel has no transparent huge pages";
  const FreshMapping map(16 * kHuge);
  ASSERT_NE(map.data, MAP_FAILED);
  std::byte* const aligned = map.aligned();
  std::byte* const begin = aligned + 12345;    // 2 MiB - 12345 bytes before the first whole page
  const std::size_t bytes = 9 * kHuge + 4321;  // ends 4321 + 12345 bytes into a partial page
  adviseHugePages(begin, bytes);
  std::byte* const firstWhole = aligned + kHuge;  // the whole pages: [aligned + 2 MiB, aligned + 10 MiB)
  std::byte* const endWhole = aligned + 9 * kHuge;
  EXPECT_TRUE(hugePageAdvised(firstWhole)) << vmFlagsAt(firstWhole);
  EXPECT_TRUE(hugePageAdvised(endWhole - 1)) << vmFlagsAt(endWhole - 1);
  EXPECT_FALSE(hugePageAdvised(firstWhole - 1)) << vmFlagsAt(firstWhole - 1);
  EXPECT_FALSE(hugePageAdvised(begin)) << vmFlagsAt(begin);
  EXPECT_FALSE(hugePageAdvised(endWhole)) << vmFlagsAt(endWhole);
  EXPECT_FALSE(hugePageAdvised(begin + bytes - 1)) << vmFlagsAt(begin + bytes - 1);
}

// Spans without a whole 2 MiB page are left alone.
TEST(MemoryAdvice, SpansWithoutAWholePageAreLeftAlone) {
  if (!kernelHasHugePages()) GTEST_SKIP() << "this kernel has no transparent huge pages";
  const FreshMapping map(8 * kHuge);
  ASSERT_NE(map.data, MAP_FAILED);
  std::byte* const aligned = map.aligned();
  adviseHugePages(aligned + 1, kHuge);              // 2 MiB, but across a page boundary
  adviseHugePages(aligned + 2 * kHuge, kHuge - 1);  // one byte short of a whole page
  adviseHugePages(nullptr, 0);
  for (std::size_t at : {std::size_t{0}, kHuge, 2 * kHuge, 3 * kHuge - 1})
    EXPECT_FALSE(hugePageAdvised(aligned + at)) << at << " " << vmFlagsAt(aligned + at);
}

// A vector reserved through reserveHugePages has its whole pages advised and keeps what is written.
TEST(MemoryAdvice, ReservedVectorsAreAdvisedAndHoldTheirValues) {
  if (!kernelHasHugePages()) GTEST_SKIP() << "this kernel has no transparent huge pages";
  std::vector<uint32_t> big;
  reserveHugePages(big, (9 * kHuge + 12345) / sizeof(uint32_t));
  const auto begin = reinterpret_cast<std::uintptr_t>(big.data());
  const auto* const firstWhole =
      reinterpret_cast<const std::byte*>(big.data()) + (((begin + kHuge - 1) & ~(kHuge - 1)) - begin);
  EXPECT_TRUE(hugePageAdvised(firstWhole)) << vmFlagsAt(firstWhole);
  big.resize(big.capacity());
  for (std::size_t i = 0; i < big.size(); ++i) big[i] = static_cast<uint32_t>(i * 2654435761u);
  for (std::size_t i = 0; i < big.size(); i += 4097)
    ASSERT_EQ(big[i], static_cast<uint32_t>(i * 2654435761u));
}

}  // namespace
}  // namespace toposlice
