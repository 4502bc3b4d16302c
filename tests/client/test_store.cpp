// The GPU fragment store: byte accounting, validation, LRU eviction under a budget with pins
// and "used this frame" marks.
#include <gtest/gtest.h>

#include <vector>

#include "base/error.h"
#include "catp/lattice.h"
#include "catp_client/catp_gpu.h"
#include "gl_support.h"

using namespace catpaq;

namespace {

// A fragment of `n` vertices (valid positions) and `triangles` triangles.
FragmentMesh fragment(uint32_t n, uint32_t triangles) {
    FragmentMesh f;
    for (uint32_t i = 0; i < n; ++i) f.vertices.push_back(PackedVertex::make(i % kBaryIndexCount, 0, 1, 2, 3));
    for (uint32_t t = 0; t < triangles; ++t)
        for (uint32_t k = 0; k < 3; ++k) f.indices.push_back((t + k) % n);
    return f;
}

// Existing (diamond, slot) items: the root's six tetrahedra, then its children's.
std::vector<DrawItem> some_items(size_t count) {
    std::vector<DrawItem> items;
    std::vector<DiamondId> diamonds{root_diamond()};
    for (DiamondId c : diamond_children(root_diamond())) diamonds.push_back(c);
    for (DiamondId d : diamonds) {
        uint8_t mask = existing_slots(diamond_info(d));
        for (int s = 0; s < 8; ++s)
            if (mask & (1 << s)) items.push_back({d.bits, s});
    }
    items.resize(std::min(items.size(), count));
    return items;
}

}  // namespace

TEST(FragmentStore, CountsPackedAndFloatBytes) {
    GL_TEST_CONTEXT();
    FragmentStore store;
    std::vector<DrawItem> items = some_items(3);
    ASSERT_EQ(items.size(), 3u);
    store.upload(items[0].diamond_key, items[0].slot, fragment(100, 50));
    EXPECT_EQ(store.gpu_bytes(), 100u * 8 + 150 * 2);  // 8 bytes per vertex, 16-bit indices
    const GpuFragment* g = store.find(items[0].diamond_key, items[0].slot);
    ASSERT_NE(g, nullptr);
    EXPECT_FALSE(g->index32);
    EXPECT_EQ(g->format, VertexFormat::Packed);
    // Canonical corners of the slot's tetrahedron.
    Tetrahedron t = canonical_tetrahedron(diamond_tetrahedron(diamond_info(DiamondId{items[0].diamond_key}), items[0].slot));
    for (int i = 0; i < 4; ++i) EXPECT_EQ(g->corners[size_t(i)], t[size_t(i)]);

    store.upload(items[1].diamond_key, items[1].slot, fragment(70000, 10));  // >= 65536 vertices: 32-bit indices
    EXPECT_TRUE(store.find(items[1].diamond_key, items[1].slot)->index32);
    EXPECT_EQ(store.gpu_bytes(), 100u * 8 + 150 * 2 + 70000 * 8 + 30 * 4);

    CatpMeta meta;
    meta.cell = 1.0 / 1024;
    store.upload_float(items[2].diamond_key, items[2].slot, fragment(100, 50), meta);
    EXPECT_EQ(store.find(items[2].diamond_key, items[2].slot)->bytes, 100u * 28 + 150 * 2);
    EXPECT_EQ(store.size(), 3u);

    // Replacing an item replaces its bytes.
    store.upload(items[0].diamond_key, items[0].slot, fragment(10, 5));
    EXPECT_EQ(store.find(items[0].diamond_key, items[0].slot)->bytes, 10u * 8 + 15 * 2);
    EXPECT_TRUE(store.release(items[1].diamond_key, items[1].slot));
    EXPECT_FALSE(store.release(items[1].diamond_key, items[1].slot));
    EXPECT_EQ(store.gpu_bytes(), 10u * 8 + 15 * 2 + 100 * 28 + 150 * 2);
    store.clear();
    EXPECT_EQ(store.gpu_bytes(), 0u);
    EXPECT_EQ(store.size(), 0u);
}

