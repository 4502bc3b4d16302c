// The PNG data codec and the AQP byte formats (aqp/png_codec.h, aqp/format.h): exact round trips,
// golden metadata bytes, and decoders that refuse every truncation and corruption with a message
// instead of crashing.
#include <gtest/gtest.h>

#include <cstring>
#include <random>

#include "aqp/format.h"
#include "aqp/png_codec.h"
#include "base/checksum.h"
#include "base/error.h"

using namespace catpaq;
using namespace catpaq::aqp;

namespace {

PngImage random_image(int width, int height, int channels, int depth, uint64_t seed, bool smooth) {
    std::mt19937_64 rng(seed);
    PngImage im{width, height, channels, depth, {}};
    const int mask = (1 << depth) - 1;
    for (size_t i = 0; i < im.value_count(); ++i)
        im.values.push_back(uint16_t(smooth ? (i * 37 + rng() % 5) & mask : rng() & mask));
    return im;
}

// A patch grid with smooth positions and arbitrary normals and colours.
PatchGrid grid_at(int level, uint32_t patch, bool colors, uint64_t seed) {
    std::mt19937_64 rng(seed);
    PatchGrid g;
    g.patch = patch;
    g.level = level;
    g.size = (1 << level) + 1;
    for (int j = 0; j < g.size; ++j)
        for (int i = 0; i < g.size; ++i) {
            g.position.push_back({uint16_t(1000 * i + rng() % 7), uint16_t(65535 - 900 * j), uint16_t(rng() & 0xffff)});
            g.normal.push_back(uint16_t(rng()));
            if (colors) g.color.push_back({uint8_t(rng()), uint8_t(i * 8), uint8_t(255 - j)});
        }
    return g;
}

// The coarser level of g: every other sample.
PatchGrid coarser_of(const PatchGrid& g) {
    PatchGrid c;
    c.patch = g.patch;
    c.level = g.level - 1;
    c.size = g.size / 2 + 1;
    for (int j = 0; j < c.size; ++j)
        for (int i = 0; i < c.size; ++i) {
            const size_t s = g.index(2 * i, 2 * j);
            c.position.push_back(g.position[s]);
            c.normal.push_back(g.normal[s]);
            if (!g.color.empty()) c.color.push_back(g.color[s]);
        }
    return c;
}

AqpMeta small_meta() {
    AqpMeta m;
    m.patch_level = 3;
    m.base_vertices = 4;
    m.base_triangles = 4;
    m.flags = kAqpColorFlag;
    m.origin[0] = -1, m.origin[1] = 0.5, m.origin[2] = 2;
    m.step = 0.25;
    m.bounds_max[0] = m.bounds_max[1] = m.bounds_max[2] = 3;
    m.input_vertices = 4, m.input_triangles = 4;
    m.precision = 0.2165;
    m.mean_edge = 1.5;
    m.atlas_columns = 2;
    m.up_axis = 2;  // +y
    m.tile_shift = {1, 1, 0, 0};  // levels 0-1: both patches in one tile
    m.patches.resize(2);
    // A pillow: two patches sharing all four edges, running each the other way (edge e of
    // patch 0, from corner e to e + 1, is edge 3 - e of patch 1).
    m.patches[0].corner = {4, 0, 5, 1};
    m.patches[1].corner = {4, 1, 5, 0};
    for (uint8_t e = 0; e < 4; ++e) {
        m.patches[0].link[e] = {1, uint8_t(3 - e), true};
        m.patches[1].link[3 - e] = {0, e, true};
    }
    m.patches[1].origin = {7, 8, 9};
    m.patches[1].extent = {100, 200, 300};
    return m;
}

}  // namespace

TEST(AqpPng, RoundTripIsExactForEveryChannelCountAndDepthWithAndWithoutRowFilters) {
    for (int depth : {8, 16})
        for (int channels = 1; channels <= 4; ++channels)
            for (bool smooth : {false, true})
                for (bool filters : {true, false})
                    for (auto [w, h] : {std::pair{1, 1}, std::pair{3, 5}, std::pair{66, 33}}) {
                        PngImage in = random_image(w, h, channels, depth, uint64_t(depth * 100 + channels), smooth);
                        std::vector<uint8_t> bytes = png_encode(in, 6, filters);
                        PngImage out;
                        ASSERT_EQ(png_decode(bytes.data(), bytes.size(), w, h, channels, depth, out), "");
                        EXPECT_EQ(out.values, in.values)
                            << depth << "-bit, " << channels << " channels, " << w << "x" << h << (filters ? "" : ", no filters");
                    }
}

