// AQP datasets end to end (aqp/build.h, aqp/dataset.h, aqp/verify.h): shared edge and corner
// samples bit-identical in every patch at every level, coarse levels exact subsets of fine ones,
// closed inputs giving closed welded meshes at every level, stored error bounds that hold against
// the input both ways and are monotone, and verify catching a dataset that breaks any of it.
#include <gtest/gtest.h>

#include <cmath>

#include "aqp/dataset.h"
#include "aqp/verify.h"
#include "base/error.h"
#include "common_codec/archive.h"
#include "mesh/generators.h"
#include "mesh/io.h"
#include "support.h"

using namespace catpaq;
using namespace catpaq::aqp;
using aqp::test::build;
using aqp::test::Built;

namespace {

const Built& sphere_dataset() {
    static const Built b = build(make_sphere(20000, 7), "sphere");
    return b;
}

const Built& bunny_dataset() {
    static const Built b = build(read_mesh(std::string(CATPAQ_SOURCE_DIR) + "/data/bunny.ply"), "bunny");
    return b;
}

const Built& torus_dataset() {
    AqpBuildOptions options;
    options.patch_level = 4;  // deeper than the default, for more levels
    static const Built b = build(make_torus(12000, 3), "torus", options);
    return b;
}

// The sphere with one patch per node at every level (no tiles).
const Built& sphere_untiled_dataset() {
    AqpBuildOptions options;
    options.tile_samples = 0;
    static const Built b = build(make_sphere(20000, 7), "sphere_untiled", options);
    return b;
}

// The metadata of an untiled dataset as version 2 or 3 wrote it: without the tile shifts
// (which follow the up axis, at byte 156: format.h), and the version number.
std::vector<uint8_t> meta_as_version(const AqpMeta& m, uint32_t version) {
    EXPECT_TRUE(m.tile_shift.empty());
    std::vector<uint8_t> bytes = encode_aqp_meta(m, 4);  // 58-byte patch records, as versions 1-4
    constexpr size_t kTileShiftOffset = 156;
    bytes.erase(bytes.begin() + kTileShiftOffset, bytes.begin() + kTileShiftOffset + m.patch_level + 1);
    bytes[8] = uint8_t(version);
    return bytes;
}

// Rewrites `from` into `to` with patch `patch` at `level` changed by `edit` (which gets the
// decoded grid, then its tile is re-encoded against the same coarser level). `version2`: every
// node in the RGB16 layout of metadata version 2, which can hold a level that does not nest
// (`from` must have no tiles).
void rewrite_with_edit(const std::string& from, const std::string& to, uint32_t patch, int level,
                       const std::function<void(PatchGrid&)>& edit, bool version2 = false) {
    AqpDataset d(from);
    const AqpMeta& meta = d.meta();
    ArchiveWriter w(to, ArchiveKind::Aqp);
    const std::vector<ArchiveEntry>& entries = d.archive().entries();
    for (size_t i = 0; i < entries.size(); ++i) {
        const uint32_t t = aqp_key_tile(entries[i].key);
        const int l = aqp_key_level(entries[i].key);
        const uint32_t first = meta.first_patch(t, l), count = meta.tile_patches(t, l);
        std::vector<std::vector<PatchGrid>> levels(count);
        std::vector<const PatchGrid*> grids, coarser;
        for (uint32_t q = 0; q < count; ++q) {
            levels[q] = d.decode_levels(first + q, l);
            if (first + q == patch && l == level) edit(levels[q].back());
            grids.push_back(&levels[q].back());
            if (l > 0) coarser.push_back(&levels[q][size_t(l) - 1]);
        }
        std::vector<uint8_t> node;
        if (version2) {
            EXPECT_EQ(count, 1u);
            node = encode_patch_node(*grids[0], l > 0 ? coarser[0] : nullptr, NodeLayout{meta.has_colors(), false});
        } else {
            node = encode_tile_node(grids, coarser, meta.has_colors(), 6,
                                    l == 0 && meta.node_layout().shared_corners ? meta.tile_patch_info(aqp_key_tile(entries[i].key), 0)
                                                                                : TilePatches{});
        }
        w.add_node(entries[i], node.data(), node.size());
    }
    w.finish(version2 ? meta_as_version(meta, 2) : d.archive().meta());
}

}  // namespace

TEST(AqpDataset, SharedEdgeAndCornerSamplesAreBitIdenticalAtEveryLevel) {
    for (const Built* b : {&sphere_dataset(), &torus_dataset(), &bunny_dataset()}) {
        AqpDataset d(b->path);
        AqpVerifyReport r = verify_aqp(d);
        EXPECT_EQ(r.shared_sample_mismatches, 0u) << b->path;
        EXPECT_EQ(r.corrupt_nodes, 0u) << (r.problems.empty() ? "" : r.problems[0]);
        EXPECT_EQ(r.nodes, d.archive().entries().size());
        EXPECT_TRUE(r.ok());
    }
}