TEST(FragmentStore, RejectsInvalidFragmentsAndLeavesTheStoreUnchanged) {
    GL_TEST_CONTEXT();
    FragmentStore store;
    DrawItem item = some_items(1)[0];
    store.upload(item.diamond_key, item.slot, fragment(10, 5));
    const uint64_t before = store.gpu_bytes();
    FragmentMesh bad_index = fragment(10, 5);
    bad_index.indices[4] = 10;
    EXPECT_THROW(store.upload(item.diamond_key, item.slot, bad_index), Error);
    FragmentMesh bad_position = fragment(10, 5);
    bad_position.vertices[3].word0 |= 0xffffffu;  // index >= kBaryIndexCount
    EXPECT_THROW(store.upload(item.diamond_key, item.slot, bad_position), Error);
    FragmentMesh ragged = fragment(10, 5);
    ragged.indices.pop_back();
    EXPECT_THROW(store.upload(item.diamond_key, item.slot, ragged), Error);
    EXPECT_THROW(store.upload(item.diamond_key, 8, fragment(10, 5)), Error);            // no slot 8
    EXPECT_THROW(store.upload(DiamondId::from_centre({0, 0, 0}).bits, 0, fragment(3, 1)), Error);  // a grid corner
    // The root is a cube diamond: ring of 6, so slots 6 and 7 do not exist.
    EXPECT_THROW(store.upload(root_diamond().bits, 6, fragment(3, 1)), Error);
    EXPECT_EQ(store.gpu_bytes(), before);
    EXPECT_EQ(store.size(), 1u);
}

TEST(FragmentStore, EvictsLeastRecentlyUsedUnpinnedFragmentsOverBudget) {
    GL_TEST_CONTEXT();
    FragmentStore store;
    std::vector<DrawItem> items = some_items(8);
    ASSERT_EQ(items.size(), 8u);
    const uint64_t each = 100 * 8 + 150 * 2;
    std::vector<DrawItem> evicted;
    store.set_eviction_callback([&](uint64_t key, int slot) { evicted.push_back({key, slot}); });

    // Frame 1: upload 4 items. Frame 2: upload 4 more and use item 0 again.
    for (int i = 0; i < 4; ++i) store.upload(items[i].diamond_key, items[i].slot, fragment(100, 50));
    store.begin_frame();
    for (int i = 4; i < 8; ++i) store.upload(items[i].diamond_key, items[i].slot, fragment(100, 50));
    store.mark_used(items[0].diamond_key, items[0].slot);
    store.pin(items[1].diamond_key, items[1].slot);
    EXPECT_EQ(store.gpu_bytes(), 8 * each);

    // Budget for 5: evicts the least recently used unpinned items of earlier frames: 2 and 3.
    // Item 1 is pinned; items 0 and 4..7 were used this frame; so it stays over budget (6 left).
    store.set_budget(5 * each);
    EXPECT_EQ(evicted, (std::vector<DrawItem>{items[2], items[3]}));
    EXPECT_EQ(store.size(), 6u);
    EXPECT_TRUE(store.over_budget());

    // Next frame only items 5 and 6 are used: the least recently used unpinned one goes, item 4
    // (uploaded in frame 2 before item 0 was used again in that frame).
    store.begin_frame();
    store.mark_used(items[5].diamond_key, items[5].slot);
    store.mark_used(items[6].diamond_key, items[6].slot);
    evicted.clear();
    EXPECT_EQ(store.evict_to_budget(), 1u);
    EXPECT_EQ(evicted, (std::vector<DrawItem>{items[4]}));
    EXPECT_EQ(store.gpu_bytes(), 5 * each);
    EXPECT_FALSE(store.over_budget());
    EXPECT_TRUE(store.resident(items[1].diamond_key, items[1].slot));  // pinned survives

    // Unpinning makes it evictable; a new upload over budget evicts the oldest (item 1, last used
    // in frame 1), never the new one.
    store.unpin(items[1].diamond_key, items[1].slot);
    store.begin_frame();
    evicted.clear();
    store.upload(items[2].diamond_key, items[2].slot, fragment(100, 50));
    EXPECT_EQ(evicted, (std::vector<DrawItem>{items[1]}));
    EXPECT_TRUE(store.resident(items[2].diamond_key, items[2].slot));
    EXPECT_EQ(store.gpu_bytes(), 5 * each);

    // No budget: nothing is evicted.
    store.set_budget(0);
    for (DrawItem it : items) store.upload(it.diamond_key, it.slot, fragment(100, 50));
    EXPECT_EQ(store.size(), 8u);
}
