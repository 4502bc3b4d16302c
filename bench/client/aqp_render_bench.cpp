// aqp_render_bench: AQP's client plug-in against CATP on the same mesh, in the same run and GL
// context: decode throughput of the level chain, and streaming sessions converged to the same
// tolerance on the same views (triangles, GPU bytes, bytes fetched, frame time and the CPU time
// to submit a frame).
//
// The mesh is make_scan_like (colours, area-weighted normals); both datasets are built into a
// temporary directory (AQP: finest level chosen by the converter unless --level; CATP: defaults).
// Frames are timed from the first GL call to glFinish (llvmpipe renders on the CPU, so frame times
// include rasterization); submit time is the same draw without glFinish.
//
// Usage: aqp_render_bench [--triangles N] [--level K] [--width W] [--height H] [--frames F]
//                         [--tolerance PX]
#include <epoxy/gl.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "aqp/build.h"
#include "aqp_client/aqp_format.h"
#include "base/error.h"
#include "catp/builder.h"
#include "client/camera.h"
#include "client/gl_context.h"
#include "client/session.h"
#include "mesh/generators.h"

using namespace catpaq;
namespace fs = std::filesystem;

namespace {

struct Options {
    size_t triangles = 200000;
    int level = -1;
    int width = 1024, height = 768, frames = 9;
    double tolerance = 1.0;
};

Options parse(int argc, char** argv) {
    Options o;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto value = [&]() -> std::string {
            if (i + 1 >= argc) fail("%s needs a value", a.c_str());
            return argv[++i];
        };
        if (a == "--triangles") o.triangles = std::stoull(value());
        else if (a == "--level") o.level = std::stoi(value());
        else if (a == "--width") o.width = std::stoi(value());
        else if (a == "--height") o.height = std::stoi(value());
        else if (a == "--frames") o.frames = std::max(2, std::stoi(value()));
        else if (a == "--tolerance") o.tolerance = std::stod(value());
        else fail("unknown option %s", a.c_str());
    }
    return o;
}

double seconds_since(std::chrono::steady_clock::time_point t) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

// Decodes every node of an AQP dataset through its chain, one thread.
void decode_throughput(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    const std::vector<uint8_t> file((std::istreambuf_iterator<char>(in)), {});
    AqpFormat format(DatasetPrefix::parse(file.data(), file.size(), path));
    const Hierarchy& h = format.hierarchy();
    const auto start = std::chrono::steady_clock::now();
    uint64_t bytes = 0, samples = 0;
    // Node order is coarse to fine: a node's decode parent is decoded before it.
    std::vector<std::shared_ptr<const DecodedNode>> decoded(h.size());
    for (uint32_t i = 0; i < h.size(); ++i) {
        const HierarchyNode& n = h.node(i);
        std::shared_ptr<const DecodedNode> out;
        const uint8_t* data = file.data() + n.payload_offset;
        const std::string problem = n.decode_parent == kNoNode
                                        ? format.decode(n.index, data, n.payload_bytes, out)
                                        : format.decode_with_parent(n.index, *decoded[n.decode_parent], data, n.payload_bytes, out);
        if (!problem.empty()) fail("%s", problem.c_str());
        bytes += n.payload_bytes;
        for (const aqp::PatchGrid& g : aqp_grids(*out)) samples += g.position.size();
        decoded[i] = std::move(out);
    }
    const double s = seconds_since(start);
    std::printf("AQP decode (one thread, every level of %zu patches): %.2f MB in %.3f s = %.1f MB/s compressed, %.1f M "
                "samples/s, %.2f compressed bytes per sample\n",
                format.meta().patches.size(), bytes / 1e6, s, bytes / 1e6 / s, samples / 1e6 / s, double(bytes) / double(samples));
}

struct Measured {
    SessionFrameStats stats;
    size_t items = 0;
    double frame_ms = 0, submit_ms = 0;
};

