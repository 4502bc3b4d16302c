#pragma once
// A large block of zero-filled memory, mapped with transparent huge pages requested.
//
// Fresh memory costs a page fault per 4 KiB page on first touch: about 13 us each on the
// development VM, which for the converter's big arrays cost more than the work done in them.
// With huge pages it is one fault per 2 MiB. (This machine's kernel grants huge pages only on
// request: /sys/kernel/mm/transparent_hugepage/enabled is "madvise".) Blocks below 8 MiB come
// from calloc: the heap hands warm pages to the next user.
//
// Even a huge page costs about 4 ms there to zero and map (the hypervisor's work, not the
// guest's): 0.4 s for the 200 MB vertex array of a 10M-triangle build, in its single-threaded
// read. A block made with Populate::kAhead has its pages mapped by a background thread, front to
// back, while its owner fills it (madvise MADV_POPULATE_WRITE, which leaves the contents alone:
// writer and populator never race on data).
#include <cstddef>
#include <memory>

namespace catpaq {

class LargeBuffer {
public:
    enum class Populate { kOnTouch, kAhead };

    LargeBuffer();
    explicit LargeBuffer(size_t bytes, Populate populate = Populate::kOnTouch);
    ~LargeBuffer();
    LargeBuffer(LargeBuffer&& other) noexcept;
    LargeBuffer& operator=(LargeBuffer&& other) noexcept;
    LargeBuffer(const LargeBuffer&) = delete;
    LargeBuffer& operator=(const LargeBuffer&) = delete;

    // 64-byte aligned, `size()` bytes, zero-filled when allocated. Throws std::bad_alloc.
    std::byte* data() const { return data_; }
    size_t size() const { return bytes_; }

private:
    struct Populator;
    void release();
    std::unique_ptr<Populator> populator_;  // joined before the mapping goes
    std::byte* data_ = nullptr;
    size_t bytes_ = 0;
    void* map_ = nullptr;  // the mapping, when mapped (else data_ came from calloc)
    size_t map_bytes_ = 0;
    void* heap_ = nullptr;
};

}  // namespace catpaq
