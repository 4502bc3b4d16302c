#include "base/large_buffer.h"

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <new>
#include <system_error>
#include <thread>
#include <utility>

#ifdef __linux__
#include <sys/mman.h>
#endif

namespace catpaq {

// Maps the pages of [data, data + bytes) front to back, a huge page at a time, until done or
// stopped. A kernel without MADV_POPULATE_WRITE (before Linux 5.14) refuses the first call:
// the owner then faults the pages in itself, as without a populator.
struct LargeBuffer::Populator {
    std::atomic<bool> stop{false};
    std::thread thread;

    Populator(std::byte* data, size_t bytes) {
        thread = std::thread([this, data, bytes] {
#if defined(__linux__) && defined(MADV_POPULATE_WRITE)
            constexpr size_t kStep = size_t(2) << 20;
            for (size_t at = 0; at < bytes && !stop.load(std::memory_order_relaxed); at += kStep)
                if (madvise(data + at, std::min(kStep, bytes - at), MADV_POPULATE_WRITE) != 0) break;
#else
            (void)data;
            (void)bytes;
#endif
        });
    }
    ~Populator() {
        stop = true;
        thread.join();
    }
};

LargeBuffer::LargeBuffer() = default;

LargeBuffer::LargeBuffer(size_t bytes, Populate populate) : bytes_(bytes) {
    (void)populate;  // only mapped blocks are populated ahead
    if (bytes == 0) return;
#ifdef __linux__
    constexpr size_t kHuge = size_t(2) << 20;
    if (bytes >= 4 * kHuge) {
        // One extra huge page, so the block can start on a huge-page boundary.
        const size_t map_bytes = (bytes + kHuge - 1) / kHuge * kHuge + kHuge;
        void* map = mmap(nullptr, map_bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
        if (map != MAP_FAILED) {
            map_ = map;
            map_bytes_ = map_bytes;
            const uintptr_t start = (reinterpret_cast<uintptr_t>(map) + kHuge - 1) / kHuge * kHuge;
            data_ = static_cast<std::byte*>(map) + (start - reinterpret_cast<uintptr_t>(map));
            madvise(data_, map_bytes - kHuge, MADV_HUGEPAGE);  // a hint: failure is harmless
            if (populate == Populate::kAhead) {
                try {
                    populator_ = std::make_unique<Populator>(data_, bytes);
                } catch (const std::system_error&) {
                    // No thread to spare: the owner faults the pages in itself.
                }
            }
            return;
        }
    }
#endif
    heap_ = std::calloc(1, bytes + 64);
    if (!heap_) throw std::bad_alloc();
    const uintptr_t p = reinterpret_cast<uintptr_t>(heap_);
    data_ = static_cast<std::byte*>(heap_) + ((64 - p % 64) % 64);
}

void LargeBuffer::release() {
    populator_.reset();
#ifdef __linux__
    if (map_) munmap(map_, map_bytes_);
#endif
    std::free(heap_);
    data_ = nullptr;
    bytes_ = 0;
    map_ = nullptr;
    map_bytes_ = 0;
    heap_ = nullptr;
}

LargeBuffer::~LargeBuffer() { release(); }

LargeBuffer::LargeBuffer(LargeBuffer&& other) noexcept { *this = std::move(other); }

LargeBuffer& LargeBuffer::operator=(LargeBuffer&& other) noexcept {
    if (this != &other) {
        release();
        std::swap(data_, other.data_);
        std::swap(bytes_, other.bytes_);
        std::swap(map_, other.map_);
        std::swap(map_bytes_, other.map_bytes_);
        std::swap(heap_, other.heap_);
        std::swap(populator_, other.populator_);
    }
    return *this;
}

}  // namespace catpaq
