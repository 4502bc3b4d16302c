#pragma once
// A large block of zero-filled memory, mapped with transparent huge pages requested.
//
// Fresh memory costs a page fault per 4 KiB page on first touch: about 13 us each on the
// development VM, which for the converter's big arrays cost more than the work done in them.
// With huge pages it is one fault per 2 MiB. (This machine's kernel grants huge pages only on
// request: /sys/kernel/mm/transparent_hugepage/enabled is "madvise".) Blocks below 8 MiB come
// from calloc: the heap hands warm pages to the next user.
#include <cstddef>

namespace catpaq {

class LargeBuffer {
public:
    LargeBuffer() = default;
    explicit LargeBuffer(size_t bytes);
    ~LargeBuffer();
    LargeBuffer(LargeBuffer&& other) noexcept;
    LargeBuffer& operator=(LargeBuffer&& other) noexcept;
    LargeBuffer(const LargeBuffer&) = delete;
    LargeBuffer& operator=(const LargeBuffer&) = delete;

    // 64-byte aligned, `size()` bytes, zero-filled when allocated. Throws std::bad_alloc.
    std::byte* data() const { return data_; }
    size_t size() const { return bytes_; }

private:
    void release();
    std::byte* data_ = nullptr;
    size_t bytes_ = 0;
    void* map_ = nullptr;  // the mapping, when mapped (else data_ came from calloc)
    size_t map_bytes_ = 0;
    void* heap_ = nullptr;
};

}  // namespace catpaq
