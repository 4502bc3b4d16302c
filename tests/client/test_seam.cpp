// The format seam end to end: a second, test-only format (box_format.h, its GPU side in
// box_renderer.h) registered in a FormatRegistry of the test, streamed by the unchanged
// StreamingSession from a local file and from `catpaq serve` (which knows nothing of it), drawn
// headless, and picked by the viewer's pick_cut.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "box_format.h"
#include "box_renderer.h"
#include "client/gl_context.h"
#include "common_codec/archive.h"
#include "client/session.h"
#include "client/viewer.h"
#include "scratch_directory.h"
#include "server/server.h"

namespace fs = std::filesystem;
using namespace catpaq;

namespace {

// The served root, in the process's scratch directory.
const fs::path& root_dir() {
    static const test::ScratchDirectory dir("catpaq_seam_");
    static const fs::path root = [] {
        fs::create_directories(dir / "root");
        return dir / "root";
    }();
    return root;
}

// The box dataset, in a directory a server can serve.
const std::string& box_dataset() {
    static std::string path = [] {
        std::string p = (root_dir() / "boxes.cpq").string();
        test::write_box_dataset(p, test::BoxDatasetSettings{});
        return p;
    }();
    return path;
}

const FormatRegistry& box_registry() {
    static const FormatRegistry registry = [] {
        FormatRegistry r;
        r.add(test::box_format_module_with_renderer());
        return r;
    }();
    return registry;
}

// Above the square's centre, the whole square in view (its half width is 2/3 of the view's half
// height): level 3 projects to about 2.4 px, the leaves to 1.3 px.
Camera top_camera() {
    Camera c;
    c.eye = {50, 50, 180};
    c.target = {50, 50, 0};
    c.up = {0, 1, 0};
    c.fov_y_degrees = 45;
    c.width = 320;
    c.height = 240;
    return c;
}

// `catpaq serve` of the root on a free port, one thread, silent.
ServerSettings served_root_settings() {
    ServerSettings s;
    s.root = root_dir().string();
    s.port = 0;
    s.threads = 1;
    s.log_level = LogLevel::Error;
    s.log = [](LogLevel, std::string_view) {};
    return s;
}

SessionFrameStats settle(StreamingSession& session, const Camera& camera) {
    SessionFrameStats s = session.step(camera);
    for (int i = 0; i < 20000 && !session.settled(); ++i) {
        usleep(1000);
        s = session.step(camera);
    }
    EXPECT_TRUE(session.settled());
    return s;
}

void expect_all_leaves_drawn(StreamingSession& session, const SessionFrameStats& s) {
    EXPECT_TRUE(session.failures().empty());
    EXPECT_TRUE(s.tolerance_met);
    EXPECT_EQ(s.holes, 0u);
    EXPECT_EQ(s.drawn_nodes, 256u);
    EXPECT_EQ(s.triangles, 256u * 32);
    EXPECT_EQ(s.fragments, 256u);
    ASSERT_EQ(session.items().size(), 256u);
    uint64_t triangles = 0;
    const Hierarchy& h = session.hierarchy();
    for (const DrawnPart& item : session.items()) {
        const DecodedNode* decoded = session.decoded(item.key, item.part);
        ASSERT_NE(decoded, nullptr);
        const HierarchyNode& node = h.node(h.find(item.key));
        for (size_t i = 0; i < node.parts.size(); ++i)  // part_primitives follow HierarchyNode::parts
            if (node.parts[i].id == item.part) triangles += decoded->part_primitives.at(i);
    }
    EXPECT_EQ(triangles, s.triangles);
    EXPECT_GE(s.gpu_bytes, s.triangles * 36);  // the box renderer's float vertices, and earlier levels
}

}  // namespace

