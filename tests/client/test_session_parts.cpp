// Fetching parts (HierarchyNode::fetch_parts): a streaming session that fetches only the slots a
// refinement draws converges to the same cut, draws the same image, and fetches fewer bytes
// than one that fetches whole diamonds; what it fetches is what its cut draws, or drew.
#include <gtest/gtest.h>
#include <unistd.h>

#include <set>

#include "client/session.h"
#include "gl_support.h"

using namespace catpaq;

namespace {

SessionFrameStats settle(StreamingSession& session, const Camera& camera) {
    SessionFrameStats s = session.step(camera);
    for (int i = 0; i < 20000 && !session.settled(); ++i) {
        usleep(500);
        s = session.step(camera);
    }
    EXPECT_TRUE(session.settled());
    return s;
}

struct Converged {
    SessionFrameStats stats;
    std::set<std::pair<uint64_t, uint8_t>> items;
    std::vector<uint8_t> image;
};

Converged converge(const std::string& dataset, const Camera& camera, bool fetch_parts) {
    SessionSettings settings;
    settings.fetch_parts = fetch_parts;
    StreamingSession session(dataset, settings);
    Converged out;
    out.stats = settle(session, camera);
    for (const DrawnPart& p : session.items()) out.items.insert({p.key, p.part});
    Framebuffer fb(camera.width, camera.height);
    fb.bind();
    session.draw(camera, RenderSettings{});
    out.image = fb.read_pixels();
    return out;
}

}  // namespace

TEST(SessionParts, FetchingPartsDrawsTheSameCutAndImageForFewerBytes) {
    GL_TEST_CONTEXT();
    const std::string& dataset = test::dataset_path(test::Model::Sphere, 40000, 6);
    CatpFile file(dataset);
    ASSERT_TRUE(file.index().has_slot_ranges());
    std::vector<Camera> cameras = test::test_cameras(file.index(), 240, 180);
    size_t saved = 0;
    for (size_t i = 0; i < cameras.size(); ++i) {
        Converged parts = converge(dataset, cameras[i], true);
        Converged whole = converge(dataset, cameras[i], false);
        EXPECT_TRUE(parts.stats.tolerance_met) << "camera " << i;
        EXPECT_EQ(parts.items, whole.items) << "camera " << i;
        EXPECT_EQ(parts.stats.triangles, whole.stats.triangles) << "camera " << i;
        EXPECT_TRUE(parts.image == whole.image) << "camera " << i;
        EXPECT_LE(parts.stats.bytes_fetched, whole.stats.bytes_fetched) << "camera " << i;
        saved += parts.stats.bytes_fetched < whole.stats.bytes_fetched;
        std::printf("camera %zu: %zu parts drawn, fetched %llu bytes by parts, %llu whole\n", i, parts.items.size(),
                    (unsigned long long)parts.stats.bytes_fetched, (unsigned long long)whole.stats.bytes_fetched);
    }
    // The close-up leaves coarse diamonds unrefined beside the view: their other slots stay put.
    EXPECT_GT(saved, 0u);
    EXPECT_LT(converge(dataset, cameras.back(), true).stats.bytes_fetched,
              converge(dataset, cameras.back(), false).stats.bytes_fetched * 9 / 10);
}