TEST(AqpPng, FullAlphaRangeIsNotPremultiplied) {
    // Every value of colour and alpha, including alpha 0 and 1 where a premultiplying codec
    // would zero or round the colour.
    PngImage in{256, 256, 4, 8, {}};
    for (int a = 0; a < 256; ++a)
        for (int c = 0; c < 256; ++c) in.values.insert(in.values.end(), {uint16_t(c), uint16_t(255 - c), uint16_t(c ^ a), uint16_t(a)});
    std::vector<uint8_t> bytes = png_encode(in);
    PngImage out;
    ASSERT_EQ(png_decode(bytes.data(), bytes.size(), 256, 256, 4, 8, out), "");
    EXPECT_EQ(out.values, in.values);
}

TEST(AqpPng, DecoderRefusesEveryTruncationAndOtherShapes) {
    PngImage in = random_image(17, 9, 3, 16, 3, true);
    std::vector<uint8_t> bytes = png_encode(in);
    PngImage out;
    for (size_t n = 0; n < bytes.size(); ++n) EXPECT_NE(png_decode(bytes.data(), n, 17, 9, 3, 16, out), "") << n << " bytes";
    EXPECT_NE(png_decode(bytes.data(), bytes.size(), 17, 9, 3, 8, out), "");   // other depth
    EXPECT_NE(png_decode(bytes.data(), bytes.size(), 17, 9, 4, 16, out), "");  // other channels
    EXPECT_NE(png_decode(bytes.data(), bytes.size(), 9, 17, 3, 16, out), "");  // other size
    std::vector<uint8_t> longer = bytes;
    longer.push_back(0);
    EXPECT_NE(png_decode(longer.data(), longer.size(), 17, 9, 3, 16, out), "");  // trailing bytes
}

TEST(AqpPng, DecoderSurvivesCorruptBytes) {
    PngImage in = random_image(33, 17, 3, 16, 4, true);
    const std::vector<uint8_t> bytes = png_encode(in);
    std::mt19937_64 rng(9);
    size_t refused = 0;
    for (int trial = 0; trial < 2000; ++trial) {
        std::vector<uint8_t> bad = bytes;
        for (int flips = 1 + int(rng() % 3); flips > 0; --flips) bad[rng() % bad.size()] ^= uint8_t(1 + rng() % 255);
        PngImage out;
        std::string e = png_decode(bad.data(), bad.size(), 33, 17, 3, 16, out);
        refused += !e.empty();  // (a flip in ancillary bits may decode; it must never crash)
    }
    EXPECT_GT(refused, 1900u);  // PNG's CRCs catch nearly all
}

TEST(AqpFormat, PatchNodeRoundTripIsExactAtEveryLevelInBothLayouts) {
    for (bool colors : {false, true})
    for (bool planes : {true, false}) {
        const NodeLayout layout{colors, planes};
        PatchGrid finest = grid_at(5, 42, colors, 11);
        std::vector<PatchGrid> levels{finest};
        while (levels.back().level > 0) levels.push_back(coarser_of(levels.back()));
        std::reverse(levels.begin(), levels.end());
        PatchGrid decoded_coarser;
        for (const PatchGrid& g : levels) {
            const PatchGrid* coarser = g.level > 0 ? &decoded_coarser : nullptr;
            std::vector<uint8_t> node = encode_patch_node(g, coarser, layout);
            PatchGrid out;
            ASSERT_EQ(decode_patch_node(node.data(), node.size(), 42, g.level, layout, coarser, out), "") << g.level;
            // A node read as the other layout is refused (its image has another shape).
            PatchGrid wrong;
            EXPECT_NE(decode_patch_node(node.data(), node.size(), 42, g.level, NodeLayout{colors, !planes}, coarser, wrong), "");
            EXPECT_EQ(out.position, g.position);
            EXPECT_EQ(out.normal, g.normal);
            EXPECT_EQ(out.color, g.color);
            decoded_coarser = out;
        }
    }
}