TEST(AqpDataset, CoarseLevelsAreExactSubsetsOfFineOnes) {
    for (const Built* b : {&sphere_dataset(), &torus_dataset()}) {
        AqpDataset d(b->path);
        EXPECT_EQ(verify_aqp(d).nesting_mismatches, 0u);
        // And directly: level l's samples are level k's at stride 2^(k-l), in every patch.
        const int k = d.finest_level();
        for (uint32_t p = 0; p < d.patch_count(); p += 7) {
            const std::vector<PatchGrid> levels = d.decode_levels(p, k);
            for (int l = 0; l < k; ++l)
                for (int j = 0; j < levels[l].size; ++j)
                    for (int i = 0; i < levels[l].size; ++i) {
                        const int s = 1 << (k - l);
                        ASSERT_EQ(levels[l].position[levels[l].index(i, j)], levels[k].position[levels[k].index(i * s, j * s)]);
                        ASSERT_EQ(levels[l].normal[levels[l].index(i, j)], levels[k].normal[levels[k].index(i * s, j * s)]);
                    }
        }
    }
}

TEST(AqpDataset, AClosedInputWeldsIntoAClosedMeshAtEveryLevel) {
    for (const Built* b : {&sphere_dataset(), &torus_dataset(), &bunny_dataset()}) {
        AqpDataset d(b->path);
        for (int l = 0; l <= d.finest_level(); ++l) {
            const Mesh m = aqp_level_mesh(d, l);
            const EdgeCounts e = count_edges(m.indices);
            EXPECT_EQ(e.border, 0u) << b->path << " level " << l;
            EXPECT_EQ(e.nonmanifold, 0u) << b->path << " level " << l;
            // Welding merged every shared sample: without it the same mesh has borders.
            EXPECT_GT(count_edges(aqp_level_mesh(d, l, false).indices).border, 0u);
        }
    }
}

TEST(AqpDataset, StoredBoundsHoldAgainstTheInputBothWays) {
    aqp::test::expect_bounds_hold(make_sphere(20000, 7), sphere_dataset().path);
    aqp::test::expect_bounds_hold(read_mesh(std::string(CATPAQ_SOURCE_DIR) + "/data/bunny.ply"), bunny_dataset().path);
}

TEST(AqpDataset, StoredBoundsAreMonotoneAndShrinkTowardsTheFinestLevel) {
    const Built& b = torus_dataset();
    AqpDataset d(b.path);
    EXPECT_EQ(verify_aqp(d).monotonicity_violations, 0u);
    const int k = d.finest_level();
    ASSERT_GE(k, 3);
    for (uint32_t p = 0; p < d.patch_count(); ++p)
        for (int l = 0; l < k; ++l) ASSERT_GE(d.entry(p, l).error, d.entry(p, l + 1).error);
    // Refinement pays: the finest level's largest bound is well below the coarsest's.
    EXPECT_LT(b.report.levels[k].max_error, 0.25 * b.report.levels[0].max_error);
    // And the finest level is within a few quantization steps of the input where the input is
    // smooth and finely sampled.
    EXPECT_LT(b.report.levels[k].max_error, 0.01 * b.report.diagonal);
}

TEST(AqpDataset, TheReportAgreesWithTheDataset) {
    const Built& b = sphere_dataset();
    AqpDataset d(b.path);
    EXPECT_EQ(d.patch_count(), b.report.patches);
    EXPECT_EQ(d.finest_level(), b.report.patch_level);
    EXPECT_EQ(d.meta().input_triangles, 20000u);
    EXPECT_TRUE(d.meta().has_colors());
    EXPECT_EQ(d.meta().step, b.report.step);
    EXPECT_LE(b.report.precision, b.report.precision_asked * (1 + 1e-12));
    uint64_t payload = 0;
    for (const ArchiveEntry& e : d.archive().entries()) payload += e.size;
    EXPECT_EQ(payload, b.report.payload_bytes);
    EXPECT_NEAR(b.report.bits_per_sample, 8.0 * double(payload) / double(b.report.samples), 1e-9);
    EXPECT_EQ(b.report.location_misses, 0u);
}

TEST(AqpDataset, VerifyCatchesAMovedSharedEdgeSample) {
    const Built& b = sphere_dataset();
    const std::string broken = (aqp::test::scratch_dir() / "moved_edge.cpq").string();
    const int k = AqpDataset(b.path).finest_level();
    rewrite_with_edit(b.path, broken, 3, k, [](PatchGrid& g) { g.position[g.index(1, 0)][0] ^= 1; });
    AqpVerifyReport r = verify_aqp(AqpDataset(broken));
    EXPECT_EQ(r.shared_sample_mismatches, 1u);
    EXPECT_FALSE(r.ok());
    // ... and the welded mesh opens there.
    EXPECT_GT(count_edges(aqp_level_mesh(AqpDataset(broken), k).indices).border, 0u);
}

