// Rendered images of CATP cuts: crack-freeness in pixels, and basic sanity.
//
// Crack test: a closed model drawn in one flat colour with back faces culled, so a crack in the
// front surface shows the background (not the inside of the far side). The finest cut defines
// the silhouette; a pixel is inside it if it and its 8 neighbours are covered. A mixed cut
// (levels mixing across shared faces) may move the silhouette by its simplification error, but
// no background pixel may appear inside the full render's silhouette eroded by 2 more pixels.
// A negative control removes one front fragment and checks the detector sees the hole.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>

#include "base/error.h"
#include "catp/builder.h"
#include "mesh/generators.h"

#include "catp/cut.h"
#include "catp/dataset.h"
#include "catp_client/catp_gpu.h"
#include "catp_client/static_render.h"
#include "client/gl_program.h"
#include "gl_support.h"

using namespace catpaq;

namespace {

constexpr int kSize = 256;
constexpr int kCrackLeafLevel = 9;
const uint8_t kBackground[3] = {0, 0, 0};

RenderSettings flat_settings() {
    RenderSettings s;
    s.background = {0, 0, 0, 1};
    s.flat = true;
    s.flat_color = {1.0f, 0.5f, 0.25f};
    s.cull_back_faces = true;
    return s;
}

// World bounding box of a diamond (its spine and ring vertices).
void diamond_world_bounds(const CatpMeta& meta, DiamondId id, glm::dvec3& bmin, glm::dvec3& bmax) {
    DiamondInfo info = diamond_info(id);
    bmin = glm::dvec3(1e300);
    bmax = glm::dvec3(-1e300);
    auto add = [&](const LatticePoint& p) {
        for (int i = 0; i < 3; ++i) {
            double w = meta.origin[i] + double(std::clamp(p[i], 0, kLatticeSize)) * meta.cell;
            bmin[i] = std::min(bmin[i], w);
            bmax[i] = std::max(bmax[i], w);
        }
    };
    add(info.spine_a);
    add(info.spine_b);
    for (const LatticePoint& r : info.ring) add(r);
}

// Spatial mixed cut: every diamond coarser than `base_level`, plus those within `radius`
// (lattice units) of `focus`.
RefinedSet spatial_cut(const CatpIndex& index, const LatticePoint& focus, double radius, int base_level) {
    RefinedSet r;
    for (const ArchiveEntry& e : index.entries()) {
        if (e.flags & kCatpLeafFlag) continue;
        LatticePoint c = DiamondId{e.key}.centre();
        double d2 = 0;
        for (int i = 0; i < 3; ++i) d2 += double(c[i] - focus[i]) * double(c[i] - focus[i]);
        if (int(e.level) < base_level || d2 < radius * radius) r.refine(DiamondId{e.key});
    }
    return r;
}

// View-dependent cut, as the cut engine makes it: refine while the projected error exceeds
// `tolerance` pixels.
RefinedSet error_cut(const CatpIndex& index, const Camera& camera, double tolerance) {
    RefinedSet r;
    for (const ArchiveEntry& e : index.entries()) {
        if (e.flags & kCatpLeafFlag) continue;
        glm::dvec3 bmin, bmax;
        diamond_world_bounds(index.meta(), DiamondId{e.key}, bmin, bmax);
        if (projected_error(camera, e.error, bmin, bmax) > tolerance) r.refine(DiamondId{e.key});
    }
    return r;
}

struct CrackCheck {
    size_t inside = 0;      // pixels strictly inside the eroded full silhouette
    size_t holes = 0;       // of those, background in the cut's render
    size_t covered = 0;     // covered pixels in the cut's render
};

CrackCheck check(const std::vector<uint8_t>& full, const std::vector<uint8_t>& cut) {
    std::vector<uint8_t> full_mask = test::coverage(full, kSize, kSize, kBackground);
    std::vector<uint8_t> inside = test::erode(test::erode(full_mask, kSize, kSize, 1), kSize, kSize, 2);
    std::vector<uint8_t> cut_mask = test::coverage(cut, kSize, kSize, kBackground);
    CrackCheck c;
    for (size_t i = 0; i < inside.size(); ++i) {
        c.covered += cut_mask[i];
        if (!inside[i]) continue;
        ++c.inside;
        c.holes += !cut_mask[i];
    }
    return c;
}

size_t level_count(const CatpIndex& index, const std::vector<DrawItem>& items) {
    std::map<int, size_t> levels;
    for (const DrawItem& it : items) levels[index.find(DiamondId{it.diamond_key})->level]++;
    return levels.size();
}

void expect_mixed_cuts_have_no_holes(test::Model model, const char* name, LayoutChoice layout = LayoutChoice::Auto) {
    CatpFile file(test::dataset_path(model, 40000, kCrackLeafLevel, layout));
    const CatpIndex& index = file.index();
    StaticRenderer renderer(file);
    RenderSettings settings = flat_settings();
    RefinedSet finest = finest_cut(index);
    std::vector<Camera> cameras = test::test_cameras(index, kSize, kSize);

    // Foci for spatial cuts: points on the surface (centres of leaf diamonds with geometry).
    std::vector<LatticePoint> foci;
    for (const ArchiveEntry& e : index.entries())
        if ((e.flags & kCatpLeafFlag) && (e.flags & 0xff)) foci.push_back(DiamondId{e.key}.centre());
    ASSERT_GT(foci.size(), 10u);

    size_t cuts_checked = 0, multi_level = 0;
    for (size_t ci = 0; ci < cameras.size(); ++ci) {
        const Camera& camera = cameras[ci];
        std::vector<uint8_t> full = renderer.render(finest, camera, settings);
        test::maybe_save(std::string(name) + "_full_" + std::to_string(ci), full, kSize, kSize);
        CrackCheck self = check(full, full);
        EXPECT_GT(self.inside, 1000u) << "camera " << ci << ": the model should fill part of the view";
        EXPECT_EQ(self.holes, 0u);

        std::vector<std::pair<std::string, RefinedSet>> cuts;
        // Spatial cuts around points on the surface: finer near the focus, the rest at a base
        // level 3 to 5 levels above the leaves.
        for (int k = 0; k < 3; ++k) {
            const LatticePoint& focus = foci[(ci * 7 + size_t(k) * 13) * 7919 % foci.size()];
            int base = int(index.meta().leaf_level) - 5 + k;
            cuts.emplace_back("spatial" + std::to_string(k), spatial_cut(index, focus, kLatticeSize * (0.15 + 0.05 * k), base));
        }
        cuts.emplace_back("error1px", error_cut(index, camera, 1.0));
        cuts.emplace_back("error3px", error_cut(index, camera, 3.0));
        for (auto& [cut_name, cut] : cuts) {
            RenderStats stats;
            std::vector<uint8_t> image = renderer.render(cut, camera, settings, &stats);
            std::vector<DrawItem> items = renderer.draw_items(cut);
            size_t levels = level_count(index, items);
            multi_level += levels > 1;
            ++cuts_checked;
            CrackCheck c = check(full, image);
            std::printf("%s camera %zu cut %-8s: %5zu fragments, %zu levels, %6zu triangles, %zu pixels inside, %zu holes\n",
                        name, ci, cut_name.c_str(), items.size(), levels, stats.triangles, c.inside, c.holes);
            test::maybe_save(std::string(name) + "_" + cut_name + "_" + std::to_string(ci), image, kSize, kSize);
            EXPECT_EQ(c.holes, 0u) << name << " camera " << ci << " cut " << cut_name;
        }
    }
    EXPECT_GE(cuts_checked, 20u);
    EXPECT_GE(multi_level, cuts_checked * 3 / 4);  // the cuts really mix levels
}

}  // namespace

