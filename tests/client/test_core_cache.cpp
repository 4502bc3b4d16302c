// LRU caches with byte budgets: the budget holds, pinned entries are never evicted, eviction goes
// least recently used first, and memory stays flat over a long camera path driven by the engine.
#include <gtest/gtest.h>

#include <random>
#include <set>

#include "client/cache.h"
#include "client/cut_engine.h"
#include "client/hierarchy.h"
#include "test_core_support.h"

using namespace catpaq;

using IntCache = LruCache<int>;

TEST(LruCache, NeverHoldsMoreThanItsBudget) {
    IntCache cache(10000);
    std::mt19937_64 rng(1);
    size_t refused = 0;
    for (int i = 0; i < 5000; ++i) {
        uint64_t bytes = 1 + rng() % 3000;
        refused += !cache.insert(rng() % 400, i, bytes);
        ASSERT_LE(cache.bytes(), cache.budget());
        if (i % 7 == 0) cache.get(rng() % 400);
    }
    EXPECT_GT(cache.evictions(), 1000u);
    EXPECT_EQ(refused, 0u);  // every entry is below the budget and nothing is pinned
    EXPECT_FALSE(cache.insert(1, 0, 20000)) << "an entry larger than the budget is refused";
    cache.set_budget(3000);
    EXPECT_LE(cache.bytes(), 3000u);
}

TEST(LruCache, PinnedEntriesAreNeverEvicted) {
    IntCache cache(1000);
    for (uint64_t k = 0; k < 10; ++k) cache.insert(k, int(k), 100);
    cache.set_pinned({2, 5, 7, 42});  // 42 is not cached yet: pinned once inserted
    std::mt19937_64 rng(2);
    for (int i = 0; i < 2000; ++i) {
        cache.insert(100 + rng() % 1000, i, 50 + rng() % 200);
        for (uint64_t k : {2, 5, 7}) ASSERT_TRUE(cache.contains(k));
    }
    EXPECT_EQ(cache.pinned_bytes(), 300u);
    // A pinned entry is stored even past the budget; unpinned ones make room for it first.
    EXPECT_TRUE(cache.insert(42, 0, 900));
    EXPECT_TRUE(cache.pinned(42));
    EXPECT_EQ(cache.bytes(), 1200u);  // only pinned entries left: over budget, by the pins alone
    EXPECT_FALSE(cache.insert(500, 0, 10)) << "no room while the pins fill the budget";
    // Unpinned entries become evictable again.
    cache.set_pinned({42});
    EXPECT_LE(cache.bytes(), 1000u);
    EXPECT_TRUE(cache.contains(42));
}

TEST(LruCache, EvictsTheLeastRecentlyUsedFirst) {
    IntCache cache(500);
    std::vector<uint64_t> evicted;
    cache.on_evict([&](uint64_t key, const int&, uint64_t) { evicted.push_back(key); });
    for (uint64_t k = 1; k <= 5; ++k) cache.insert(k, int(k), 100);
    EXPECT_EQ(cache.lru_order(), (std::vector<uint64_t>{5, 4, 3, 2, 1}));
    cache.get(1);
    cache.get(3);
    EXPECT_EQ(cache.lru_order(), (std::vector<uint64_t>{3, 1, 5, 4, 2}));
    cache.insert(6, 6, 100);
    cache.insert(7, 7, 200);
    EXPECT_EQ(evicted, (std::vector<uint64_t>{2, 4, 5}));
    EXPECT_EQ(cache.lru_order(), (std::vector<uint64_t>{7, 6, 3, 1}));
    EXPECT_EQ(cache.hits(), 2u);
    EXPECT_EQ(cache.peek(99), nullptr);
    EXPECT_EQ(cache.get(99), nullptr);
    EXPECT_EQ(cache.misses(), 1u);
    // Entries that lose their pin become the most recently used.
    cache.set_pinned({1});
    cache.set_pinned({});
    EXPECT_EQ(cache.lru_order().front(), 1u);
}

TEST(LruCache, MemoryStaysFlatAndTheCutStaysResidentOverALongCameraPath) {
    // The engine on a synthetic terrain, data arriving into an LRU cache (bytes = node cost) that
    // pins the engine's cut every frame; residency is "in the cache".
    SyntheticHierarchySettings s;
    s.levels = 7;
    s.seed = 9;
    Hierarchy h = build_synthetic_hierarchy(s);
    PartDrawCounter counter(h);
    test::FakeResidency residency(h, false);
    IntCache cache(400000);
    cache.on_evict([&](uint64_t key, const int&, uint64_t) { residency.set(uint32_t(key), false); });
    CutBudgets b;
    b.max_cpu_bytes = 250000;
    b.max_new_requests = 30;
    CutEngine engine(h, counter, b);
    uint64_t peak = 0;
    size_t evictions_seen = 0;
    for (int f = 0; f < 600; ++f) {
        double a = f * 2 * M_PI / 150;
        ViewParams v = test::camera({500 + 450 * std::cos(a), 500 + 450 * std::sin(a), 40}, {500, 500, 0}, 1.0, 50);
        const CutFrame& frame = engine.update(v, residency);
        std::vector<uint64_t> pins;
        for (uint32_t n : engine.pinned()) pins.push_back(n);
        cache.set_pinned(pins);
        // Everything drawn with data is cached (pinned), except a root before it arrives.
        for (uint32_t n : engine.drawn_nodes())
            if (h.node(n).has_data && residency.resident(n)) {
                ASSERT_TRUE(cache.contains(n));
            }
        // The requested nodes arrive at once.
        for (const CutRequest& r : frame.requests)
            if (cache.insert(r.node, 0, residency.bytes(r.node).cpu)) residency.set(r.node, true);
        ASSERT_LE(cache.bytes(), cache.budget());
        peak = std::max(peak, cache.bytes());
        evictions_seen = cache.evictions();
    }
    EXPECT_GT(evictions_seen, 100u) << "the path should cycle through more data than fits";
    EXPECT_GT(peak, cache.budget() / 2);
}