TEST(AqpFormat, PatchNodeDecoderRefusesTruncationsAndMissingCoarserLevels) {
    PatchGrid g = grid_at(3, 7, true, 12);
    PatchGrid c = coarser_of(g);
    const NodeLayout with{true, true}, without{false, true};
    std::vector<uint8_t> node = encode_patch_node(g, &c, with);
    PatchGrid out;
    for (size_t n = 0; n < node.size(); ++n) EXPECT_NE(decode_patch_node(node.data(), n, 7, 3, with, &c, out), "");
    EXPECT_NE(decode_patch_node(node.data(), node.size(), 7, 3, with, nullptr, out), "");  // no coarser level
    EXPECT_NE(decode_patch_node(node.data(), node.size(), 7, 2, with, &c, out), "");       // another level
    EXPECT_NE(decode_patch_node(node.data(), node.size(), 7, 3, without, &c, out), "");    // colours unexpected
    EXPECT_NE(decode_patch_node(node.data(), node.size(), 7, 99, with, &c, out), "");      // level out of range
}

// Level-0 grids of patches over quad vertices with world grid positions `world` (and a
// normal and colour each): patch q's sample at corner c is its quad vertex's, in q's frame.
std::vector<PatchGrid> level0_grids(const TilePatches& patches, const std::vector<std::array<uint32_t, 3>>& world) {
    constexpr int kCornerOfSample[4] = {0, 1, 3, 2};  // grid order (0,0), (1,0), (0,1), (1,1)
    std::vector<PatchGrid> grids;
    for (uint32_t q = 0; q < patches.size(); ++q) {
        PatchGrid& g = grids.emplace_back();
        g.patch = 10 + q;
        g.level = 0;
        g.size = 2;
        for (int s = 0; s < 4; ++s) {
            const uint32_t v = patches[q].corner[size_t(kCornerOfSample[s])];
            std::array<uint16_t, 3> local{};
            for (int a = 0; a < 3; ++a) local[size_t(a)] = uint16_t(world[v][size_t(a)] - patches[q].origin[size_t(a)]);
            g.position.push_back(local);
            g.normal.push_back(uint16_t(v * 977));
            g.color.push_back({uint8_t(v * 3), uint8_t(v * 5), uint8_t(v * 7)});
        }
    }
    return grids;
}

