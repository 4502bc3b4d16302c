// render_bench: frame time of the packed 8-byte CATP vertex (decoded by the vertex shader)
// against the float path (the same fragments decoded on the CPU: 3 floats position, 3 floats
// normal, 4 bytes colour = 28 bytes per vertex), same cut, camera, context and run.
//
// The dataset is built from a deterministic mesh (make_scan_like by default, --sphere for
// make_sphere) with build_catp into a temporary directory; the finest cut is drawn (one draw call
// per fragment) into an offscreen framebuffer. Both paths are resident in two stores of the same
// context and frames alternate between them, so both see the same load from other processes
// (llvmpipe renders on the CPU). Each frame is timed from the first GL call to glFinish; the first
// frame of each path is a warm-up. Reports best and median frame time, triangles per second (at
// the best frame), GPU bytes per vertex (vertex buffer alone and with indices), and the
// float/packed ratios.
//
// Usage: render_bench [--triangles N] [--width W] [--height H] [--frames F] [--sphere]
//                     [--leaf-triangles N] [--png prefix]
#include <epoxy/gl.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "base/error.h"
#include "base/sysinfo.h"
#include "catp/builder.h"
#include "catp/cut.h"
#include "catp/dataset.h"
#include "catp_client/catp_gpu.h"
#include "catp_client/static_render.h"
#include "client/camera.h"
#include "client/gl_context.h"
#include "client/image.h"
#include "mesh/generators.h"

using namespace catpaq;
namespace fs = std::filesystem;

namespace {

struct Options {
    size_t triangles = 1000000;
    int width = 1024, height = 768, frames = 9;
    bool sphere = false;
    size_t leaf_triangles = 2000;
    std::string png;
};

Options parse(int argc, char** argv) {
    Options o;
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        auto value = [&]() -> std::string {
            if (i + 1 >= argc) fail("%s needs a value", a.c_str());
            return argv[++i];
        };
        if (a == "--triangles") o.triangles = std::stoull(value());
        else if (a == "--width") o.width = std::stoi(value());
        else if (a == "--height") o.height = std::stoi(value());
        else if (a == "--frames") o.frames = std::max(2, std::stoi(value()));
        else if (a == "--leaf-triangles") o.leaf_triangles = std::stoull(value());
        else if (a == "--sphere") o.sphere = true;
        else if (a == "--png") o.png = value();
        else fail("unknown option '%s' (see the comment at the top of render_bench.cpp)", a.c_str());
    }
    return o;
}

struct Timing {
    std::vector<double> ms;
    double best() const { return *std::min_element(ms.begin(), ms.end()); }
    double median() const {
        std::vector<double> sorted = ms;
        std::sort(sorted.begin(), sorted.end());
        return sorted[sorted.size() / 2];
    }
    RenderStats stats;
    std::vector<uint8_t> image;
};

// One frame from the first GL call to glFinish.
double time_frame(FragmentStore& store, CatpRenderer& renderer, Framebuffer& fb, const CatpMeta& meta,
                  const std::vector<DrawItem>& items, const Camera& camera, const RenderSettings& settings,
                  RenderStats& stats) {
    fb.bind();
    glFinish();
    auto start = std::chrono::steady_clock::now();
    store.begin_frame();
    stats = renderer.render(camera, meta, items, settings);
    glFinish();
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

double load_average() {
    double load = 0;
    if (FILE* f = std::fopen("/proc/loadavg", "r")) {
        if (std::fscanf(f, "%lf", &load) != 1) load = 0;
        std::fclose(f);
    }
    return load;
}

}  // namespace