TEST(FormatSeam, AStreamingSessionStreamsDrawsAndPicksAnotherFormat) {
    std::string why;
    if (!HeadlessGlContext::available(&why)) GTEST_SKIP() << why;
    HeadlessGlContext context;
    SessionSettings settings;
    settings.formats = &box_registry();
    StreamingSession session(box_dataset(), settings);
    EXPECT_EQ(session.hierarchy().size(), size_t(1 + 4 + 16 + 64 + 256));
    const Camera camera = top_camera();
    SessionFrameStats s = settle(session, camera);
    expect_all_leaves_drawn(session, s);
    EXPECT_GT(s.bytes_fetched, 0u);

    // Drawn headless: every drawn part once, the square in the middle of the image.
    Framebuffer framebuffer(camera.width, camera.height);
    framebuffer.bind();
    RenderStats r = session.draw(camera, RenderSettings{});
    EXPECT_EQ(r.triangles, s.triangles);
    EXPECT_EQ(r.draws, session.items().size());
    EXPECT_EQ(r.missing, 0u);
    std::vector<uint8_t> pixels = framebuffer.read_pixels();
    auto pixel_is_box = [&](int x, int y) {
        const uint8_t* p = &pixels[(size_t(y) * size_t(camera.width) + size_t(x)) * 4];
        return p[0] == test::kBoxColor[0] && p[1] == test::kBoxColor[1] && p[2] == test::kBoxColor[2];
    };
    EXPECT_TRUE(pixel_is_box(160, 120));
    EXPECT_FALSE(pixel_is_box(2, 2));
    size_t covered = 0;
    for (int y = 0; y < camera.height; ++y)
        for (int x = 0; x < camera.width; ++x) covered += pixel_is_box(x, y);
    // The square spans 2/3 of the image's height: 160 x 160 pixels.
    EXPECT_NEAR(double(covered), 160.0 * 160.0, 160.0 * 4);

    // The viewer's picking, through the format's drawn geometry.
    DrawnGeometry geometry = session.drawn_geometry({camera.eye.x, camera.eye.y, camera.eye.z});
    EXPECT_EQ(geometry.mesh.triangle_count(), s.triangles);
    std::optional<glm::dvec3> hit = pick_cut(session, camera, pixel_ray(camera, 160, 120));
    ASSERT_TRUE(hit.has_value());
    EXPECT_NEAR(hit->x, 50, 0.5);
    EXPECT_NEAR(hit->y, 50, 0.5);
    EXPECT_NEAR(hit->z, 0, 1e-9);
    EXPECT_FALSE(pick_cut(session, camera, pixel_ray(camera, 2, 2)).has_value());

    // A loose tolerance: the cut coarsens back to the root.
    session.set_tolerance(100);
    s = settle(session, camera);
    EXPECT_EQ(s.drawn_nodes, 1u);
    EXPECT_EQ(s.triangles, 32u);
    ASSERT_EQ(session.items().size(), 1u);
    EXPECT_EQ(session.items()[0].key, session.hierarchy().node(session.hierarchy().roots()[0]).key);
}

// `catpaq serve` without any format's describer serves the box archive's prefix and nodes; the
// session streams it over HTTP as it streams CATP.
TEST(FormatSeam, AServerThatKnowsNoFormatServesItToTheSession) {
    std::string why;
    if (!HeadlessGlContext::available(&why)) GTEST_SKIP() << why;
    box_dataset();
    StreamingServer server(served_root_settings());
    uint16_t port = server.start();

    HeadlessGlContext context;
    SessionSettings settings;
    settings.formats = &box_registry();
    const std::string url = "http://127.0.0.1:" + std::to_string(port) + "/api/datasets/boxes";
    for (const std::string& location : {url, "http://127.0.0.1:" + std::to_string(port) + "/files/boxes.cpq"}) {
        SCOPED_TRACE(location);
        StreamingSession session(location, settings);
        SessionFrameStats s = settle(session, top_camera());
        expect_all_leaves_drawn(session, s);
        EXPECT_GT(s.requests, 0u);
    }
    server.stop();
    server.wait();
}