TEST(AqpDataset, VerifyCatchesACoarseSampleThatIsNotTheFineOne) {
    const Built& b = sphere_dataset();
    const std::string broken = (aqp::test::scratch_dir() / "not_nested.cpq").string();
    const int k = AqpDataset(b.path).finest_level();
    auto edit = [](PatchGrid& g) { g.normal[g.index(2, 2)] ^= 0x0101; };
    // Version 3 cannot hold it: a level stores only the samples its coarser level lacks, and the
    // encoder refuses a level that does not nest rather than drop the difference.
    EXPECT_THROW(rewrite_with_edit(b.path, broken, 5, k, edit), Error);
    // Version 2 stored every sample: verify finds the one that is not the coarser level's.
    rewrite_with_edit(sphere_untiled_dataset().path, broken, 5, k, edit, true);
    AqpVerifyReport r = verify_aqp(AqpDataset(broken));
    EXPECT_EQ(r.nesting_mismatches, 1u);
    EXPECT_FALSE(r.ok());
}

// Datasets written before byte planes (meta version 2, RGB16 node images) still read: the same
// dataset rewritten in the old layout decodes to the same samples at every level.
TEST(AqpDataset, AVersionTwoDatasetWithRgb16NodesDecodesTheSameSamples) {
    const std::string path = sphere_untiled_dataset().path;
    const std::string old_path = (aqp::test::scratch_dir() / "version2.cpq").string();
    AqpDataset d(path);
    ASSERT_TRUE(d.meta().node_layout().byte_planes);
    rewrite_with_edit(path, old_path, 0, 0, [](PatchGrid&) {}, true);
    AqpDataset old(old_path);
    EXPECT_EQ(old.meta().version, 2u);
    EXPECT_FALSE(old.meta().node_layout().byte_planes);
    EXPECT_EQ(old.meta().up_axis, d.meta().up_axis);
    for (uint32_t p = 0; p < d.patch_count(); p += 7) {
        const std::vector<PatchGrid> now = d.decode_levels(p, d.finest_level());
        const std::vector<PatchGrid> then = old.decode_levels(p, d.finest_level());
        for (size_t l = 0; l < now.size(); ++l) {
            EXPECT_EQ(then[l].position, now[l].position) << p << " " << l;
            EXPECT_EQ(then[l].normal, now[l].normal);
            EXPECT_EQ(then[l].color, now[l].color);
        }
    }
}

// Tiles change how nodes group patches, not the samples: the same sphere converted with tiles
// and without decodes to the same samples in every patch at every level, in fewer nodes and
// fewer bytes. And a version-3 dataset (before tiles: no tile shifts in the metadata, one patch
// per node, nodes laid out as a tile of one) still reads.
TEST(AqpDataset, TilesHoldTheSameSamplesInFewerNodesAndBytesAndVersionThreeStillReads) {
    AqpDataset tiled(sphere_dataset().path), untiled(sphere_untiled_dataset().path);
    ASSERT_EQ(tiled.patch_count(), untiled.patch_count());
    ASSERT_FALSE(tiled.meta().tile_shift.empty());
    EXPECT_GT(tiled.meta().shift(0), 0);
    EXPECT_LT(tiled.archive().entries().size(), untiled.archive().entries().size() / 2);
    EXPECT_LT(sphere_dataset().report.file_bytes, untiled.archive().header().file_size);
    std::printf("sphere: %zu nodes, %llu bytes with tiles; %zu nodes, %llu bytes without\n", tiled.archive().entries().size(),
                (unsigned long long)sphere_dataset().report.file_bytes, untiled.archive().entries().size(),
                (unsigned long long)untiled.archive().header().file_size);
    const std::string v3_path = (aqp::test::scratch_dir() / "version3.cpq").string();
    {
        ArchiveWriter w(v3_path, ArchiveKind::Aqp);
        for (size_t e = 0; e < untiled.archive().entries().size(); ++e) {
            std::string error;
            const uint8_t* bytes = untiled.archive().node(e, &error);
            ASSERT_NE(bytes, nullptr) << error;
            w.add_node(untiled.archive().entries()[e], bytes, untiled.archive().entries()[e].size);
        }
        w.finish(meta_as_version(untiled.meta(), 3));
    }
    AqpDataset v3(v3_path);
    EXPECT_EQ(v3.meta().version, 3u);
    for (uint32_t p = 0; p < tiled.patch_count(); ++p) {
        const std::vector<PatchGrid> a = tiled.decode_levels(p, tiled.finest_level());
        const std::vector<PatchGrid> b = untiled.decode_levels(p, tiled.finest_level());
        const std::vector<PatchGrid> c = v3.decode_levels(p, tiled.finest_level());
        for (size_t l = 0; l < a.size(); ++l) {
            ASSERT_EQ(a[l].position, b[l].position) << p << " " << l;
            ASSERT_EQ(a[l].normal, b[l].normal);
            ASSERT_EQ(a[l].color, b[l].color);
            ASSERT_EQ(c[l].position, b[l].position);
        }
    }
    EXPECT_TRUE(verify_aqp(tiled).ok());
    EXPECT_TRUE(verify_aqp(v3).ok());
}

