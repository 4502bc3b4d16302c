// AQP's GPU side: crack-free images of random mixed-level cuts (stitched edges), the texture
// store's budget, and the streaming session converging on AQP datasets (with the frame time
// against CATP on the same mesh).
//
// Image crack test, as for CATP (test_render.cpp): a closed model in one flat colour with back
// faces culled, so a crack shows the background. The finest cut defines the silhouette; no
// background pixel may appear inside it eroded by 3 pixels (a coarser cut moves the silhouette
// by its error). The negative control drops a front patch and checks the detector sees it.
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <map>
#include <random>
#include <set>

#include <epoxy/gl.h>

#include "aqp_client/aqp_gpu.h"
#include "aqp_support.h"
#include "base/error.h"
#include "client/session.h"
#include "common_codec/archive.h"
#include "gl_support.h"
#include "mesh/io.h"

using namespace catpaq;
using test::AqpModel;

namespace {

constexpr int kSize = 256;
const uint8_t kBackground[3] = {0, 0, 0};

RenderSettings flat_settings() {
    RenderSettings s;
    s.background = {0, 0, 0, 1};
    s.flat = true;
    s.flat_color = {1.0f, 0.5f, 0.25f};
    s.cull_back_faces = true;
    return s;
}

std::vector<Camera> cameras_around(const AqpFormat& f, int width, int height) {
    const Aabb b = f.world_bounds();
    const glm::dvec3 bmin(b.min[0], b.min[1], b.min[2]), bmax(b.max[0], b.max[1], b.max[2]);
    std::vector<Camera> cameras = orbit_path(bmin, bmax, 3, width, height, 40, 30, 0.8).frames;
    std::vector<Camera> below = orbit_path(bmin, bmax, 2, width, height, 40, -60, 0.8).frames;
    cameras.insert(cameras.end(), below.begin(), below.end());
    return cameras;
}

// Every level of every patch uploaded to a store, drawn by an AqpRenderer; the dataset must have
// one patch per tile (test::aqp_untiled_dataset_path), so that any per-patch levels can be drawn.
struct AqpScene {
    test::OpenedAqp opened;
    aqp::AqpDataset dataset;
    PatchTextureStore store;
    std::unique_ptr<AqpRenderer> renderer;