Measured measure(const std::string& path, const Camera& camera, const Options& o) {
    SessionSettings settings;
    settings.tolerance_px = o.tolerance;
    StreamingSession session(path, settings);
    Measured m;
    m.stats = session.step(camera);
    for (int i = 0; i < 200000 && !session.settled(); ++i) {
        usleep(200);
        m.stats = session.step(camera);
    }
    m.items = session.items().size();
    Framebuffer fb(camera.width, camera.height);
    fb.bind();
    std::vector<double> frame, submit;
    for (int f = 0; f < o.frames; ++f) {
        glFinish();
        auto start = std::chrono::steady_clock::now();
        session.draw(camera, RenderSettings{});
        submit.push_back(seconds_since(start) * 1e3);
        glFinish();
        frame.push_back(seconds_since(start) * 1e3);
    }
    // The first frame is a warm-up (templates, shader caches); the median of the rest.
    frame.erase(frame.begin());
    submit.erase(submit.begin());
    std::sort(frame.begin(), frame.end());
    std::sort(submit.begin(), submit.end());
    m.frame_ms = frame[frame.size() / 2];
    m.submit_ms = submit[submit.size() / 2];
    return m;
}

}  // namespace

int main(int argc, char** argv) {
    try {
        const Options o = parse(argc, argv);
        const fs::path dir = fs::temp_directory_path() / ("aqp_render_bench_" + std::to_string(getpid()));
        fs::create_directories(dir);
        struct Cleanup {
            fs::path dir;
            ~Cleanup() {
                std::error_code ignored;
                fs::remove_all(dir, ignored);
            }
        } cleanup{dir};
        const Mesh mesh = make_scan_like(o.triangles, 1);
        const std::string aqp_path = (dir / "mesh_aqp.cpq").string(), catp_path = (dir / "mesh_catp.cpq").string();
        auto start = std::chrono::steady_clock::now();
        aqp::AqpBuildOptions aqp_options;
        aqp_options.patch_level = o.level;
        aqp_options.progress = false;
        aqp::AqpBuildReport report;
        aqp::build_aqp_dataset(mesh, aqp_path, aqp_options, &report);
        std::printf("mesh: %zu triangles; AQP: %zu patches, finest level %d, %.2f MB, built in %.1f s\n", mesh.triangle_count(),
                    report.patches, report.patch_level, fs::file_size(aqp_path) / 1e6, seconds_since(start));
        start = std::chrono::steady_clock::now();
        CatpBuildSettings catp_settings;
        catp_settings.progress = false;
        build_catp(mesh, catp_path, catp_settings);
        std::printf("CATP: %.2f MB, built in %.1f s\n", fs::file_size(catp_path) / 1e6, seconds_since(start));
        decode_throughput(aqp_path);

        HeadlessGlContext context;
        const Bounds b = mesh.bounds();
        const glm::dvec3 bmin(b.min[0], b.min[1], b.min[2]), bmax(b.max[0], b.max[1], b.max[2]);
        const std::vector<Camera> cameras = orbit_path(bmin, bmax, 3, o.width, o.height, 40, 30, 0.8).frames;
        std::printf("%dx%d, tolerance %.2f px, median of %d frames\n", o.width, o.height, o.tolerance, o.frames - 1);
        std::printf("view format  drawn  triangles  GPU MB  fetched MB  certified px  frame ms  submit ms  ms/Mtri\n");
        for (size_t ci = 0; ci < cameras.size(); ++ci) {
            for (const auto& [name, path] : {std::pair{"AQP", aqp_path}, std::pair{"CATP", catp_path}}) {
                const Measured m = measure(path, cameras[ci], o);
                std::printf("%4zu %-6s %6zu %10llu %7.2f %11.2f %13.2f %9.2f %10.3f %8.1f\n", ci, name, m.items,
                            (unsigned long long)m.stats.triangles, m.stats.gpu_bytes / 1e6, m.stats.bytes_fetched / 1e6,
                            m.stats.certified_error_px, m.frame_ms, m.submit_ms, m.frame_ms / (m.stats.triangles / 1e6));
            }
        }
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "aqp_render_bench: %s\n", e.what());
        return 1;
    }
}