TEST(AqpDataset, ACorruptNodeIsReportedNotACrash) {
    const Built& b = sphere_dataset();
    const std::string broken = (aqp::test::scratch_dir() / "corrupt.cpq").string();
    std::filesystem::copy_file(b.path, broken, std::filesystem::copy_options::overwrite_existing);
    {
        AqpDataset d(broken);
        const ArchiveEntry& e = d.entry(0, 1);
        FILE* f = std::fopen(broken.c_str(), "r+b");
        ASSERT_NE(f, nullptr);
        std::fseek(f, long(e.offset + e.size / 2), SEEK_SET);
        std::fputc(0x5a, f);
        std::fclose(f);
    }
    AqpDataset d(broken);
    EXPECT_THROW(d.decode(0, 1), Error);
    AqpVerifyReport r = verify_aqp(d);
    EXPECT_GT(r.corrupt_nodes, 0u);
    EXPECT_FALSE(r.ok());
}

TEST(AqpDataset, BadInputIsRefusedWithAMessageAndLeavesNoFile) {
    const std::string path = (aqp::test::scratch_dir() / "bad.cpq").string();
    std::filesystem::remove(path);
    Mesh empty;
    try {
        build(empty, "bad");
        FAIL() << "an empty mesh was converted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("no triangles"), std::string::npos) << e.what();
    }
    Mesh nan = make_sphere(500, 1);
    nan.positions[3][0] = std::nan("");
    EXPECT_THROW(build(nan, "bad"), Error);
    Mesh infinite = make_sphere(500, 1);
    infinite.positions[5][2] = INFINITY;
    EXPECT_THROW(build(infinite, "bad"), Error);
    EXPECT_THROW(build(aqp::test::moebius_band(40), "bad"), Error);
    AqpBuildOptions too_deep;
    too_deep.patch_level = kMaxPatchLevel + 1;
    EXPECT_THROW(build(make_sphere(500, 1), "bad", too_deep), Error);
    AqpBuildOptions tight;
    tight.memory_budget = 1 << 20;
    try {
        build(make_sphere(500, 1), "bad", tight);
        FAIL() << "a 1 MiB budget was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("budget"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(std::filesystem::exists(path));
}

// Tile shifts: the largest tiles within the target, one patch where a patch alone exceeds it,
// no larger than the dataset, nesting (non-increasing), none with a target of 0.
TEST(AqpTiles, ShiftsKeepTilesWithinTheTargetAndNest) {
    // Level l stores 4, 5, 16, 56, 208, 800 samples per patch (a finer level only the new ones).
    EXPECT_EQ(tile_shifts(5, 1272, 2048), (std::vector<uint8_t>{4, 4, 3, 2, 1, 0}));
    EXPECT_EQ(tile_shifts(5, 10, 2048), (std::vector<uint8_t>{2, 2, 2, 2, 1, 0}));  // 16 patches hold all 10
    EXPECT_EQ(tile_shifts(5, 1272, 0), (std::vector<uint8_t>(6, 0)));
    EXPECT_EQ(tile_shifts(3, 1, 1 << 20), (std::vector<uint8_t>(4, 0)));
    for (size_t target : {size_t(100), size_t(4096), size_t(1) << 24})
        for (size_t patches : {size_t(1), size_t(30), size_t(5000), size_t(1) << 22}) {
            const std::vector<uint8_t> s = tile_shifts(8, patches, target);
            for (int l = 0; l <= 8; ++l) {
                const uint64_t side = (uint64_t(1) << l) + 1, coarse = l ? (uint64_t(1) << (l - 1)) + 1 : 0;
                const uint64_t stored = side * side - coarse * coarse, tile = uint64_t(1) << (2 * s[size_t(l)]);
                if (l > 0) {
                    EXPECT_LE(s[size_t(l)], s[size_t(l) - 1]);
                }
                if (s[size_t(l)] > 0) {
                    EXPECT_LE(tile * stored, target);
                    EXPECT_LT(tile / 4, patches) << "no larger than needed to hold every patch";
                }
                EXPECT_LE(s[size_t(l)], kMaxTileShift);
            }
        }
}
