#pragma once
// An array of trivially copyable records larger than memory may allow: pages live in an
// anonymous scratch file and at most `cache_bytes` of them in memory (clock replacement, dirty
// pages written back on eviction). The converter keeps per-vertex data here so that its memory
// is bounded by the --memory budget, not by the input's vertex count; when the whole array fits
// in the cache, no page is ever written.
//
// Not thread-safe. at() returns a reference that stays valid only until the next at().
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include "base/large_buffer.h"
#include "base/temp_file.h"

namespace catpaq {

template <typename T>
class PagedArray {
    static_assert(std::is_trivially_copyable_v<T>);

public:
    // size: number of records (initially zero-filled); scratch files go next to `near_path`.
    PagedArray(uint64_t size, uint64_t cache_bytes, const std::string& near_path)
        : size_(size), near_path_(near_path) {
        uint64_t pages = (size + kPageRecords - 1) / kPageRecords;
        uint64_t fit = cache_bytes / (kPageRecords * sizeof(T));
        slots_.resize(size_t(std::max<uint64_t>(2, std::min(pages, fit))));
        slot_of_page_.assign(size_t(pages), -1);
        // All slots in one block (zero-filled, huge pages, mapped ahead of the writer): a page
        // allocated at a time cost a page fault per 4 KiB.
        storage_ = LargeBuffer(slots_.size() * kPageRecords * sizeof(T), LargeBuffer::Populate::kAhead);
    }

    uint64_t size() const { return size_; }

    // Records per page. Small pages: a mesh whose triangles visit vertices in an order unlike
    // their index order (vertices sorted by position, faces in scan order) needs many pages at
    // once; with 4096-record pages a 10M-triangle build at 256 MiB spent 30 s re-reading them.
    static constexpr uint64_t kPageRecords = 256;

    T& at(uint64_t i) {
        uint64_t page = i / kPageRecords;
        int32_t s = slot_of_page_[size_t(page)];
        if (s < 0) s = load(page);
        Slot& slot = slots_[size_t(s)];
        slot.referenced = true;
        return slot.data[size_t(i % kPageRecords)];
    }
    // Marks the page of record i as modified (call after writing through at()).
    T& at_for_write(uint64_t i) {
        T& r = at(i);
        slots_[size_t(slot_of_page_[size_t(i / kPageRecords)])].dirty = true;
        return r;
    }
    // True when every page is in memory and none was ever evicted: then resident_at() may be
    // used, from any number of threads, as long as nothing calls at().
    bool resident() const {
        if (file_) return false;
        for (int32_t s : slot_of_page_)
            if (s < 0) return false;
        return true;
    }
    const T& resident_at(uint64_t i) const {
        return slots_[size_t(slot_of_page_[size_t(i / kPageRecords)])].data[size_t(i % kPageRecords)];
    }
    // The same, for writing (different records from different threads). No page is marked
    // dirty: with every page in memory, none is ever evicted, so none is ever written back.
    T& resident_at(uint64_t i) {
        return slots_[size_t(slot_of_page_[size_t(i / kPageRecords)])].data[size_t(i % kPageRecords)];
    }
    // Bytes written to and read from the scratch file so far.
    uint64_t bytes_spilled() const { return spilled_; }

private:
    struct Slot {
        T* data = nullptr;  // in storage_, set when the slot is first used
        int64_t page = -1;
        bool dirty = false, referenced = false;
    };

    int32_t load(uint64_t page) {
        // Clock: skip recently referenced slots once.
        while (slots_[hand_].data && slots_[hand_].referenced) {
            slots_[hand_].referenced = false;
            hand_ = (hand_ + 1) % slots_.size();
        }
        Slot& slot = slots_[hand_];
        int32_t s = int32_t(hand_);
        hand_ = (hand_ + 1) % slots_.size();
        const size_t page_bytes = kPageRecords * sizeof(T);
        if (!slot.data) {
            slot.data = reinterpret_cast<T*>(storage_.data()) + size_t(s) * kPageRecords;  // zero-filled
            if (file_) file_->read_or_zero(page * page_bytes, slot.data, page_bytes);
        } else {
            if (slot.dirty) {
                if (!file_) file_ = std::make_unique<TempFile>(near_path_);
                file_->write_at(uint64_t(slot.page) * page_bytes, slot.data, page_bytes);
                spilled_ += page_bytes;
            }
            slot_of_page_[size_t(slot.page)] = -1;
            if (file_)
                file_->read_or_zero(page * page_bytes, slot.data, page_bytes);
            else
                std::memset(static_cast<void*>(slot.data), 0, page_bytes);
        }
        slot.page = int64_t(page);
        slot.dirty = false;
        slot_of_page_[size_t(page)] = s;
        return s;
    }
    uint64_t size_;
    std::string near_path_;
    LargeBuffer storage_;
    std::vector<Slot> slots_;
    std::vector<int32_t> slot_of_page_;
    size_t hand_ = 0;
    std::unique_ptr<TempFile> file_;
    uint64_t spilled_ = 0;
};

}  // namespace catpaq