int main(int argc, char** argv) {
    try {
        Options o = parse(argc, argv);
        fs::path dir = fs::temp_directory_path() / ("catpaq_render_bench_" + std::to_string(getpid()));
        fs::create_directories(dir);
        struct Cleanup {
            fs::path dir;
            ~Cleanup() {
                std::error_code ec;
                fs::remove_all(dir, ec);
            }
        } cleanup{dir};

        double t0 = now_seconds();
        Mesh mesh = o.sphere ? make_sphere(o.triangles, 1) : make_scan_like(o.triangles, 1);
        std::string path = (dir / "bench.cpq").string();
        CatpBuildSettings build;
        build.leaf_triangles = o.leaf_triangles;
        build.progress = false;
        CatpBuildReport report = build_catp(mesh, path, build);
        std::printf("dataset: %s, %zu input triangles, leaf level %d, %zu nodes, %.1f MB, built in %.1f s\n",
                    o.sphere ? "make_sphere" : "make_scan_like", report.input_triangles, report.leaf_level, report.nodes,
                    double(report.file_bytes) / 1e6, now_seconds() - t0);
        mesh = Mesh();

        HeadlessGlContext context;
        std::printf("GL: %s, %s (%s platform), %s\n", context.renderer().c_str(), context.version().c_str(),
                    context.platform().c_str(), cpu_model().c_str());
        CatpFile file(path);
        const CatpMeta& meta = file.index().meta();
        std::vector<DrawItem> items;
        for (const DrawnSlot& d : drawn_slots(file.index(), finest_cut(file.index()))) items.push_back({d.entry->key, d.slot});

        // Decode every node once, for both uploads.
        std::map<uint64_t, DiamondFragments> nodes;
        size_t vertices = 0, triangles = 0;
        for (const DrawItem& it : items) {
            auto n = nodes.find(it.diamond_key);
            if (n == nodes.end())
                n = nodes.emplace(it.diamond_key, file.decode(*file.index().find(DiamondId{it.diamond_key}))).first;
            vertices += n->second.slots[size_t(it.slot)].vertices.size();
            triangles += n->second.slots[size_t(it.slot)].triangle_count();
        }
        std::printf("finest cut: %zu fragments, %zu triangles, %zu vertices (%.2f vertices per triangle)\n", items.size(),
                    triangles, vertices, double(vertices) / double(triangles));

        Camera camera = orbit_path(glm::dvec3(meta.bounds_min[0], meta.bounds_min[1], meta.bounds_min[2]),
                                   glm::dvec3(meta.bounds_max[0], meta.bounds_max[1], meta.bounds_max[2]), 1, o.width,
                                   o.height, 45, 25)
                            .frames[0];
        RenderSettings settings;
        settings.background = {1, 1, 1, 1};
        settings.light_direction = {0.3f, -0.6f, 0.75f};
        Framebuffer fb(o.width, o.height);

        // Two stores in the same context: the packed 8-byte vertices and the CPU-decoded 28-byte
        // floats of the same fragments.
        FragmentStore packed_store, float_store;
        CatpRenderer packed_renderer(packed_store), float_renderer(float_store);
        double up0 = now_seconds();
        for (const DrawItem& it : items) packed_store.upload(it.diamond_key, it.slot, nodes[it.diamond_key].slots[size_t(it.slot)]);
        glFinish();
        double packed_upload = now_seconds() - up0;
        double up1 = now_seconds();
        for (const DrawItem& it : items)
            float_store.upload_float(it.diamond_key, it.slot, nodes[it.diamond_key].slots[size_t(it.slot)], meta);
        glFinish();
        double float_upload = now_seconds() - up1;
        uint64_t packed_bytes = packed_store.gpu_bytes(), float_bytes = float_store.gpu_bytes();
        uint64_t index_bytes = 0;
        for (const DrawItem& it : items) {
            const GpuFragment* g = packed_store.find(it.diamond_key, it.slot);
            index_bytes += uint64_t(g->index_count) * (g->index32 ? 4 : 2);
        }

        // Frames alternate between the paths so both see the same machine load (other processes
        // share the CPU that llvmpipe renders on); frame 0 of each warms up.
        double load_before = load_average();
        Timing packed, floats;
        for (int f = 0; f < o.frames; ++f) {
            double a = time_frame(packed_store, packed_renderer, fb, meta, items, camera, settings, packed.stats);
            if (f == o.frames - 1) packed.image = fb.read_pixels();
            double b = time_frame(float_store, float_renderer, fb, meta, items, camera, settings, floats.stats);
            if (f == o.frames - 1) floats.image = fb.read_pixels();
            if (f > 0) {
                packed.ms.push_back(a);
                floats.ms.push_back(b);
            }
        }
        double load_after = load_average();

        size_t differing = 0;
        for (size_t i = 0; i < packed.image.size(); i += 4)
            differing += std::memcmp(&packed.image[i], &floats.image[i], 3) != 0;
        if (!o.png.empty()) {
            write_png(o.png + "_packed.png", o.width, o.height, packed.image);
            write_png(o.png + "_float.png", o.width, o.height, floats.image);
        }

        auto line = [&](const char* name, const Timing& t, uint64_t bytes, double upload) {
            double vb = double(bytes - index_bytes) / double(vertices);
            std::printf("%-7s best %8.2f ms  median %8.2f ms  %7.1f Mtri/s (best)  %5.2f B/vertex (%5.2f with indices)  "
                        "%7.1f MB GPU  upload %.2f s  (%zu draws, %zu triangles)\n",
                        name, t.best(), t.median(), double(t.stats.triangles) / (t.best() / 1000.0) / 1e6, vb,
                        double(bytes) / double(vertices), double(bytes) / 1e6, upload, t.stats.draws, t.stats.triangles);
        };
        std::printf("render %dx%d, %d timed frames per path, alternating (load average %.1f before, %.1f after):\n",
                    o.width, o.height, o.frames - 1, load_before, load_after);
        line("packed", packed, packed_bytes, packed_upload);
        line("float", floats, float_bytes, float_upload);
        std::printf("ratio float/packed: median frame time %.2fx, best %.2fx, vertex buffer bytes %.2fx, GPU bytes %.2fx\n",
                    floats.median() / packed.median(), floats.best() / packed.best(),
                    double(float_bytes - index_bytes) / double(packed_bytes - index_bytes),
                    double(float_bytes) / double(packed_bytes));
        std::printf("images: %zu of %d pixels differ between the paths\n", differing, o.width * o.height);
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "render_bench: %s\n", e.what());
        return 1;
    }
}
