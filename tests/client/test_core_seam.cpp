// The format seam without GL: a second format (tests/client/box_format.h, a quadtree of flat
// cells) registered here, opened from its prefix and streamed by the same Fetcher, NodeStore and
// CutEngine that stream CATP, none of them changed for it.
#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "base/error.h"
#include "box_format.h"
#include "client/cache.h"
#include "client/cut_engine.h"
#include "client/fetcher.h"
#include "client/format.h"
#include "test_core_support.h"

using namespace catpaq;

namespace {

const std::string& box_dataset() {
    static std::string path = [] {
        std::string p = test::scratch_dir() + "/boxes.cpq";
        test::write_box_dataset(p, test::BoxDatasetSettings{});
        return p;
    }();
    return path;
}

FormatRegistry box_registry() {
    FormatRegistry registry;
    registry.add(test::box_format_module());
    return registry;
}

// Steps engine, fetcher and store as a session does, until a frame changes nothing and nothing
// is on its way; checks the engine's state every frame.
const CutFrame& converge(CutEngine& engine, Fetcher& fetcher, NodeStore& store, const Hierarchy& h, const ViewParams& view) {
    std::vector<FetchedNode> arrived;
    for (int frame = 0; frame < 2000; ++frame) {
        arrived.clear();
        fetcher.poll(arrived);
        for (FetchedNode& n : arrived) {
            EXPECT_TRUE(n.ok) << n.error;
            if (n.ok) store.add(n.node, n.decoded, n.compressed);
        }
        const CutFrame& f = engine.update(view, store);
        store.pin(engine.pinned());
        std::vector<FetchRequest> wanted;
        for (const CutRequest& r : f.requests) wanted.push_back(FetchRequest::of(h.node(r.node)));
        fetcher.request(wanted);
        EXPECT_EQ(engine.check(store), "");
        if (arrived.empty() && f.requests.empty() && f.stats.refinements == 0 && f.stats.coarsenings == 0 &&
            fetcher.idle())
            return f;
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    ADD_FAILURE() << "the cut did not settle";
    return engine.last_frame();
}

}  // namespace

TEST(FormatSeam, ARegistryOpensADatasetByItsArchiveKind) {
    std::unique_ptr<NodeSource> source = open_node_source(box_dataset());
    DatasetPrefix prefix = load_prefix(*source);
    EXPECT_EQ(prefix.header.kind, ArchiveKind::Points);
    FormatRegistry registry = box_registry();
    std::unique_ptr<DatasetFormat> format = registry.module_for(prefix).open(prefix);
    const Hierarchy& h = format->hierarchy();
    EXPECT_EQ(h.size(), size_t(1 + 4 + 16 + 64 + 256));
    EXPECT_EQ(h.roots().size(), 1u);
    EXPECT_EQ(h.check(), "");
    EXPECT_EQ(format->summary().node_noun, "cells");
    // A registry without the kind names the dataset and its kind.
    FormatRegistry empty;
    try {
        empty.module_for(prefix);
        ADD_FAILURE() << "no module, yet opened";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("holds a dataset of kind points"), std::string::npos) << e.what();
    }
}

TEST(FormatSeam, TheFetcherNodeStoreAndCutEngineStreamAnotherFormat) {
    std::unique_ptr<NodeSource> source = open_node_source(box_dataset());
    DatasetPrefix prefix = load_prefix(*source);
    FormatRegistry registry = box_registry();
    std::unique_ptr<DatasetFormat> format = registry.module_for(prefix).open(prefix);
    const Hierarchy& h = format->hierarchy();
    FetcherSettings fetcher_settings;
    fetcher_settings.decode = format_decoder(*format);
    Fetcher fetcher(std::move(source), fetcher_settings);
    NodeStore store(h, uint64_t(64) << 20, uint64_t(8) << 20);
    CutEngine engine(h, store.counter());

    // Above the square's centre: every cell of the finest level is needed (level 3 projects to
    // about 2.7 px, the leaves to 1.35 px), and drawn.
    ViewParams view = test::camera({50, 50, 300}, {50, 50, 0}, 1.5);
    const CutFrame& fine = converge(engine, fetcher, store, h, view);
    EXPECT_EQ(fine.stats.holes, 0u);
    EXPECT_EQ(fine.stats.drawn_nodes, 256u);
    EXPECT_EQ(fine.stats.primitives, 256u * 32);
    EXPECT_LE(fine.stats.certified_error_px, 1.5);
    uint64_t drawn = 0;
    for (uint32_t n : engine.drawn_nodes()) {
        EXPECT_EQ(h.node(n).level, 4);
        std::shared_ptr<const DecodedNode> decoded = store.decoded(n);
        ASSERT_TRUE(decoded);
        ASSERT_EQ(decoded->part_primitives.size(), 1u);
        drawn += decoded->part_primitives[0];
        EXPECT_TRUE(h.node(n).bounds.contains(decoded->data_bounds));
        EXPECT_EQ(decoded->bytes.cpu, uint64_t(decoded->part_primitives[0]) * 36);
    }
    EXPECT_EQ(drawn, fine.stats.primitives);
    FetcherStats fs = fetcher.stats();
    EXPECT_GT(fs.delivered, 256u);
    EXPECT_EQ(fs.checksum_failures + fs.decode_failures + fs.transport_errors, 0u);

    // Far away the root alone is enough: the cut coarsens back to it.
    view.tolerance_px = 100;
    const CutFrame& coarse = converge(engine, fetcher, store, h, view);
    EXPECT_EQ(coarse.stats.drawn_nodes, 1u);
    EXPECT_EQ(coarse.stats.primitives, 32u);
    EXPECT_EQ(engine.drawn_nodes(), h.roots());
}

TEST(FormatSeam, TheFetcherReportsWhatTheFormatsDecoderRefuses) {
    std::unique_ptr<NodeSource> source = open_node_source(box_dataset());
    DatasetPrefix prefix = load_prefix(*source);
    test::BoxFormat format(prefix);
    const Hierarchy& h = format.hierarchy();
    // The bytes pass the checksum and decode; the decoder given to the fetcher refuses them all
    // the same: a decode failure, reported as the fetcher reports CATP's.
    FetcherSettings settings;
    settings.max_attempts = 1;
    settings.decode = [&](const FetchRequest& r, const uint8_t* data, size_t size, std::shared_ptr<const DecodedNode>& out) {
        std::string problem = format.decode(r.node, data, size, out);
        return problem.empty() ? std::string("the test refuses node ") + std::to_string(r.key) : problem;
    };
    Fetcher fetcher(std::move(source), settings);
    fetcher.request({FetchRequest::of(h.node(h.roots()[0]))});
    std::vector<FetchedNode> got;
    for (int i = 0; i < 20000 && got.empty(); ++i) {
        fetcher.poll(got);
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    ASSERT_EQ(got.size(), 1u);
    EXPECT_FALSE(got[0].ok);
    EXPECT_NE(got[0].error.find("the test refuses node"), std::string::npos) << got[0].error;
    EXPECT_EQ(fetcher.stats().decode_failures, 1u);
}
