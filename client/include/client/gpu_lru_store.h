#pragma once
// The GPU store policy every format shares (client/node_renderer.h): objects uploaded under a
// key, counted in bytes against a budget; pinned ones (the cut) and those used in the current
// frame are never evicted; the others go least recently used first once the store is over its
// budget, and each eviction is reported to a callback (the session then drops the node from its
// residency). A format's store derives from it (or holds one), builds its GL objects and calls insert();
// `Gpu` is its object (with a `uint64_t bytes` field), `destroy` deletes its GL names.
//
// Everything here needs a current GL context when objects are destroyed.
#include <cstddef>
#include <cstdint>
#include <functional>
#include <iterator>
#include <list>
#include <unordered_map>
#include <utility>

#include "client/node_renderer.h"

namespace catpaq {

template <class Key, class Gpu, class Hash = std::hash<Key>>
class GpuLruStore {
public:
    explicit GpuLruStore(void (*destroy)(Gpu&)) : destroy_(destroy) {}
    ~GpuLruStore() { clear(); }
    GpuLruStore(const GpuLruStore&) = delete;
    GpuLruStore& operator=(const GpuLruStore&) = delete;

    bool resident(const Key& key) const { return entries_.count(key) != 0; }
    const Gpu* find(const Key& key) const {
        auto it = entries_.find(key);
        return it == entries_.end() ? nullptr : &it->second.gpu;
    }
    // Deletes the object (not an eviction: no callback); false if it was not resident.
    bool release(const Key& key) {
        auto it = entries_.find(key);
        if (it == entries_.end()) return false;
        bytes_ -= it->second.gpu.bytes;
        destroy_(it->second.gpu);
        lru_.erase(it->second.lru);
        entries_.erase(it);
        return true;
    }
    void clear() {
        for (auto& [key, e] : entries_) destroy_(e.gpu);
        entries_.clear();
        lru_.clear();
        bytes_ = 0;
    }

    uint64_t gpu_bytes() const { return bytes_; }
    size_t size() const { return entries_.size(); }
    void set_budget(uint64_t bytes) {  // 0: unlimited; evicts at once
        budget_ = bytes;
        evict_to_budget();
    }
    uint64_t budget() const { return budget_; }
    bool over_budget() const { return budget_ != 0 && bytes_ > budget_; }

    void pin(const Key& key) {
        auto it = entries_.find(key);
        if (it != entries_.end()) ++it->second.pins;
    }
    void unpin(const Key& key) {
        auto it = entries_.find(key);
        if (it != entries_.end() && it->second.pins > 0) --it->second.pins;
    }
    void unpin_all() {
        for (auto& [key, e] : entries_) e.pins = 0;
    }
    bool pinned(const Key& key) const {
        auto it = entries_.find(key);
        return it != entries_.end() && it->second.pins > 0;
    }
    void begin_frame() { ++frame_; }
    uint64_t frame() const { return frame_; }
    void mark_used(const Key& key) {  // no-op if not resident
        auto it = entries_.find(key);
        if (it != entries_.end()) touch(it->second);
    }
    // Evicts least recently used objects, neither pinned nor used this frame, while over the
    // budget (reporting each); returns how many. May stay over budget.
    size_t evict_to_budget() {
        size_t evicted = 0;
        auto it = lru_.begin();
        while (over_budget() && it != lru_.end()) {
            const Key key = *it++;
            Entry& e = entries_.at(key);
            if (e.pins > 0) continue;
            if (e.last_used >= frame_) break;  // the rest of the list was used this frame too
            release(key);
            ++evicted;
            if (on_evict_) {
                on_evict_(key);
                it = lru_.begin();  // the callback may release others, the one `it` points to among them
            }
        }
        return evicted;
    }
    void set_eviction_callback(std::function<void(const Key&)> callback) { on_evict_ = std::move(callback); }

    // Takes an uploaded object under `key`, replacing an earlier one (whose pins it keeps); it
    // counts as used this frame. Then evicts down to the budget.
    void insert(const Key& key, Gpu gpu) {
        int pins = 0;
        if (auto it = entries_.find(key); it != entries_.end()) pins = it->second.pins;
        release(key);
        lru_.push_back(key);
        bytes_ += gpu.bytes;
        entries_.emplace(key, Entry{std::move(gpu), std::prev(lru_.end()), pins, frame_});
        evict_to_budget();
    }

private:
    struct Entry {
        Gpu gpu;
        typename std::list<Key>::iterator lru;  // front: least recently used
        int pins = 0;
        uint64_t last_used = 0;  // frame of the last upload or mark_used
    };
    void touch(Entry& e) {
        e.last_used = frame_;
        lru_.splice(lru_.end(), lru_, e.lru);  // most recently used at the back
    }

    void (*destroy_)(Gpu&);
    std::unordered_map<Key, Entry, Hash> entries_;
    std::list<Key> lru_;
    uint64_t bytes_ = 0, budget_ = 0, frame_ = 1;
    std::function<void(const Key&)> on_evict_;
};

// The NodeRenderer's store half for formats whose nodes are drawn whole (one part, id 0), kept in
// a store keyed by node key (a GpuLruStore<uint64_t, ...>): AQP and points. The format adds
// upload() and draw().
template <class Store>
class WholeNodeRenderer : public NodeRenderer {
public:
    bool resident(uint64_t key, uint8_t part) const override { return part == 0 && store_.resident(key); }
    void release(uint64_t key, uint8_t part) override {
        if (part == 0) store_.release(key);
    }
    void begin_frame() override { store_.begin_frame(); }
    void unpin_all() override { store_.unpin_all(); }
    void pin(uint64_t key, uint8_t part) override {
        if (part == 0) store_.pin(key);
    }
    void mark_used(uint64_t key, uint8_t part) override {
        if (part == 0) store_.mark_used(key);
    }
    size_t evict_to_budget() override { return store_.evict_to_budget(); }
    void set_budget(uint64_t bytes) override { store_.set_budget(bytes); }
    uint64_t gpu_bytes() const override { return store_.gpu_bytes(); }
    void set_eviction_callback(std::function<void(uint64_t key, uint8_t part)> callback) override {
        if (!callback) {
            store_.set_eviction_callback(nullptr);
            return;
        }
        store_.set_eviction_callback([callback = std::move(callback)](const uint64_t& key) { callback(key, 0); });
    }

protected:
    Store store_;
};

}  // namespace catpaq