TEST(RenderCracks, MixedCutsOfAClosedSphereHaveNoHoles) {
    GL_TEST_CONTEXT();
    expect_mixed_cuts_have_no_holes(test::Model::Sphere, "sphere");
}

TEST(RenderCracks, MixedCutsOfAClosedTorusHaveNoHoles) {
    GL_TEST_CONTEXT();
    expect_mixed_cuts_have_no_holes(test::Model::Torus, "torus");
}

// The same in every vertex layout (the sphere has colours: Auto chose one of the coloured ones).
TEST(RenderCracks, MixedCutsHaveNoHolesInEveryVertexLayout) {
    GL_TEST_CONTEXT();
    expect_mixed_cuts_have_no_holes(test::Model::Sphere, "sphere_rgb24", LayoutChoice::Rgb24);
    expect_mixed_cuts_have_no_holes(test::Model::Sphere, "sphere_rgb18", LayoutChoice::Rgb18);
    expect_mixed_cuts_have_no_holes(test::Model::Torus, "torus_position48", LayoutChoice::Position48);
}

// The detector works: drop the front fragment nearest the image centre from the finest cut and
// the hole is found.
TEST(RenderCracks, DetectorFindsAMissingFragment) {
    GL_TEST_CONTEXT();
    CatpFile file(test::dataset_path(test::Model::Sphere, 40000, 6));
    const CatpIndex& index = file.index();
    StaticRenderer renderer(file);
    RenderSettings settings = flat_settings();
    Camera camera = test::test_cameras(index, kSize, kSize)[0];
    std::vector<DrawItem> items = renderer.draw_items(finest_cut(index));
    std::vector<uint8_t> full = renderer.render_items(items, camera, settings);

    // The fragment whose tetrahedron centroid projects nearest the image centre, among the
    // nearest to the eye.
    const CatpMeta& meta = index.meta();
    size_t best = items.size();
    double best_score = 1e300;
    for (size_t i = 0; i < items.size(); ++i) {
        Tetrahedron t = diamond_tetrahedron(diamond_info(DiamondId{items[i].diamond_key}), items[i].slot);
        glm::dvec3 c(0.0);
        for (const LatticePoint& p : t)
            for (int k = 0; k < 3; ++k) c[k] += (meta.origin[k] + p[k] * meta.cell) / 4;
        glm::dvec2 px;
        double depth;
        if (!project_to_pixels(camera, c, px, &depth)) continue;
        const GpuFragment* g = renderer.store().find(items[i].diamond_key, items[i].slot);
        if (!g || g->index_count < 30) continue;
        double score = glm::length(px - glm::dvec2(kSize / 2, kSize / 2)) + depth * 1e3;
        if (score < best_score) {
            best_score = score;
            best = i;
        }
    }
    ASSERT_LT(best, items.size());
    std::vector<DrawItem> holed = items;
    holed.erase(holed.begin() + long(best));
    std::vector<uint8_t> image = renderer.render_items(holed, camera, settings);
    test::maybe_save("sphere_holed", image, kSize, kSize);
    CrackCheck c = check(full, image);
    std::printf("missing fragment: %zu hole pixels\n", c.holes);
    EXPECT_GT(c.holes, 0u);
}