// Version 5's level-0 tiles store each shared quad vertex once, positions moved between the
// patches' frames: the tile decodes to every patch's own samples, in fewer bytes than four a
// patch; a decoder without the patch records, or with records that move a corner out of a
// patch's frame, refuses; an encoder refuses patches that differ at a shared corner.
TEST(AqpFormat, LevelZeroTilesStoreSharedCornersOnceAndDecodeEveryPatchsOwn) {
    // A strip of patches along quad vertices 0..n: patch q has corners (q, q+1, q+2, q+3) mod n,
    // so neighbours share three; origins differ per patch.
    const uint32_t n = 40;
    TilePatches patches(24);
    std::vector<std::array<uint32_t, 3>> world(n);
    for (uint32_t v = 0; v < n; ++v) world[v] = {1000 + 37 * v, 2000 + 11 * (v % 7), 3000 + 5 * v};
    for (uint32_t q = 0; q < patches.size(); ++q) {
        patches[q].corner = {q % n, (q + 1) % n, (q + 2) % n, (q + 3) % n};
        patches[q].origin = {900 + q, 1990, 2990 - q};
    }
    const std::vector<PatchGrid> grids = level0_grids(patches, world);
    std::vector<const PatchGrid*> ptrs;
    for (const PatchGrid& g : grids) ptrs.push_back(&g);
    const std::vector<uint8_t> shared = encode_tile_node(ptrs, {}, true, 6, patches);
    const std::vector<uint8_t> every = encode_tile_node(ptrs, {}, true, 6);
    EXPECT_LT(shared.size(), every.size());
    std::vector<PatchGrid> out;
    ASSERT_EQ(decode_tile_node(shared.data(), shared.size(), 10, uint32_t(grids.size()), 0, NodeLayout{true, true, true}, {}, out,
                               patches),
              "");
    ASSERT_EQ(out.size(), grids.size());
    for (size_t q = 0; q < grids.size(); ++q) {
        EXPECT_EQ(out[q].patch, grids[q].patch);
        EXPECT_EQ(out[q].position, grids[q].position) << q;
        EXPECT_EQ(out[q].normal, grids[q].normal) << q;
        EXPECT_EQ(out[q].color, grids[q].color) << q;
    }
    // The version-4 layout reads as before.
    ASSERT_EQ(decode_tile_node(every.data(), every.size(), 10, uint32_t(grids.size()), 0, NodeLayout{true, true, false}, {}, out),
              "");
    EXPECT_EQ(out[5].position, grids[5].position);
    // Without the records, or with one whose frame the corner falls outside of.
    EXPECT_NE(decode_tile_node(shared.data(), shared.size(), 10, uint32_t(grids.size()), 0, NodeLayout{true, true, true}, {}, out),
              "");
    TilePatches moved = patches;
    moved[7].origin[0] = 5000;
    EXPECT_NE(decode_tile_node(shared.data(), shared.size(), 10, uint32_t(grids.size()), 0, NodeLayout{true, true, true}, {}, out,
                               moved),
              "");
    // Patches that disagree at a shared corner cannot be stored.
    std::vector<PatchGrid> differing = grids;
    differing[3].normal[1] ^= 1;
    std::vector<const PatchGrid*> differing_ptrs;
    for (const PatchGrid& g : differing) differing_ptrs.push_back(&g);
    EXPECT_THROW(encode_tile_node(differing_ptrs, {}, true, 6, patches), Error);
}

TEST(AqpFormat, MetadataRoundTripsAndHasGoldenBytes) {
    const AqpMeta m = small_meta();
    const std::vector<uint8_t> bytes = encode_aqp_meta(m);
    // 8 magic + 7 u32 + 10 f64 + 2 u64 + 2 f64 + 2 u32 = 156 bytes, a tile shift per level (4),
    // then the deflated patch table (docs/formats/aqp.md); a few fields at their documented offsets.
    auto u32_at = [&](size_t at) { return uint32_t(bytes[at] | bytes[at + 1] << 8 | bytes[at + 2] << 16 | uint32_t(bytes[at + 3]) << 24); };
    auto f64_at = [&](size_t at) {
        uint64_t u = 0;
        for (int i = 0; i < 8; ++i) u |= uint64_t(bytes[at + i]) << (8 * i);
        double d;
        std::memcpy(&d, &u, 8);
        return d;
    };
    EXPECT_EQ(std::string(bytes.begin(), bytes.begin() + 8), std::string("AQPMETA\0", 8));
    EXPECT_EQ(u32_at(8), kAqpMetaVersion);
    EXPECT_EQ(u32_at(12), 3u);     // finest level
    EXPECT_EQ(u32_at(16), 2u);     // patches
    EXPECT_EQ(u32_at(32), 1u);     // flags: colours
    EXPECT_EQ(f64_at(36), -1.0);   // origin x
    EXPECT_EQ(f64_at(60), 0.25);   // step
    EXPECT_EQ(u32_at(148), 2u);    // atlas columns
    EXPECT_EQ(u32_at(152), 2u);    // up axis: +y
    EXPECT_EQ(bytes[156], 1);      // tile shift, level 0
    EXPECT_EQ(bytes[159], 0);      // tile shift, level 3
    EXPECT_EQ(bytes[160], 0x78);   // the patch table's zlib header
    // Golden: any change to the layout must be deliberate (and the version bumped). The fixed
    // fields only: deflate's output may differ between zlib versions (the round trip below
    // covers the patch table).
    EXPECT_EQ(checksum64(bytes.data(), 160), 15728355483238253114ull);  // version 5 (packed patch table)
    AqpMeta out;
    ASSERT_EQ(decode_aqp_meta(bytes.data(), bytes.size(), out), "");
    EXPECT_EQ(encode_aqp_meta(out), bytes);
    EXPECT_EQ(out.version, 5u);
    for (size_t p = 0; p < 2; ++p) {
        EXPECT_EQ(out.patches[p].corner, m.patches[p].corner);
        EXPECT_EQ(out.patches[p].origin, m.patches[p].origin);
        EXPECT_EQ(out.patches[p].extent, m.patches[p].extent);
        for (size_t e = 0; e < 4; ++e) {  // links derived from the corners, as they were
            EXPECT_EQ(out.patches[p].link[e].patch, m.patches[p].link[e].patch);
            EXPECT_EQ(out.patches[p].link[e].edge, m.patches[p].link[e].edge);
            EXPECT_TRUE(out.patches[p].link[e].reversed);
        }
    }
    EXPECT_EQ(out.world(1, 0, 4), -1 + 0.25 * (7 + 4));
    EXPECT_EQ(out.up_axis, 2u);
    EXPECT_EQ(out.tile_shift, m.tile_shift);
    EXPECT_EQ(out.tile_count(0), 1u);
    EXPECT_EQ(out.tile_patches(0, 1), 2u);
    EXPECT_EQ(out.tile_count(2), 2u);
    EXPECT_EQ(out.tile_of(1, 3), 1u);
}

