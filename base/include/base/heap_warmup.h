#pragma once
// Warm heap for a phase of heavy allocation.
//
// On the development VM the first touch of a fresh 4 KiB page costs about 13 us (the page fault
// traps into the hypervisor), while one madvise(MADV_POPULATE_WRITE) call maps pages in bulk for
// 0.75 us each. The converter touches about as much fresh heap as its peak memory, hundreds of
// MiB across many vectors, and faulting it in page by page was the largest single item of a 10M-
// triangle build's kernel time. A HeapWarmup maps `bytes` of heap in bulk up front and, while it
// lives, keeps glibc's malloc from handing freed memory back, so allocations reuse warm pages:
//  - one malloc arena (M_ARENA_MAX 1): worker threads would otherwise allocate from arenas of
//    their own, which the warm main heap does not serve (threads that already have an arena keep
//    it);
//  - no trimming of the heap's top (M_TRIM_THRESHOLD) and blocks below 32 MiB from the heap, not
//    from fresh mappings (M_MMAP_THRESHOLD).
// Resident memory grows by `bytes` at once: size it below what the work will allocate anyway.
// The destructor restores fixed default thresholds and gives the free memory back
// (malloc_trim). Process-wide settings: one HeapWarmup at a time. Does nothing but the bulk
// mapping's absence on other C libraries or kernels before Linux 5.14.
#include <cstddef>

namespace catpaq {

class HeapWarmup {
public:
    explicit HeapWarmup(size_t bytes);
    ~HeapWarmup();
    HeapWarmup(const HeapWarmup&) = delete;
    HeapWarmup& operator=(const HeapWarmup&) = delete;

    // Bytes mapped in bulk (0 where bulk mapping is unavailable).
    size_t warmed() const { return warmed_; }

private:
    size_t warmed_ = 0;
};

}  // namespace catpaq