TEST(RenderSanity, ImagesShowTheModelAndDependOnTheCamera) {
    GL_TEST_CONTEXT();
    CatpFile file(test::dataset_path(test::Model::Torus, 40000, 6));
    StaticRenderer renderer(file);
    RenderSettings settings;  // lit, white background
    settings.background = {1, 1, 1, 1};
    settings.light_direction = {0.3f, -0.5f, 0.8f};
    std::vector<Camera> cameras = test::test_cameras(file.index(), kSize, kSize);
    RefinedSet finest = finest_cut(file.index());
    RenderStats stats;
    std::vector<uint8_t> a = renderer.render(finest, cameras[0], settings, &stats);
    std::vector<uint8_t> b = renderer.render(finest, cameras[1], settings);
    test::maybe_save("torus_lit_0", a, kSize, kSize);
    test::maybe_save("torus_lit_1", b, kSize, kSize);
    EXPECT_GT(stats.triangles, 10000u);
    EXPECT_EQ(stats.missing, 0u);
    const uint8_t white[3] = {255, 255, 255};
    std::vector<uint8_t> ca = test::coverage(a, kSize, kSize, white), cb = test::coverage(b, kSize, kSize, white);
    size_t covered_a = size_t(std::count(ca.begin(), ca.end(), 1)), covered_b = size_t(std::count(cb.begin(), cb.end(), 1));
    EXPECT_GT(covered_a, size_t(kSize * kSize / 20));
    EXPECT_LT(covered_a, size_t(kSize * kSize));
    EXPECT_GT(covered_b, size_t(kSize * kSize / 20));
    size_t differing = 0;
    for (size_t i = 0; i < ca.size(); ++i) differing += a[i * 4] != b[i * 4] || a[i * 4 + 1] != b[i * 4 + 1];
    EXPECT_GT(differing, size_t(kSize * kSize / 50));
    // Lighting: the model is not one flat colour.
    std::map<uint32_t, size_t> colours;
    for (size_t i = 0; i < ca.size(); ++i)
        if (ca[i]) colours[uint32_t(a[i * 4]) | uint32_t(a[i * 4 + 1]) << 8 | uint32_t(a[i * 4 + 2]) << 16]++;
    EXPECT_GT(colours.size(), 50u);
    // Rendering the same thing twice gives the same bits.
    EXPECT_EQ(renderer.render(finest, cameras[0], settings), a);
}

