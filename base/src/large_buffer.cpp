#include "base/large_buffer.h"

#include <cstdint>
#include <cstdlib>
#include <new>
#include <utility>

#ifdef __linux__
#include <sys/mman.h>
#endif

namespace catpaq {

LargeBuffer::LargeBuffer(size_t bytes) : bytes_(bytes) {
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
    }
    return *this;
}

}  // namespace catpaq
