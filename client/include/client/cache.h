#pragma once
// LRU caches with byte budgets for the client's CPU side: compressed node bytes (optional) and
// decoded nodes (DecodedNode, client/format.h: of any format). The nodes of the current cut are
// pinned every frame (CutEngine::pinned()) and never evicted; everything else goes least recently
// used first, so memory stays flat over any camera path: bytes() <= budget() unless the pinned
// entries alone exceed it (the cut engine's CPU budget is meant to be below the cache budget,
// leaving room for prefetched nodes). The format's GPU store (client/node_renderer.h) follows the
// same policy.
//
// NodeStore glues them to the cut engine: it is the engine's Residency (a node is resident while
// its decoded data is cached, with the data box the format gave it), keeps the exact per-part
// draw counts (PartDrawCounter) and evicts under the same pins.
#include <cstdint>
#include <functional>
#include <list>
#include <memory>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "client/cut_engine.h"
#include "client/format.h"
#include "client/hierarchy.h"

namespace catpaq {

template <class V>
class LruCache {
public:
    // Called for every entry the cache evicts (not for erase() or replacement).
    using EvictFn = std::function<void(uint64_t key, const V& value, uint64_t bytes)>;

    explicit LruCache(uint64_t budget_bytes) : budget_(budget_bytes) {}

    // Inserts (or replaces) an entry as the most recently used, evicting least recently used
    // unpinned entries to make room. An unpinned entry that cannot fit even then is not stored
    // (returns false); a pinned one always is.
    bool insert(uint64_t key, V value, uint64_t bytes) {
        auto it = map_.find(key);
        if (it != map_.end()) remove(it);
        bool pin = pinned_keys_.count(key) != 0;
        if (!pin && (bytes > budget_ || pinned_bytes_ > budget_ - bytes)) return false;  // cannot fit: evict nothing
        evict_until(budget_ >= bytes ? budget_ - bytes : 0);
        std::list<Entry>& list = pin ? pinned_ : lru_;
        list.push_front(Entry{key, std::move(value), bytes, pin});
        map_[key] = list.begin();
        bytes_ += bytes;
        if (pin) pinned_bytes_ += bytes;
        return true;
    }

    // The value, marked most recently used; nullptr if absent (a miss).
    const V* get(uint64_t key) {
        auto it = map_.find(key);
        if (it == map_.end()) {
            misses_++;
            return nullptr;
        }
        hits_++;
        auto e = it->second;
        std::list<Entry>& list = e->pinned ? pinned_ : lru_;
        list.splice(list.begin(), list, e);
        return &e->value;
    }
    // The value without touching the order.
    const V* peek(uint64_t key) const {
        auto it = map_.find(key);
        return it == map_.end() ? nullptr : &it->second->value;
    }
    bool contains(uint64_t key) const { return map_.count(key) != 0; }
    bool erase(uint64_t key) {
        auto it = map_.find(key);
        if (it == map_.end()) return false;
        remove(it);
        return true;
    }

    // Replaces the pinned set (keys not cached yet are pinned when inserted). Entries that lose
    // their pin become the most recently used (they were in use until now); then the cache is
    // trimmed to its budget.
    void set_pinned(const std::vector<uint64_t>& keys) {
        std::unordered_set<uint64_t> next(keys.begin(), keys.end());
        for (auto e = pinned_.begin(); e != pinned_.end();) {
            auto n = std::next(e);
            if (!next.count(e->key)) {
                e->pinned = false;
                pinned_bytes_ -= e->bytes;
                lru_.splice(lru_.begin(), pinned_, e);
            }
            e = n;
        }
        for (uint64_t key : next) {
            auto it = map_.find(key);
            if (it == map_.end() || it->second->pinned) continue;
            auto e = it->second;
            e->pinned = true;
            pinned_bytes_ += e->bytes;
            pinned_.splice(pinned_.begin(), lru_, e);
        }
        pinned_keys_.swap(next);
        evict_until(budget_);
    }
    bool pinned(uint64_t key) const {
        auto it = map_.find(key);
        return it != map_.end() && it->second->pinned;
    }

    void set_budget(uint64_t budget_bytes) {
        budget_ = budget_bytes;
        evict_until(budget_);
    }
    void on_evict(EvictFn fn) { on_evict_ = std::move(fn); }

