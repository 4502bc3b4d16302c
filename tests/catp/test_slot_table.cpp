// The slot table (CATP meta versions 3 and 4) lets a client fetch one slot's fragment of a node by byte
// range: each range holds exactly that slot's fragment, decodable alone; a table that does not
// match the index is refused; datasets without one still read (nodes fetched whole).
#include <gtest/gtest.h>

#include <filesystem>

#include "base/error.h"
#include "catp/builder.h"
#include "catp/dataset.h"
#include "mesh/generators.h"
#include "scratch_directory.h"

using namespace catpaq;
namespace fs = std::filesystem;

namespace {

std::string build_torus(const std::string& name) {
    static const catpaq::test::ScratchDirectory dir("catpaq_slots_");
    std::string path = (dir / (name + ".cpq")).string();
    CatpBuildSettings settings;
    settings.leaf_triangles = 300;
    settings.progress = false;
    build_catp(make_torus(20000), path, settings);
    return path;
}

// The prefix of `file` (header, meta, index) with its meta replaced by `meta`, written as
// `version` (version 4's writer checks the table against the index, version 3's does not).
CatpIndex index_with_meta(const CatpFile& file, const CatpMeta& meta, uint32_t version = kCatpMetaVersion) {
    const ArchiveReader& a = file.archive();
    std::vector<ArchiveEntry> entries = a.entries();
    return CatpIndex(a.header(), encode_catp_meta(meta, entries, version), entries, "edited");
}

}  // namespace

TEST(SlotTable, EachSlotRangeHoldsExactlyThatSlotsFragment) {
    CatpFile file(build_torus("ranges"));
    const CatpIndex& index = file.index();
    ASSERT_TRUE(index.has_slot_ranges());
    size_t slots = 0;
    for (size_t i = 0; i < index.entries().size(); ++i) {
        const ArchiveEntry& e = index.entries()[i];
        DiamondFragments whole = file.decode(e);
        for (int s = 0; s < 8; ++s) {
            uint64_t offset = 0;
            uint32_t size = 0;
            const bool present = (e.flags & (1u << s)) != 0;
            ASSERT_EQ(index.slot_range(i, s, offset, size), present);
            if (!present) continue;
            ASSERT_GE(offset, e.offset);
            ASSERT_LE(offset + size, e.offset + e.size);
            FragmentMesh alone;
            ASSERT_EQ(fragment_decode(file.archive().data() + offset, size, alone), FragmentStatus::Ok);
            EXPECT_EQ(alone.indices, whole.slots[size_t(s)].indices);
            ASSERT_EQ(alone.vertices.size(), whole.slots[size_t(s)].vertices.size());
            for (size_t v = 0; v < alone.vertices.size(); ++v)
                ASSERT_EQ(alone.vertices[v].payload(), whole.slots[size_t(s)].vertices[v].payload());
            ++slots;
        }
    }
    EXPECT_GT(slots, index.entries().size());  // diamonds hold several slots
}

TEST(SlotTable, ATableThatDoesNotMatchTheIndexIsRefused) {
    CatpFile file(build_torus("mismatch"));
    CatpMeta meta = file.index().meta();
    ASSERT_FALSE(meta.slot_bytes.empty());

    // Version 3 stores every size as given: the reader refuses; version 4's writer refuses.
    CatpMeta longer = meta;
    longer.slot_bytes.push_back(7);
    EXPECT_THROW(index_with_meta(file, longer, 3), Error);
    EXPECT_THROW(index_with_meta(file, longer), Error);

    CatpMeta shorter = meta;
    shorter.slot_bytes.pop_back();
    EXPECT_THROW(index_with_meta(file, shorter, 3), Error);
    EXPECT_THROW(index_with_meta(file, shorter), Error);

    // Same count and total, a byte moved from the last entry's slot to the first entry's.
    ASSERT_GT(file.index().entries().size(), 1u);
    CatpMeta shifted = meta;
    shifted.slot_bytes.front() += 1;
    shifted.slot_bytes.back() -= 1;
    EXPECT_THROW(index_with_meta(file, shifted, 3), Error);
    EXPECT_THROW(index_with_meta(file, shifted), Error);
}

// Version 4 leaves each entry's last slot out (the entry's size implies it) and deflates the
// rest: the reader rebuilds exactly the table version 3 stores whole, from fewer bytes.
TEST(SlotTable, Version4ImpliesEachEntrysLastSlotAndReadsTheSameTable) {
    CatpFile file(build_torus("version4"));
    const CatpMeta& meta = file.index().meta();
    const std::vector<ArchiveEntry>& entries = file.archive().entries();
    ASSERT_FALSE(meta.slot_bytes.empty());
    const std::vector<uint8_t> v3 = encode_catp_meta(meta, entries, 3), v4 = encode_catp_meta(meta, entries);
    EXPECT_LT(v4.size(), v3.size());
    for (const std::vector<uint8_t>* bytes : {&v3, &v4}) {
        CatpMeta read;
        ASSERT_EQ(decode_catp_meta(bytes->data(), bytes->size(), read, &entries), "");
        EXPECT_EQ(read.slot_bytes, meta.slot_bytes);
    }
    // Without the index a version-4 table cannot be completed: it is left out.
    CatpMeta alone;
    ASSERT_EQ(decode_catp_meta(v4.data(), v4.size(), alone), "");
    EXPECT_TRUE(alone.slot_bytes.empty());
    // An index of another length, or an entry too short for its stored slots, is refused.
    std::vector<ArchiveEntry> fewer(entries.begin(), entries.end() - 1);
    CatpMeta read;
    EXPECT_NE(decode_catp_meta(v4.data(), v4.size(), read, &fewer), "");
    std::vector<ArchiveEntry> shrunk = entries;
    for (ArchiveEntry& e : shrunk)
        if (__builtin_popcount(e.flags & 0xffu) > 1) e.size = 8;
    EXPECT_NE(decode_catp_meta(v4.data(), v4.size(), read, &shrunk), "");
    // Every truncation of the table is refused with a message.
    for (size_t size = v4.size() - 40; size < v4.size(); ++size)
        EXPECT_NE(decode_catp_meta(v4.data(), size, read, &entries), "") << size;
}

TEST(SlotTable, ADatasetWithoutATableReadsAndHasNoSlotRanges) {
    CatpFile file(build_torus("untabled"));
    CatpMeta meta = file.index().meta();
    meta.slot_bytes.clear();
    CatpIndex index = index_with_meta(file, meta);
    EXPECT_FALSE(index.has_slot_ranges());
    uint64_t offset = 0;
    uint32_t size = 0;
    EXPECT_FALSE(index.slot_range(0, __builtin_ctz(index.entries()[0].flags | 0x100), offset, size));
}
