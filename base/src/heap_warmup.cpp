#include "base/heap_warmup.h"

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <thread>
#include <vector>

#if defined(__GLIBC__)
#include <malloc.h>
#endif
#ifdef __linux__
#include <sys/mman.h>
#endif

namespace catpaq {
namespace {

// Below glibc's largest mmap threshold (32 MiB on 64-bit), so every piece comes from the heap.
constexpr size_t kPiece = size_t(16) << 20;
constexpr size_t kMmapThreshold = size_t(32) << 20;
// glibc's default thresholds (as fixed values: setting one turns its dynamic adjustment off).
constexpr int kDefaultThreshold = 128 * 1024;

}  // namespace

HeapWarmup::HeapWarmup(size_t bytes) {
#if defined(__GLIBC__)
    mallopt(M_ARENA_MAX, 1);
    mallopt(M_TRIM_THRESHOLD, INT32_MAX);
    mallopt(M_MMAP_THRESHOLD, int(kMmapThreshold));
#endif
#if defined(__GLIBC__) && defined(__linux__) && defined(MADV_POPULATE_WRITE)
    // Allocated piece by piece, populated, then freed: the pieces merge into the heap's top,
    // which is no longer trimmed.
    std::vector<void*> pieces;
    for (size_t done = 0; done < bytes; done += kPiece) {
        void* piece = std::malloc(kPiece);
        if (!piece) break;
        pieces.push_back(piece);
        const uintptr_t page = 4096, begin = (reinterpret_cast<uintptr_t>(piece) + page - 1) & ~(page - 1);
        const uintptr_t end = (reinterpret_cast<uintptr_t>(piece) + kPiece) & ~(page - 1);
        if (madvise(reinterpret_cast<void*>(begin), end - begin, MADV_POPULATE_WRITE) != 0) break;
        warmed_ += end - begin;
    }
    for (size_t i = pieces.size(); i-- > 0;) std::free(pieces[i]);
#else
    (void)bytes;
#endif
}

HeapWarmup::~HeapWarmup() {
#if defined(__GLIBC__)
    mallopt(M_ARENA_MAX, int(8 * std::max(1u, std::thread::hardware_concurrency())));  // glibc's default
    mallopt(M_MMAP_THRESHOLD, kDefaultThreshold);
    mallopt(M_TRIM_THRESHOLD, kDefaultThreshold);
    malloc_trim(0);
#endif
}

}  // namespace catpaq
