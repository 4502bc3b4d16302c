#include <gtest/gtest.h>

#include <cstring>
#include <memory>
#include <thread>
#include <vector>

#include "base/heap_warmup.h"

#ifdef __linux__
#include <sys/resource.h>
#endif

using namespace catpaq;

#if defined(__linux__) && defined(__GLIBC__) && defined(RUSAGE_THREAD)

namespace {

// Page faults taken by the calling thread so far.
long thread_faults() {
    rusage usage{};
    getrusage(RUSAGE_THREAD, &usage);
    return usage.ru_minflt + usage.ru_majflt;
}

// Page faults that a fresh thread takes to allocate and fill `bytes` in blocks of 1 MiB (the
// converter's vectors: heap blocks filled by worker threads).
long faults_to_fill(size_t bytes) {
    long faults = 0;
    std::thread worker([&] {
        const long before = thread_faults();
        std::vector<std::unique_ptr<char[]>> blocks;
        for (size_t done = 0; done < bytes; done += size_t(1) << 20) {
            blocks.emplace_back(new char[size_t(1) << 20]);
            std::memset(blocks.back().get(), 1, size_t(1) << 20);
        }
        faults = thread_faults() - before;
    });
    worker.join();
    return faults;
}

}  // namespace

// While a HeapWarmup lives, memory that other threads allocate within its size is already
// mapped: filling 32 MiB takes a few faults instead of one per 4 KiB page (8192).
TEST(HeapWarmup, OtherThreadsAllocateWarmPages) {
    const size_t fill = size_t(32) << 20;
    HeapWarmup warm(size_t(64) << 20);
    if (warm.warmed() == 0) GTEST_SKIP() << "no MADV_POPULATE_WRITE (Linux before 5.14)";
    EXPECT_GE(warm.warmed(), size_t(60) << 20);
    const long faults = faults_to_fill(fill);
    EXPECT_LT(faults, long(fill / 4096 / 8)) << faults << " faults";
}

#endif