// Version 4 metadata (58-byte patch records with explicit links) still reads.
TEST(AqpFormat, VersionFourMetadataStillReads) {
    const AqpMeta m = small_meta();
    const std::vector<uint8_t> bytes = encode_aqp_meta(m, 4);
    constexpr size_t P = 160;  // the first patch record
    ASSERT_EQ(bytes.size(), P + 2 * 58);
    auto u32_at = [&](size_t at) { return uint32_t(bytes[at] | bytes[at + 1] << 8 | bytes[at + 2] << 16 | uint32_t(bytes[at + 3]) << 24); };
    EXPECT_EQ(u32_at(8), 4u);
    EXPECT_EQ(u32_at(P + 8), 5u);                     // patch 0, corner 2
    EXPECT_EQ(u32_at(P + 16), 1u);                    // patch 0, link 0: patch 1
    EXPECT_EQ(bytes[P + 16 + 4], 3);                  //   its edge 3
    EXPECT_EQ(bytes[P + 16 + 5], 1);                  //   reversed
    EXPECT_EQ(u32_at(P + 58 + 40), 7u);               // patch 1, origin x
    EXPECT_EQ(bytes[P + 58 + 52] | bytes[P + 58 + 53] << 8, 100);  // patch 1, extent x
    EXPECT_EQ(checksum64(bytes.data(), bytes.size()), 10179197746726957704ull);  // the version-4 layout
    AqpMeta out;
    ASSERT_EQ(decode_aqp_meta(bytes.data(), bytes.size(), out), "");
    EXPECT_EQ(out.version, 4u);
    EXPECT_EQ(encode_aqp_meta(out, 4), bytes);
    EXPECT_EQ(encode_aqp_meta(out), encode_aqp_meta(m));  // the same metadata in version 5
}

// Version 1 metadata (before the up axis) still reads, with no up axis.
TEST(AqpFormat, VersionOneMetadataReadsWithoutAnUpAxis) {
    std::vector<uint8_t> v1 = encode_aqp_meta(small_meta(), 4);
    v1.erase(v1.begin() + 152, v1.begin() + 160);  // the up axis and the tile shifts
    v1[8] = 1;
    AqpMeta out;
    ASSERT_EQ(decode_aqp_meta(v1.data(), v1.size(), out), "");
    EXPECT_EQ(out.up_axis, 0u);
    EXPECT_FALSE(out.node_layout().byte_planes);  // versions 1-2 store RGB16 node images
    EXPECT_EQ(out.patches.size(), 2u);
    EXPECT_EQ(out.patches[1].extent[0], 100);
    EXPECT_TRUE(out.tile_shift.empty());  // one patch per node
    EXPECT_EQ(out.tile_count(0), 2u);
}