    explicit AqpScene(const std::string& path) : opened(test::open_aqp(path)), dataset(path) {
        renderer = std::make_unique<AqpRenderer>(store, opened.format->meta());
        for (uint32_t p = 0; p < dataset.patch_count(); ++p) {
            const std::vector<aqp::PatchGrid> grids = dataset.decode_levels(p, dataset.finest_level());
            for (const aqp::PatchGrid& g : grids) store.upload(aqp::aqp_node_key(p, g.level), {g}, dataset.meta());
        }
    }
    std::vector<uint8_t> render(const std::vector<AqpDrawItem>& items, const Camera& camera, RenderStats* stats = nullptr) {
        Framebuffer fb(camera.width, camera.height);
        fb.bind();
        RenderStats s = renderer->render(camera, items, flat_settings());
        if (stats) *stats = s;
        return fb.read_pixels();
    }
    std::vector<AqpDrawItem> uniform(int level) const {
        std::vector<AqpDrawItem> items;
        for (uint32_t p = 0; p < dataset.patch_count(); ++p) items.push_back({aqp::aqp_node_key(p, level)});
        return items;
    }
};

struct Holes {
    size_t inside = 0, holes = 0;
};
Holes holes(const std::vector<uint8_t>& full, const std::vector<uint8_t>& cut) {
    const std::vector<uint8_t> inside = test::erode(test::coverage(full, kSize, kSize, kBackground), kSize, kSize, 3);
    const std::vector<uint8_t> covered = test::coverage(cut, kSize, kSize, kBackground);
    Holes h;
    for (size_t i = 0; i < inside.size(); ++i) {
        if (!inside[i]) continue;
        ++h.inside;
        h.holes += !covered[i];
    }
    return h;
}

void expect_mixed_cuts_have_no_holes(AqpModel m) {
    AqpScene scene(test::aqp_untiled_dataset_path(m));
    const int k = scene.dataset.finest_level();
    std::mt19937_64 rng(uint64_t(m) + 11);
    size_t checked = 0;
    const std::vector<Camera> cameras = cameras_around(*scene.opened.format, kSize, kSize);
    for (size_t ci = 0; ci < cameras.size(); ++ci) {
        const std::vector<uint8_t> full = scene.render(scene.uniform(k), cameras[ci]);
        const Holes self = holes(full, full);
        EXPECT_GT(self.inside, 3000u) << "the model should fill part of the view";
        for (int trial = 0; trial < 4; ++trial) {
            std::vector<AqpDrawItem> items;
            for (uint32_t p = 0; p < scene.dataset.patch_count(); ++p) {
                // Levels 1..k: level 0 patches are two triangles, whose silhouette can move by
                // more than the erosion.
                items.push_back({aqp::aqp_node_key(p, 1 + int(rng() % uint64_t(k)))});
            }
            RenderStats stats;
            const std::vector<uint8_t> image = scene.render(items, cameras[ci], &stats);
            const Holes h = holes(full, image);
            test::maybe_save(std::string("aqp_") + test::aqp_model_name(m) + "_" + std::to_string(ci) + "_" + std::to_string(trial),
                             image, kSize, kSize);
            EXPECT_EQ(stats.missing, 0u);
            if (trial == 0)
                std::printf("%s camera %zu: %zu pixels inside the silhouette, %zu holes, %zu triangles drawn\n",
                            test::aqp_model_name(m), ci, h.inside, h.holes, stats.triangles);
            EXPECT_EQ(h.holes, 0u) << test::aqp_model_name(m) << " camera " << ci << " trial " << trial;
            ++checked;
        }
    }
    EXPECT_GE(checked, 20u);
}

TEST(AqpRenderCracks, RandomMixedLevelsOfAClosedSphereHaveNoHoles) {
    GL_TEST_CONTEXT();
    expect_mixed_cuts_have_no_holes(AqpModel::Sphere);
}

TEST(AqpRenderCracks, RandomMixedLevelsOfAClosedTorusHaveNoHoles) {
    GL_TEST_CONTEXT();
    expect_mixed_cuts_have_no_holes(AqpModel::Torus);
}

TEST(AqpRenderCracks, DetectorFindsAMissingPatch) {
    GL_TEST_CONTEXT();
    AqpScene scene(test::aqp_untiled_dataset_path(AqpModel::Sphere));
    const int k = scene.dataset.finest_level();
    const Camera camera = cameras_around(*scene.opened.format, kSize, kSize)[0];
    const std::vector<uint8_t> full = scene.render(scene.uniform(k), camera);
    size_t detected = 0;
    for (uint32_t drop = 0; drop < scene.dataset.patch_count(); drop += 3) {
        std::vector<AqpDrawItem> items = scene.uniform(k);
        items.erase(items.begin() + drop);
        detected += holes(full, scene.render(items, camera)).holes > 0;
    }
    // About half the patches face the camera.
    EXPECT_GT(detected, scene.dataset.patch_count() / 3 / 5);
}

TEST(AqpRenderSanity, ShadedImagesShowTheModelWithItsColoursAndLight) {
    GL_TEST_CONTEXT();
    AqpScene scene(test::aqp_untiled_dataset_path(AqpModel::Bunny));
    const Camera camera = cameras_around(*scene.opened.format, kSize, kSize)[1];
    Framebuffer fb(kSize, kSize);
    fb.bind();
    RenderSettings lit;
    RenderStats stats = scene.renderer->render(camera, scene.uniform(scene.dataset.finest_level()), lit);
    const std::vector<uint8_t> image = fb.read_pixels();
    const uint8_t white[3] = {255, 255, 255};
    size_t covered = 0;
    std::set<int> shades;
    for (size_t i = 0; i < image.size() / 4; ++i) {
        if (image[4 * i] == 255 && image[4 * i + 1] == 255 && image[4 * i + 2] == 255) continue;
        ++covered;
        shades.insert(image[4 * i]);
    }
    (void)white;
    EXPECT_GT(covered, 3000u);
    EXPECT_GT(shades.size(), 20u) << "lighting varies over the surface";
    EXPECT_EQ(stats.draws, scene.dataset.patch_count());
}

TEST(AqpRenderSanity, GlesContextRendersTheSameImage) {
    GL_TEST_CONTEXT();
    const std::string& path = test::aqp_untiled_dataset_path(AqpModel::Torus);
    RenderSettings settings;
    settings.light_direction = {0.3f, -0.5f, 0.8f};
    auto render = [&] {
        AqpScene scene(path);
        const Camera camera = cameras_around(*scene.opened.format, kSize, kSize)[2];
        Framebuffer fb(kSize, kSize);
        fb.bind();
        // A mixed cut: stitching must agree too.
        std::vector<AqpDrawItem> items;
        for (uint32_t p = 0; p < scene.dataset.patch_count(); ++p) items.push_back({aqp::aqp_node_key(p, 1 + int(p % 4))});
        scene.renderer->render(camera, items, settings);
        return fb.read_pixels();
    };
    const std::vector<uint8_t> desktop = render();
    GlContextOptions options;
    options.api = GlApi::Gles;
    std::unique_ptr<HeadlessGlContext> es;
    try {
        es = std::make_unique<HeadlessGlContext>(options);
    } catch (const Error& e) {
        test::gl_context(nullptr);
        GTEST_SKIP() << "no OpenGL ES context: " << e.what();
    }
    const std::vector<uint8_t> gles = render();
    es.reset();
    test::gl_context(nullptr);
    size_t differing = 0, covered = 0;
    for (size_t i = 0; i < gles.size(); i += 4) {
        differing += std::abs(int(gles[i]) - int(desktop[i])) > 1 || std::abs(int(gles[i + 1]) - int(desktop[i + 1])) > 1;
        covered += desktop[i] != 255 || desktop[i + 1] != 255 || desktop[i + 2] != 255;
    }
    std::printf("desktop vs ES: %zu of %d pixels differ (%zu covered)\n", differing, kSize * kSize, covered);
    EXPECT_GT(covered, 3000u);
    EXPECT_LE(differing, size_t(kSize * kSize / 1000));
}

// The same dataset moved 1e7 away from the origin (only the metadata's origin and bounds change:
// the same samples) renders the same picture from the same relative camera: positions are the
// patch's integer offset from a grid anchor near the eye times the step, never large floats.
std::string moved_copy(const std::string& path, const std::array<double, 3>& shift) {
    aqp::AqpDataset source(path);
    aqp::AqpMeta meta = source.meta();
    for (int a = 0; a < 3; ++a) {
        meta.origin[a] += shift[size_t(a)];
        meta.bounds_min[a] += shift[size_t(a)];
        meta.bounds_max[a] += shift[size_t(a)];
    }
    const std::string out = test::aqp_scratch_dir() + "/moved.cpq";
    ArchiveWriter writer(out, ArchiveKind::Aqp);
    const std::vector<ArchiveEntry>& entries = source.archive().entries();
    for (size_t e = 0; e < entries.size(); ++e) {
        std::string error;
        const uint8_t* bytes = source.archive().node(e, &error);
        if (!bytes) throw Error(error);
        writer.add_node(entries[e], bytes, entries[e].size);
    }
    writer.finish(aqp::encode_aqp_meta(meta));
    return out;
}

TEST(AqpRenderPrecision, ModelFarFromTheOriginRendersLikeAtTheOrigin) {
    GL_TEST_CONTEXT();
    const std::string& near_path = test::aqp_untiled_dataset_path(AqpModel::Bunny);
    const std::array<double, 3> shift{1e7, -2e7, 3e7};
    const std::string far_path = moved_copy(near_path, shift);
    RenderSettings settings;
    settings.light_direction = {0.2f, -0.4f, 0.9f};
    auto render = [&](const std::string& path, const glm::dvec3& offset) {
        AqpScene scene(path);
        Camera camera = cameras_around(*scene.opened.format, 192, 192)[1];
        if (offset != glm::dvec3(0.0)) {  // the near scene's camera, moved along
            AqpScene near_scene(near_path);
            camera = cameras_around(*near_scene.opened.format, 192, 192)[1];
            camera.eye += offset;
            camera.target += offset;
        }
        // Close: the model fills the view.
        camera.eye = camera.target + (camera.eye - camera.target) * 0.4;
        Framebuffer fb(192, 192);
        fb.bind();
        std::vector<AqpDrawItem> items;
        for (uint32_t p = 0; p < scene.dataset.patch_count(); ++p) items.push_back({aqp::aqp_node_key(p, 1 + int(p % 4))});
        scene.renderer->render(camera, items, settings);
        return fb.read_pixels();
    };
    const std::vector<uint8_t> a = render(near_path, glm::dvec3(0.0));
    const std::vector<uint8_t> b = render(far_path, glm::dvec3(shift[0], shift[1], shift[2]));
    size_t differing = 0, covered = 0;
    for (size_t i = 0; i < a.size(); i += 4) {
        differing += std::abs(int(a[i]) - int(b[i])) > 2 || std::abs(int(a[i + 1]) - int(b[i + 1])) > 2;
        covered += a[i] != 255 || a[i + 1] != 255 || a[i + 2] != 255;
    }
    std::printf("origin vs 1e7: %zu of %zu pixels differ (%zu covered)\n", differing, a.size() / 4, covered);
    EXPECT_GT(covered, a.size() / 4 / 3);
    EXPECT_LE(differing, a.size() / 4 / 1000);
    // And the moved copy stitches as closed.
    test::OpenedAqp far = test::open_aqp(far_path);
    std::vector<std::shared_ptr<const DecodedNode>> keep;
    std::vector<DecodedPart> parts;
    for (uint32_t p = 0; p < far.format->meta().patches.size(); ++p) {
        const uint32_t node = far.format->hierarchy().find(aqp::aqp_node_key(p, 1 + int(p % 4)));
        keep.push_back(test::decode_chain(far, node));
        parts.push_back({node, keep.back().get(), 0});
    }
    const DrawnGeometry g = far.format->drawn_geometry(parts, {shift[0], shift[1], shift[2]});
    std::map<Vec3d, uint32_t> weld;
    std::map<std::pair<uint32_t, uint32_t>, int> edges;
    auto id = [&](uint32_t v) { return weld.emplace(g.mesh.positions[v], uint32_t(weld.size())).first->second; };
    for (size_t t = 0; t + 2 < g.mesh.indices.size(); t += 3)
        for (int k = 0; k < 3; ++k) {
            const uint32_t x = id(g.mesh.indices[t + size_t(k)]), y = id(g.mesh.indices[t + size_t(k + 1) % 3]);
            if (x != y) edges[{std::min(x, y), std::max(x, y)}]++;
        }
    size_t border = 0;
    for (const auto& [e, count] : edges) border += count == 1;
    EXPECT_EQ(border, 0u);
}

// A tile draws exactly as its patches drawn one by one: the same bunny converted with tiles and
// with one patch per node renders the same pixels at every level and on a cut of tiles mixing
// levels (each tile's patches at its level, stitched to its neighbours').
TEST(AqpRenderTiles, TilesRenderLikeTheirPatchesOneByOne) {
    GL_TEST_CONTEXT();
    AqpScene untiled(test::aqp_untiled_dataset_path(AqpModel::Bunny));
    const test::OpenedAqp tiled = test::open_aqp(test::aqp_dataset_path(AqpModel::Bunny));
    const aqp::AqpMeta& meta = tiled.format->meta();
    const Hierarchy& h = tiled.format->hierarchy();
    ASSERT_LT(meta.tile_count(0), meta.patches.size()) << "level 0 has tiles of several patches";
    PatchTextureStore store;
    AqpRenderer renderer(store, meta);
    const std::vector<std::shared_ptr<const DecodedNode>> decoded = test::decode_all(tiled);
    for (uint32_t i = 0; i < h.size(); ++i) store.upload(h.node(i).key, aqp_grids(*decoded[i]), meta);
    const Camera camera = cameras_around(*tiled.format, kSize, kSize)[1];
    auto render_tiles = [&](const std::vector<AqpDrawItem>& items, RenderStats& stats) {
        Framebuffer fb(kSize, kSize);
        fb.bind();
        stats = renderer.render(camera, items, flat_settings());
        return fb.read_pixels();
    };
    // The same patches: every level in turn, then a cut refining every other tile of each level.
    std::vector<std::pair<std::vector<AqpDrawItem>, std::vector<AqpDrawItem>>> cuts;
    for (int l = 0; l <= int(meta.patch_level); ++l) {
        std::vector<AqpDrawItem> tiles, patches;
        for (uint32_t t = 0; t < meta.tile_count(l); ++t) tiles.push_back({aqp::aqp_node_key(t, l)});
        for (uint32_t p = 0; p < meta.patches.size(); ++p) patches.push_back({aqp::aqp_node_key(p, l)});
        cuts.emplace_back(tiles, patches);
    }
    {
        std::vector<AqpDrawItem> tiles, patches;
        std::vector<uint32_t> open = h.roots();
        while (!open.empty()) {
            const uint32_t n = open.back();
            open.pop_back();
            const bool refine = !h.node(n).children.empty() && (h.node(n).level < 2 || aqp::aqp_key_tile(h.node(n).key) % 2 == 0);
            if (refine) {
                open.insert(open.end(), h.node(n).children.begin(), h.node(n).children.end());
                continue;
            }
            tiles.push_back({h.node(n).key});
            const int l = h.node(n).level;
            const uint32_t t = aqp::aqp_key_tile(h.node(n).key);
            for (uint32_t p = meta.first_patch(t, l); p < meta.first_patch(t, l) + meta.tile_patches(t, l); ++p)
                patches.push_back({aqp::aqp_node_key(p, l)});
        }
        cuts.emplace_back(tiles, patches);
    }
    std::set<int> cut_levels;
    for (const AqpDrawItem& item : cuts.back().first) cut_levels.insert(aqp::aqp_key_level(item.key));
    EXPECT_GT(cut_levels.size(), 1u) << "the last cut mixes levels";
    for (size_t c = 0; c < cuts.size(); ++c) {
        RenderStats tile_stats, patch_stats;
        const std::vector<uint8_t> a = render_tiles(cuts[c].first, tile_stats);
        const std::vector<uint8_t> b = untiled.render(cuts[c].second, camera, &patch_stats);
        EXPECT_EQ(tile_stats.missing, 0u);
        EXPECT_EQ(tile_stats.draws, meta.patches.size()) << "one draw per patch";
        EXPECT_EQ(tile_stats.triangles, patch_stats.triangles) << "cut " << c;
        EXPECT_TRUE(a == b) << "cut " << c << ": the tiled dataset draws other pixels";
    }
}

TEST(AqpStore, BudgetEvictsLeastRecentlyUsedNeverPinnedOrUsedThisFrame) {
    GL_TEST_CONTEXT();
    const std::string& path = test::aqp_untiled_dataset_path(AqpModel::Sphere);
    aqp::AqpDataset dataset(path);
    PatchTextureStore store;
    const int level = dataset.finest_level();
    const uint64_t each = aqp_gpu_bytes(level, dataset.meta().has_colors());
    std::vector<uint64_t> evicted;
    store.set_eviction_callback([&](uint64_t key) { evicted.push_back(key); });
    store.set_budget(each * 4);
    std::vector<aqp::PatchGrid> grids;
    for (uint32_t p = 0; p < 6; ++p) grids.push_back(dataset.decode(p, level));
    // Frame 1: six uploads (all used this frame): over budget, nothing evictable.
    store.begin_frame();
    for (const aqp::PatchGrid& g : grids) store.upload(aqp::aqp_node_key(g.patch, level), {g}, dataset.meta());
    EXPECT_EQ(store.gpu_bytes(), each * 6);
    EXPECT_TRUE(evicted.empty());
    // Frame 2: patch 0 pinned, patch 5 used: 1 and 2 go (least recently used first).
    store.begin_frame();
    store.pin(aqp::aqp_node_key(0, level));
    store.mark_used(aqp::aqp_node_key(5, level));
    EXPECT_EQ(store.evict_to_budget(), 2u);
    EXPECT_EQ(evicted, (std::vector<uint64_t>{aqp::aqp_node_key(1, level), aqp::aqp_node_key(2, level)}));
    EXPECT_LE(store.gpu_bytes(), each * 4);
    EXPECT_TRUE(store.resident(aqp::aqp_node_key(0, level)));
    // Release is not an eviction; a grid of another dataset shape is refused, store unchanged.
    EXPECT_TRUE(store.release(aqp::aqp_node_key(3, level)));
    EXPECT_EQ(evicted.size(), 2u);
    aqp::PatchGrid bad = grids[0];
    bad.position.pop_back();
    EXPECT_THROW(store.upload(aqp::aqp_node_key(0, level), {bad}, dataset.meta()), Error);
    EXPECT_THROW(store.upload(aqp::aqp_node_key(1, level), {grids[0]}, dataset.meta()), Error);
    EXPECT_THROW(store.upload(aqp::aqp_node_key(1, level), {grids[1], grids[2]}, dataset.meta()), Error);
    EXPECT_EQ(store.gpu_bytes(), each * 3);
    EXPECT_EQ(store.size(), 3u);
}

// The renderer's template grids (an index buffer per level drawn) are GPU memory: counted in its
// GPU bytes, and taken from the cache budget before the textures'.
TEST(AqpStore, TheRenderersGpuBytesCountTheTemplateGridsOfTheLevelsDrawn) {
    GL_TEST_CONTEXT();
    const test::OpenedAqp o = test::open_aqp(test::aqp_untiled_dataset_path(AqpModel::Sphere));
    const Hierarchy& h = o.format->hierarchy();
    std::unique_ptr<NodeRenderer> renderer = create_aqp_renderer(*o.format);
    const int level = int(o.format->meta().patch_level);
    const uint32_t node = h.find(aqp::aqp_node_key(0, level));
    ASSERT_NE(node, kNoNode);
    renderer->begin_frame();
    renderer->upload(h.node(node), *test::decode_chain(o, node));
    const uint64_t texture = aqp_gpu_bytes(level, o.format->meta().has_colors());
    EXPECT_EQ(renderer->gpu_bytes(), texture);  // no template before the first draw
    Camera camera = cameras_around(*o.format, 64, 48)[0];
    Framebuffer fb(camera.width, camera.height);
    fb.bind();
    renderer->draw(camera, {DrawnPart{h.node(node).key, 0}}, RenderSettings{});
    // The level's grid: 2 (n - 1)^2 triangles of 16-bit indices.
    const uint64_t grid = uint64_t(2) << (2 * level);
    EXPECT_EQ(renderer->gpu_bytes(), texture + grid * 3 * 2);
    // A cache budget of exactly that keeps the texture; one byte less leaves the texture less
    // than its size, and it goes (it is neither pinned nor used in a new frame).
    renderer->set_budget(texture + grid * 3 * 2);
    renderer->begin_frame();
    EXPECT_EQ(renderer->evict_to_budget(), 0u);
    EXPECT_TRUE(renderer->resident(h.node(node).key, 0));
    renderer->set_budget(texture + grid * 3 * 2 - 1);
    EXPECT_FALSE(renderer->resident(h.node(node).key, 0));
}

// Steps a session until it settles (or a generous frame limit).
SessionFrameStats settle(StreamingSession& session, const Camera& camera) {
    SessionFrameStats s = session.step(camera);
    for (int i = 0; i < 20000 && !session.settled(); ++i) {
        usleep(500);
        s = session.step(camera);
    }
    EXPECT_TRUE(session.settled());
    return s;
}

// Milliseconds per drawn frame of a settled session (glFinish after each).
double frame_ms(StreamingSession& session, const Camera& camera, int frames) {
    Framebuffer fb(camera.width, camera.height);
    fb.bind();
    session.draw(camera, RenderSettings{});
    glFinish();
    const auto start = std::chrono::steady_clock::now();
    for (int i = 0; i < frames; ++i) session.draw(camera, RenderSettings{});
    glFinish();
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count() / frames;
}

TEST(AqpSession, StreamingMeetsTheToleranceAndTheCloseUpMixesLevelsWithoutFailures) {
    GL_TEST_CONTEXT();
    for (AqpModel m : {AqpModel::Sphere, AqpModel::Bunny}) {
        const std::string& path = test::aqp_dataset_path(m);
        SessionSettings settings;
        settings.tolerance_px = 2.5;  // the views around the model meet it before the finest level
        StreamingSession session(path, settings);
        ASSERT_NE(dynamic_cast<const AqpFormat*>(&session.format()), nullptr);
        const AqpFormat& format = dynamic_cast<const AqpFormat&>(session.format());
        std::vector<Camera> cameras = cameras_around(format, 320, 240);
        // A close-up too: the eye near the surface, so levels differ across the view.
        Camera close = cameras[0];
        close.target = glm::dvec3(format.world_bounds().max[0], close.target.y, close.target.z);
        close.eye = close.target + (cameras[0].eye - cameras[0].target) * 0.25;
        cameras.push_back(close);
        for (size_t ci = 0; ci < cameras.size(); ++ci) {
            const SessionFrameStats s = settle(session, cameras[ci]);
            std::set<int> levels;
            for (const DrawnPart& p : session.items()) levels.insert(aqp::aqp_key_level(p.key));
            std::printf("%s camera %zu: %zu tiles drawn at %zu levels, %llu triangles, certified %.2f px, %llu bytes fetched, "
                        "%.2f MB GPU\n",
                        test::aqp_model_name(m), ci, session.items().size(), levels.size(), (unsigned long long)s.triangles,
                        s.certified_error_px, (unsigned long long)s.bytes_fetched, s.gpu_bytes / 1e6);
            // The close-up asks for more than the finest level has.
            if (ci + 1 < cameras.size()) {
                EXPECT_TRUE(s.tolerance_met) << "camera " << ci;
            } else {
                EXPECT_TRUE(s.tolerance_met || (s.limits & kLimitFinestLevel)) << "camera " << ci;
            }
            EXPECT_EQ(s.holes, 0u);
            EXPECT_TRUE(session.failures().empty());
            if (ci + 1 == cameras.size()) {
                EXPECT_GT(levels.size(), 1u) << "the close-up mixes levels";
            }
            // The drawn geometry is what the renderer draws: crack-free as a whole.
            const DrawnGeometry g = session.drawn_geometry({cameras[ci].eye.x, cameras[ci].eye.y, cameras[ci].eye.z});
            EXPECT_GT(g.mesh.triangle_count(), 0u);
        }
    }
}

// A cold start on a close view, with much of the model outside the frustum: every patch is a root,
// and the roots out of view are never fetched, yet the frame settles with a bounded error (out
// of view, a drawn node without data is no hole: it used to keep such sessions from settling).
TEST(AqpSession, ACloseViewFromAColdStartSettlesWithoutFetchingPatchesOutOfView) {
    GL_TEST_CONTEXT();
    const std::string& path = test::aqp_dataset_path(AqpModel::Bunny);
    SessionSettings settings;
    settings.tolerance_px = 2.5;
    StreamingSession whole(path, settings);
    const AqpFormat& format = dynamic_cast<const AqpFormat&>(whole.format());
    const Camera far = cameras_around(format, 320, 240)[0];
    const SessionFrameStats all = settle(whole, far);
    Camera close = far;
    close.target = glm::dvec3(format.world_bounds().max[0], far.target.y, far.target.z);
    close.eye = close.target + (far.eye - far.target) * 0.2;
    StreamingSession cold(path, settings);
    const SessionFrameStats s = settle(cold, close);
    EXPECT_TRUE(cold.settled());
    EXPECT_EQ(s.holes, 0u);
    EXPECT_GE(s.certified_error_px, 0.0);
    EXPECT_TRUE(s.tolerance_met || (s.limits & kLimitFinestLevel)) << s.certified_error_px;
    EXPECT_LT(cold.items().size(), format.meta().patches.size()) << "some patches are out of view";
    std::printf("close view from a cold start: %zu of %zu patches drawn, %llu requests (whole view %llu), %.2f px\n",
                cold.items().size(), format.meta().patches.size(), (unsigned long long)s.requests,
                (unsigned long long)all.requests, s.certified_error_px);
}

// AQP's nodes are small (one patch level each) and lie sorted by level, then patch: a cold start
// lists many nodes of one level at once (every root, then the next level of the patches in view),
// and the fetcher carries those that are neighbours in the file in shared transfers. The same
// views in turn from a cold start, with and without coalescing: far fewer requests, the same cut.
TEST(AqpSession, AColdStartNeedsFarFewerRequestsWhenAdjacentNodesShareTransfers) {
    GL_TEST_CONTEXT();
    const std::string& path = test::aqp_dataset_path(AqpModel::Bunny);
    SessionSettings settings;
    settings.tolerance_px = 2.5;
    // Enough new requests per frame for a level's patches in view to be listed, and queued, at
    // once (the default; 16 lists the nearest few, rarely neighbours in the file).
    ASSERT_GE(settings.budgets.max_new_requests, 1024u);
    SessionSettings alone = settings;
    alone.fetcher.coalesce_gap_bytes = -1;
    StreamingSession coalesced(path, settings), separate(path, alone);
    const AqpFormat& format = dynamic_cast<const AqpFormat&>(coalesced.format());
    for (const Camera& camera : {cameras_around(format, 320, 240)[0], cameras_around(format, 320, 240)[3]}) {
        const SessionFrameStats c = settle(coalesced, camera);
        const SessionFrameStats s = settle(separate, camera);
        std::printf("AQP bunny, %zu patches drawn: %llu requests and %llu bytes coalesced, %llu requests and %llu bytes one node each\n",
                    coalesced.items().size(), (unsigned long long)c.requests, (unsigned long long)c.bytes_fetched,
                    (unsigned long long)s.requests, (unsigned long long)s.bytes_fetched);
        EXPECT_TRUE(c.tolerance_met);
        EXPECT_TRUE(s.tolerance_met);
        EXPECT_EQ(c.holes, 0u);
        EXPECT_TRUE(coalesced.failures().empty());
        EXPECT_EQ(coalesced.items().size(), separate.items().size());
        EXPECT_EQ(c.triangles, s.triangles);
        EXPECT_LT(c.requests * 2, s.requests);
        // Unrequested bytes between coalesced nodes cost little.
        EXPECT_LT(double(c.bytes_fetched), 1.1 * double(s.bytes_fetched));
    }
}

TEST(AqpSession, GpuBudgetsHoldOnEveryFrame) {
    GL_TEST_CONTEXT();
    // With tiles and without: the sphere's tiles are large against these budgets, so the budgets
    // bind, and the store fills, on the untiled dataset (one patch per node).
    for (bool untiled : {false, true}) {
        const std::string& path = test::aqp_dataset_path(AqpModel::Sphere, untiled);
        SessionSettings settings;
        settings.tolerance_px = 0.5;
        // The cut may draw 40 KB of textures (the engine's budget); the store keeps at most 100 KB:
        // the cut, its frontier (the levels below, pinned) and what was used recently.
        settings.budgets.max_gpu_bytes = 40 * 1024;
        settings.gpu_cache_bytes = 100 * 1024;
        StreamingSession session(path, settings);
        const AqpFormat& format = dynamic_cast<const AqpFormat&>(session.format());
        bool binding = false;
        uint64_t most = 0;
        for (const Camera& camera : cameras_around(format, 320, 240)) {
            SessionFrameStats s = session.step(camera);
            for (int i = 0; i < 20000 && !session.settled(); ++i) {
                EXPECT_LE(s.gpu_bytes, settings.gpu_cache_bytes);
                most = std::max(most, s.gpu_bytes);
                usleep(500);
                s = session.step(camera);
            }
            EXPECT_TRUE(session.settled());
            EXPECT_LE(s.gpu_bytes, settings.gpu_cache_bytes);
            EXPECT_EQ(s.holes, 0u);
            EXPECT_TRUE(session.failures().empty());
            binding |= (s.limits & kLimitGpuBytes) != 0;
        }
        std::printf("GPU budgets (%s): cut 40 KB, store %llu bytes; the store held at most %llu\n", untiled ? "untiled" : "tiles",
                    (unsigned long long)settings.gpu_cache_bytes, (unsigned long long)most);
        EXPECT_TRUE(binding) << "the cut's GPU budget limited some view";
        if (untiled) {
            EXPECT_GT(most, settings.gpu_cache_bytes / 2) << "the store filled up to its budget";
        }
    }
}

TEST(AqpSession, FrameTimeAgainstCatpOnTheSameMesh) {
    GL_TEST_CONTEXT();
    // The same sphere (make_sphere(6000, 3)) as a CATP dataset and an AQP one, both converged to
    // 1 px on the same view, then drawn 30 times each.
    const std::string& aqp_path = test::aqp_dataset_path(AqpModel::Sphere);
    const std::string& catp_path = test::dataset_path(test::Model::Sphere, 6000, 8);
    SessionSettings settings;
    settings.tolerance_px = 1.0;
    StreamingSession aqp_session(aqp_path, settings), catp_session(catp_path, settings);
    const Camera camera = cameras_around(dynamic_cast<const AqpFormat&>(aqp_session.format()), 640, 480)[0];
    const SessionFrameStats a = settle(aqp_session, camera), c = settle(catp_session, camera);
    const double aqp_ms = frame_ms(aqp_session, camera, 30), catp_ms = frame_ms(catp_session, camera, 30);
    std::printf("frame time, 640x480 on this machine: AQP %.2f ms (%zu draws, %llu triangles, %.2f MB GPU), CATP %.2f ms "
                "(%zu fragments, %llu triangles, %.2f MB GPU): ratio %.2f; per 1000 triangles AQP %.3f ms, CATP %.3f ms\n",
                aqp_ms, aqp_session.items().size(), (unsigned long long)a.triangles, a.gpu_bytes / 1e6, catp_ms,
                catp_session.items().size(), (unsigned long long)c.triangles, c.gpu_bytes / 1e6, aqp_ms / catp_ms,
                aqp_ms / (a.triangles / 1000.0), catp_ms / (c.triangles / 1000.0));
    EXPECT_GT(aqp_ms, 0.0);
    EXPECT_GT(catp_ms, 0.0);
}

// The unchanged `catpaq render` streams an AQP dataset and exports its last cut as drawn: a
// closed surface, welded by position (the PLY's float coordinates).
TEST(AqpCommand, RenderStreamsAnAqpDatasetAndExportsAClosedCut) {
    GL_TEST_CONTEXT();  // the command needs EGL as this process does
    const std::string binary = std::string(CATPAQ_BINARY_DIR) + "/apps/catpaq";
    ASSERT_TRUE(std::filesystem::exists(binary)) << binary;
    const std::string& dataset = test::aqp_dataset_path(AqpModel::Torus);
    const std::string cut = test::aqp_scratch_dir() + "/torus_cut.ply", out = test::aqp_scratch_dir() + "/frames";
    const std::string command = binary + " render " + dataset + " --orbit 2 --size 320x240 --tolerance 1 --quiet --out " + out +
                                " --export-cut " + cut + " --stats " + test::aqp_scratch_dir() + "/stats.jsonl";
    ASSERT_EQ(std::system(command.c_str()), 0) << command;
    EXPECT_TRUE(std::filesystem::exists(out + "/frame_0001.png"));
    const Mesh mesh = read_mesh(cut);
    ASSERT_GT(mesh.triangle_count(), 100u);
    std::map<Vec3d, uint32_t> weld;
    std::map<std::pair<uint32_t, uint32_t>, int> edges;
    auto id = [&](uint32_t v) { return weld.emplace(mesh.positions[v], uint32_t(weld.size())).first->second; };
    for (size_t t = 0; t < mesh.triangle_count(); ++t)
        for (int k = 0; k < 3; ++k) {
            const uint32_t a = id(mesh.indices[3 * t + size_t(k)]), b = id(mesh.indices[3 * t + size_t(k + 1) % 3]);
            if (a != b) edges[{std::min(a, b), std::max(a, b)}]++;
        }
    size_t border = 0;
    for (const auto& [e, count] : edges) border += count == 1;
    EXPECT_EQ(border, 0u) << "of " << edges.size() << " edges";
}

}  // namespace