// The packed path and the float path draw the same picture (same triangles, positions equal up
// to float rounding of different frames).
TEST(RenderSanity, FloatPathMatchesPackedPath) {
    GL_TEST_CONTEXT();
    CatpFile file(test::dataset_path(test::Model::Sphere, 20000, 5));
    StaticRenderer renderer(file);
    RenderSettings settings = flat_settings();
    Camera camera = test::test_cameras(file.index(), kSize, kSize)[1];
    std::vector<DrawItem> items = renderer.draw_items(finest_cut(file.index()));
    std::vector<uint8_t> packed = renderer.render_items(items, camera, settings);
    std::map<uint64_t, DiamondFragments> nodes;
    for (const DrawItem& it : items) {
        auto n = nodes.find(it.diamond_key);
        if (n == nodes.end()) n = nodes.emplace(it.diamond_key, file.decode(*file.index().find(DiamondId{it.diamond_key}))).first;
        renderer.store().upload_float(it.diamond_key, it.slot, n->second.slots[size_t(it.slot)], file.index().meta());
    }
    std::vector<uint8_t> floats = renderer.render_items(items, camera, settings);
    size_t differing = 0;
    for (size_t i = 0; i < packed.size(); i += 4) differing += packed[i] != floats[i];
    std::printf("packed vs float: %zu of %d pixels differ\n", differing, kSize * kSize);
    EXPECT_LT(differing, size_t(kSize * kSize / 200));
}

// The same model at the origin and at 1e6: the anchor-relative matrices (double on the CPU)
// and the anchor-relative integer decode keep the image the same, although float cannot even
// represent the model's vertices at 1e6 to better than 1/16.
TEST(RenderPrecision, ModelFarFromTheOriginRendersLikeAtTheOrigin) {
    GL_TEST_CONTEXT();
    auto build = [](HardCase c, const std::string& name) {
        std::string path = test::scratch_dir() + "/" + name + ".cpq";
        CatpBuildSettings settings;
        settings.leaf_level = 7;
        settings.progress = false;
        build_catp(make_hard_case(c, 1), path, settings);
        return path;
    };
    CatpFile near_file(build(HardCase::OnBisectionPlanes, "near_origin"));
    CatpFile far_file(build(HardCase::FarFromOrigin, "far_from_origin"));
    const glm::dvec3 shift(1e6, 2e6, -1e6);  // make_hard_case: FarFromOrigin = OnBisectionPlanes + shift
    for (int i = 0; i < 3; ++i) ASSERT_EQ(far_file.index().meta().origin[i], near_file.index().meta().origin[i] + shift[i]);

    RenderSettings settings;
    settings.background = {1, 1, 1, 1};
    settings.light_direction = {0.2f, -0.4f, 0.9f};
    Camera camera;
    camera.width = camera.height = 192;
    camera.fov_y_degrees = 30;
    camera.target = {0.5, 0.5, 0.5};
    camera.eye = {0.5 + 0.9, 0.5 - 1.6, 0.5 + 1.1};  // close: the model fills the view
    Camera far_camera = camera;
    far_camera.eye += shift;
    far_camera.target += shift;

    std::vector<uint8_t> a, b;
    {
        StaticRenderer r(near_file);
        a = r.render(finest_cut(near_file.index()), camera, settings);
    }
    {
        StaticRenderer r(far_file);
        b = r.render(finest_cut(far_file.index()), far_camera, settings);
    }
    test::maybe_save("near_origin", a, 192, 192);
    test::maybe_save("far_from_origin", b, 192, 192);
    size_t differing = 0, covered = 0;
    for (size_t i = 0; i < a.size(); i += 4) {
        differing += std::abs(int(a[i]) - int(b[i])) > 2 || std::abs(int(a[i + 1]) - int(b[i + 1])) > 2;
        covered += a[i] != 255 || a[i + 1] != 255 || a[i + 2] != 255;
    }
    std::printf("origin vs 1e6: %zu of %zu pixels differ (%zu covered)\n", differing, a.size() / 4, covered);
    EXPECT_GT(covered, a.size() / 4 / 3);
    EXPECT_LE(differing, a.size() / 4 / 1000);
}

