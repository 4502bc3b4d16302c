#include "gl_support.h"

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <map>
#include <mutex>

#include "base/error.h"
#include "client/image.h"
#include "mesh/generators.h"
#include "scratch_directory.h"

namespace fs = std::filesystem;

namespace catpaq::test {

HeadlessGlContext* gl_context(std::string* why) {
    static std::unique_ptr<HeadlessGlContext> context;
    static std::string reason;
    static bool tried = false;
    if (!tried) {
        tried = true;
        try {
            context = std::make_unique<HeadlessGlContext>();
        } catch (const Error& e) {
            reason = e.what();
        }
    }
    if (why) *why = reason;
    if (context) context->make_current();
    return context.get();
}

std::string scratch_dir() {
    static ScratchDirectory dir("catpaq_client_gl_");
    // The images save_image writes under CATPAQ_TEST_IMAGES are there to be looked at: kept.
    static const bool images_kept = [] {
        if (!std::getenv("CATPAQ_TEST_IMAGES")) return false;
        dir.keep();
        return true;
    }();
    (void)images_kept;
    return dir.string();
}

const std::string& dataset_path(Model model, size_t triangles, int leaf_level, LayoutChoice layout) {
    static std::map<std::tuple<int, size_t, int, int>, std::string> built;
    auto key = std::make_tuple(int(model), triangles, leaf_level, int(layout));
    auto it = built.find(key);
    if (it != built.end()) return it->second;
    Mesh mesh = model == Model::Sphere ? make_sphere(triangles, 3) : make_torus(triangles, 5);
    std::string path = scratch_dir() + "/" + (model == Model::Sphere ? "sphere" : "torus") + "_" +
                       std::to_string(triangles) + "_" + std::to_string(leaf_level) + "_" + std::to_string(int(layout)) +
                       ".cpq";
    CatpBuildSettings settings;
    settings.leaf_level = leaf_level;
    settings.layout = layout;
    settings.leaf_triangles = 200;
    settings.progress = false;
    build_catp(mesh, path, settings);
    return built.emplace(key, path).first->second;
}

std::vector<Camera> test_cameras(const CatpIndex& index, int width, int height) {
    const CatpMeta& m = index.meta();
    glm::dvec3 bmin(m.bounds_min[0], m.bounds_min[1], m.bounds_min[2]);
    glm::dvec3 bmax(m.bounds_max[0], m.bounds_max[1], m.bounds_max[2]);
    std::vector<Camera> cameras = orbit_path(bmin, bmax, 3, width, height, 40, 30, 0.8).frames;
    std::vector<Camera> below = orbit_path(bmin, bmax, 2, width, height, 40, -60, 0.8).frames;
    cameras.insert(cameras.end(), below.begin(), below.end());
    // A close-up: looking at a point on the bounds' +x face from nearby, so the surface fills the
    // view and levels differ in projected size.
    Camera close;
    close.width = width;
    close.height = height;
    close.fov_y_degrees = 50;
    glm::dvec3 centre = (bmin + bmax) * 0.5, extent = bmax - bmin;
    close.target = glm::dvec3(centre.x + extent.x * 0.35, centre.y + extent.y * 0.1, centre.z + extent.z * 0.05);
    close.eye = close.target + glm::dvec3(extent.x * 0.6, extent.y * 0.25, extent.z * 0.3);
    cameras.push_back(close);
    return cameras;
}

std::vector<uint8_t> coverage(const std::vector<uint8_t>& rgba, int width, int height, const uint8_t background[3]) {
    std::vector<uint8_t> mask(size_t(width) * size_t(height));
    for (size_t i = 0; i < mask.size(); ++i) {
        const uint8_t* p = &rgba[i * 4];
        mask[i] = p[0] != background[0] || p[1] != background[1] || p[2] != background[2];
    }
    return mask;
}

std::vector<uint8_t> erode(const std::vector<uint8_t>& mask, int width, int height, int radius) {
    std::vector<uint8_t> out(mask.size(), 0);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            bool all = true;
            for (int dy = -radius; dy <= radius && all; ++dy)
                for (int dx = -radius; dx <= radius && all; ++dx) {
                    int xx = x + dx, yy = y + dy;
                    all = xx >= 0 && yy >= 0 && xx < width && yy < height && mask[size_t(yy) * width + xx];
                }
            out[size_t(y) * width + x] = all;
        }
    return out;
}

void maybe_save(const std::string& name, const std::vector<uint8_t>& rgba, int width, int height) {
    if (!std::getenv("CATPAQ_TEST_IMAGES")) return;
    std::string path = scratch_dir() + "/" + name + ".png";
    write_png(path, width, height, rgba);
    std::printf("saved %s\n", path.c_str());
}

}  // namespace catpaq::test