// The first request brings the first frame. From a server, the /prefix route answers with the
// prefix and level 0's nodes (archive_first_request_size); from a local file or a static file
// server, the first 64 KiB. Nodes inside those bytes are decoded from them: a view that needs
// only them makes no further request, and none is fetched twice. (Before, the bytes past the
// prefix were dropped and level 0 was fetched again: 28 KB more for the bunny.)
TEST(FormatSeam, TheFirstRequestBringsTheFirstFrameAndItsNodesAreNotFetchedAgain) {
    std::string why;
    if (!HeadlessGlContext::available(&why)) GTEST_SKIP() << why;
    const std::string path = box_dataset();
    ArchiveReader reader(path);
    const uint64_t first_request = archive_first_request_size(reader.header(), reader.entries());
    ASSERT_GT(first_request, reader.prefix_size());  // the root fits
    // Level 1's nodes lie within the first 64 KiB of the file, past what the server sends.
    uint64_t level1_end = 0;
    for (const ArchiveEntry& e : reader.entries())
        if (e.level == 1) level1_end = std::max(level1_end, e.offset + e.size);
    ASSERT_LE(level1_end, kFirstRequestBytes);
    ASSERT_GT(reader.size(), kFirstRequestBytes);

    StreamingServer server(served_root_settings());
    const std::string base = "http://127.0.0.1:" + std::to_string(server.start());

    HeadlessGlContext context;
    SessionSettings settings;
    settings.formats = &box_registry();
    settings.skip_factor = 0;  // every level on the way is fetched and drawn
    struct Location {
        std::string name;
        uint64_t first_bytes;  // what the first request brings
        bool serves_level1;    // whether those bytes hold level 1
    };
    for (const Location& at : {Location{path, kFirstRequestBytes, true},
                               Location{base + "/files/boxes.cpq", kFirstRequestBytes, true},
                               Location{base + "/api/datasets/boxes", first_request, false}}) {
        SCOPED_TRACE(at.name);
        settings.tolerance_px = 100;  // the root alone
        StreamingSession session(at.name, settings);
        SessionFrameStats s = settle(session, top_camera());
        EXPECT_TRUE(session.failures().empty());
        EXPECT_EQ(s.drawn_nodes, 1u);
        EXPECT_EQ(s.requests, 0u);
        EXPECT_EQ(s.bytes_fetched, at.first_bytes);
        // Level 1 projects to about 9.6 px: drawn at 12 px, the root refined.
        session.set_tolerance(12);
        s = settle(session, top_camera());
        EXPECT_EQ(s.drawn_nodes, 4u);
        EXPECT_EQ(s.requests == 0, at.serves_level1);
        if (at.serves_level1) {
            EXPECT_EQ(s.bytes_fetched, at.first_bytes);
        }
        // The leaves: every other node is fetched once (the root and level 1 not again).
        session.set_tolerance(1.5);
        s = settle(session, top_camera());
        expect_all_leaves_drawn(session, s);
        uint64_t rest = 0;  // the nodes the first request did not hold whole
        for (const ArchiveEntry& e : reader.entries())
            if (e.offset + e.size > at.first_bytes) rest += e.size;
        EXPECT_EQ(s.bytes_fetched, at.first_bytes + rest);
    }
    server.stop();
    server.wait();
}

// Bytes of the first request that do not check out are no dead end: the node is fetched again.
// (A supplied node nobody lists is dropped by the fetcher, so the session keeps it listed while
// it is decoded.) A level-1 node is corrupt in the file while the session reads its first 64 KiB,
// and mended before the view needs it.
TEST(FormatSeam, ANodeWhoseFirstRequestBytesAreBadIsFetchedAgain) {
    std::string why;
    if (!HeadlessGlContext::available(&why)) GTEST_SKIP() << why;
    const std::string path = (root_dir() / "boxes_mended.cpq").string();
    fs::copy_file(box_dataset(), path, fs::copy_options::overwrite_existing);
    ArchiveEntry level1;
    {
        ArchiveReader reader(path);
        for (const ArchiveEntry& e : reader.entries())
            if (e.level == 1) level1 = e;
    }
    ASSERT_GT(level1.size, 0u);
    ASSERT_LE(level1.offset + level1.size, kFirstRequestBytes);
    auto flip = [&] {
        std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
        const std::streamoff at = std::streamoff(level1.offset + level1.size / 2);
        char c = 0;
        f.seekg(at);
        f.read(&c, 1);
        c = char(c ^ 0x10);
        f.seekp(at);
        f.write(&c, 1);
        ASSERT_TRUE(f.good());
    };

    HeadlessGlContext context;
    SessionSettings settings;
    settings.formats = &box_registry();
    settings.skip_factor = 0;
    settings.tolerance_px = 100;
    flip();
    StreamingSession session(path, settings);
    SessionFrameStats s = settle(session, top_camera());
    EXPECT_EQ(s.drawn_nodes, 1u);
    flip();  // mended
    session.set_tolerance(12);
    s = settle(session, top_camera());
    EXPECT_TRUE(session.failures().empty());
    EXPECT_EQ(s.drawn_nodes, 4u);
    EXPECT_EQ(s.requests, 1u);  // the bad node, fetched again
    EXPECT_EQ(s.bytes_fetched, kFirstRequestBytes + level1.size);
}