// OpenGL ES 3.0 renders the same picture as desktop 3.3 core.
TEST(RenderSanity, GlesContextRendersTheSameImage) {
    GL_TEST_CONTEXT();
    CatpFile file(test::dataset_path(test::Model::Torus, 40000, kCrackLeafLevel));
    RenderSettings settings;
    settings.light_direction = {0.3f, -0.5f, 0.8f};
    Camera camera = test::test_cameras(file.index(), kSize, kSize)[2];
    RefinedSet finest = finest_cut(file.index());
    std::vector<uint8_t> desktop;
    {
        StaticRenderer r(file);
        desktop = r.render(finest, camera, settings);
    }
    GlContextOptions options;
    options.api = GlApi::Gles;
    std::unique_ptr<HeadlessGlContext> es;
    try {
        es = std::make_unique<HeadlessGlContext>(options);
    } catch (const Error& e) {
        test::gl_context(nullptr);
        GTEST_SKIP() << "no OpenGL ES context: " << e.what();
    }
    std::vector<uint8_t> gles;
    {
        StaticRenderer r(file);
        gles = r.render(finest, camera, settings);
    }
    es.reset();
    test::gl_context(nullptr);
    size_t differing = 0;
    for (size_t i = 0; i < gles.size(); i += 4)
        differing += std::abs(int(gles[i]) - int(desktop[i])) > 1 || std::abs(int(gles[i + 1]) - int(desktop[i + 1])) > 1;
    std::printf("desktop vs ES: %zu of %d pixels differ\n", differing, kSize * kSize);
    EXPECT_LE(differing, size_t(kSize * kSize / 1000));
}

// Wireframe (desktop GL) draws edges only: fewer covered pixels than filled, but some.
TEST(RenderSanity, WireframeDrawsEdges) {
    GL_TEST_CONTEXT();
    if (current_context_is_gles()) GTEST_SKIP() << "no polygon mode in OpenGL ES";
    CatpFile file(test::dataset_path(test::Model::Sphere, 20000, 5));
    StaticRenderer renderer(file);
    RenderSettings settings = flat_settings();
    settings.cull_back_faces = false;
    Camera camera = test::test_cameras(file.index(), kSize, kSize)[0];
    RefinedSet finest = finest_cut(file.index());
    std::vector<uint8_t> filled = renderer.render(finest, camera, settings);
    settings.wireframe = true;
    std::vector<uint8_t> lines = renderer.render(finest, camera, settings);
    std::vector<uint8_t> cf = test::coverage(filled, kSize, kSize, kBackground), cl = test::coverage(lines, kSize, kSize, kBackground);
    size_t nf = size_t(std::count(cf.begin(), cf.end(), 1)), nl = size_t(std::count(cl.begin(), cl.end(), 1));
    EXPECT_GT(nl, nf / 20);
    EXPECT_LT(nl, nf);
}