    uint64_t bytes() const { return bytes_; }
    uint64_t budget() const { return budget_; }
    uint64_t pinned_bytes() const { return pinned_bytes_; }
    size_t size() const { return map_.size(); }
    uint64_t evictions() const { return evictions_; }
    uint64_t hits() const { return hits_; }
    uint64_t misses() const { return misses_; }
    // Unpinned keys, most recently used first (for tests and reports).
    std::vector<uint64_t> lru_order() const {
        std::vector<uint64_t> out;
        for (const Entry& e : lru_) out.push_back(e.key);
        return out;
    }

private:
    struct Entry {
        uint64_t key;
        V value;
        uint64_t bytes;
        bool pinned;
    };
    using Map = std::unordered_map<uint64_t, typename std::list<Entry>::iterator>;

    void remove(typename Map::iterator it) {
        auto e = it->second;
        bytes_ -= e->bytes;
        if (e->pinned) {
            pinned_bytes_ -= e->bytes;
            pinned_.erase(e);
        } else {
            lru_.erase(e);
        }
        map_.erase(it);
    }
    void evict_until(uint64_t target) {
        while (bytes_ > target && !lru_.empty()) {
            Entry& victim = lru_.back();
            uint64_t key = victim.key;
            uint64_t size = victim.bytes;
            V value = std::move(victim.value);
            bytes_ -= size;
            map_.erase(key);
            lru_.pop_back();
            evictions_++;
            if (on_evict_) on_evict_(key, value, size);
        }
    }

    uint64_t budget_;
    uint64_t bytes_ = 0, pinned_bytes_ = 0;
    uint64_t evictions_ = 0, hits_ = 0, misses_ = 0;
    std::list<Entry> lru_;     // unpinned, most recent first
    std::list<Entry> pinned_;  // pinned, never evicted
    Map map_;
    std::unordered_set<uint64_t> pinned_keys_;
    EvictFn on_evict_;
};

using CompressedCache = LruCache<std::shared_ptr<const std::vector<uint8_t>>>;
using DecodedCache = LruCache<std::shared_ptr<const DecodedNode>>;

class NodeStore : public Residency {
public:
    // compressed_budget_bytes = 0: no compressed cache. Before a node is decoded its bytes are
    // estimated at `bytes_per_primitive` times its primitives (GPU and CPU alike, as
    // ResidencyTable does).
    NodeStore(const Hierarchy& hierarchy, uint64_t decoded_budget_bytes, uint64_t compressed_budget_bytes = 0,
              double bytes_per_primitive = 16.0);
    NodeStore(const NodeStore&) = delete;
    NodeStore& operator=(const NodeStore&) = delete;

    bool resident(uint32_t node) const override;
    NodeBytes bytes(uint32_t node) const override;
    const Aabb* data_bounds(uint32_t node) const override;
    bool changes_since(uint64_t& cursor, std::vector<uint32_t>& out) const override { return log_.since(cursor, out); }
    const PartDrawCounter& counter() const { return counter_; }

    // Stores a decoded node (its exact part counts, and the compressed bytes when a compressed
    // cache exists). Returns false if the decoded cache had no room for it.
    bool add(uint32_t node, std::shared_ptr<const DecodedNode> decoded,
             std::shared_ptr<const std::vector<uint8_t>> compressed = {});
    // The decoded data of a resident node (marked recently used), or nullptr.
    std::shared_ptr<const DecodedNode> decoded(uint32_t node);
    // Compressed bytes of a node, if cached (for Fetcher::supply after an eviction).
    std::shared_ptr<const std::vector<uint8_t>> compressed(uint32_t node);
    // Pins the cut (CutEngine::pinned()) in both caches and trims them.
    void pin(const std::vector<uint32_t>& nodes);

    DecodedCache& decoded_cache() { return decoded_; }
    CompressedCache* compressed_cache() { return compressed_.get(); }

private:
    const Hierarchy& hierarchy_;
    double bytes_per_primitive_;
    PartDrawCounter counter_;
    DecodedCache decoded_;
    std::unique_ptr<CompressedCache> compressed_;
    std::vector<NodeBytes> bytes_;
    std::vector<Aabb> data_bounds_;
    std::vector<uint8_t> resident_;
    ChangeLog log_;
};

}  // namespace catpaq