// Links come from the corners: an edge between two quad vertices that three patch edges run
// cannot be linked, and is refused (by the reader, and by the writer, which also refuses links
// other than the corners imply).
TEST(AqpFormat, LinksDerivedFromCornersRefuseEdgesOfMoreThanTwoPatches) {
    AqpMeta m = small_meta();
    std::vector<AqpPatchInfo> patches = m.patches;
    ASSERT_EQ(derive_patch_links(patches), "");
    AqpPatchInfo third = patches[0];
    third.corner = {4, 0, 6, 7};  // runs 4 -> 0 as patch 0 does, and patch 1 the other way
    patches.push_back(third);
    EXPECT_NE(derive_patch_links(patches).find("3 patch edges"), std::string::npos) << derive_patch_links(patches);
    m.patches[0].link[1].patch = kNone;  // not what the corners say
    EXPECT_THROW(encode_aqp_meta(m), Error);
    AqpPatchInfo repeated = m.patches[0];
    repeated.corner = {4, 4, 5, 1};
    std::vector<AqpPatchInfo> one{repeated};
    EXPECT_NE(derive_patch_links(one), "");
}

TEST(AqpFormat, MetadataDecoderRefusesTruncationsAndBrokenFields) {
    for (uint32_t version : {4u, kAqpMetaVersion}) {
        const std::vector<uint8_t> bytes = encode_aqp_meta(small_meta(), version);
        AqpMeta out;
        for (size_t n = 0; n < bytes.size(); ++n)
            EXPECT_NE(decode_aqp_meta(bytes.data(), n, out), "") << n << " bytes, version " << version;
        auto refused = [&](auto&& change) {
            AqpMeta m = small_meta();
            change(m);
            std::vector<uint8_t> b = encode_aqp_meta(m, version);
            return !decode_aqp_meta(b.data(), b.size(), out).empty();
        };
        if (version == 4) {  // version 5 stores no links
            EXPECT_TRUE(refused([](AqpMeta& m) { m.patches[0].link[1].patch = 0; }));  // a link that does not link back
            EXPECT_TRUE(refused([](AqpMeta& m) { m.patches[1].link[0].patch = 5; }));  // out of range
        }
        EXPECT_TRUE(refused([](AqpMeta& m) { m.patches[0].corner[2] = m.patches[1].corner[2] = 99; }));  // no such quad vertex
        EXPECT_TRUE(refused([](AqpMeta& m) { m.patch_level = kMaxPatchLevel + 1; }));
        EXPECT_TRUE(refused([](AqpMeta& m) { m.step = 0; }));
        EXPECT_TRUE(refused([](AqpMeta& m) { m.atlas_columns = 3; }));
        EXPECT_TRUE(refused([](AqpMeta& m) { m.up_axis = 7; }));
        EXPECT_TRUE(refused([](AqpMeta& m) { m.tile_shift = {0, 1, 0, 0}; }));  // tiles that do not nest
        EXPECT_TRUE(refused([](AqpMeta& m) { m.tile_shift = {16, 1, 0, 0}; }));  // above kMaxTileShift
        std::vector<uint8_t> other_version = bytes;
        other_version[8] = uint8_t(kAqpMetaVersion + 1);
        EXPECT_NE(decode_aqp_meta(other_version.data(), other_version.size(), out).find("version"), std::string::npos);
        // A patch count the patch table does not hold, a huge one included (refused before
        // anything that large is allocated).
        for (uint32_t count : {3u, 0x7fffffffu}) {
            std::vector<uint8_t> more = bytes;
            for (int i = 0; i < 4; ++i) more[16 + i] = uint8_t(count >> (8 * i));
            EXPECT_NE(decode_aqp_meta(more.data(), more.size(), out), "") << count << " patches, version " << version;
        }
    }
    // A broken byte in the deflated patch table.
    std::vector<uint8_t> bytes = encode_aqp_meta(small_meta());
    for (size_t at = 161; at < bytes.size(); ++at) {
        std::vector<uint8_t> broken = bytes;
        broken[at] ^= 0x5a;
        AqpMeta out;
        const std::string e = decode_aqp_meta(broken.data(), broken.size(), out);
        // Deflate's Adler-32 catches what the table's own checks do not.
        EXPECT_NE(e, "") << "byte " << at;
    }
}
