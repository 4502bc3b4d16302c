// catpaq render: headless rendering of a dataset (local path or URL) along a camera path, with
// streaming exactly as an interactive client does it; PNG frames and per-frame statistics.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <thread>

#include "apps/commands.h"
#include "base/atomic_file.h"
#include "base/error.h"
#include "base/options.h"
#include "base/sysinfo.h"
#include "client/camera.h"
#include "client/gl_context.h"
#include "client/image.h"
#include "client/session.h"
#include "mesh/io.h"

namespace catpaq {

static const char* kRenderUsage =
    "usage: catpaq render DATASET [options]\n"
    "  DATASET is a local .cpq file, a server URL (http://HOST:PORT/api/datasets/NAME) or the URL\n"
    "  of a .cpq file on any static web server (fetched with Range requests).\n"
    "options:\n"
    "  --camera-path FILE     JSON camera path (see docs/ARCHITECTURE.md); default: an orbit\n"
    "  --orbit N              frames of the default orbit (default 8)\n"
    "  --up y|z               the model's up axis, for the default orbit (default z)\n"
    "  --size WxH             image size (default 640x480; overrides the path's)\n"
    "  --tolerance PX         screen-space error tolerance in pixels (default 1.5)\n"
    "  --skip F               skip levels: nodes within F times the tolerance are not fetched\n"
    "                         when their descendants are drawn instead (default 8; 0: fetch\n"
    "                         every level)\n"
    "  --max-triangles N      triangle budget per frame\n"
    "  --gpu-budget SIZE      GPU bytes of the cut (e.g. 256M)\n"
    "  --cpu-budget SIZE      CPU bytes of the cut\n"
    "  --gpu-cache SIZE       GPU buffer cache, cut plus recently used (default 512M)\n"
    "  --compressed-cache SIZE  compressed nodes kept to re-decode evicted ones (default 256M)\n"
    "  --no-converge          one streaming step per frame (progressive, like a live view)\n"
    "                         instead of waiting until nothing is pending before each frame\n"
    "  --timeout SECONDS      longest wait for one frame to converge (default 120)\n"
    "  --out DIR              write frames as DIR/frame_0000.png ...\n"
    "  --stats FILE           write one JSON line of statistics per frame (elapsed_ms: since the\n"
    "                         dataset was opened, including loading its prefix)\n"
    "  --background R,G,B     background colour, 0..255 (default 255,255,255)\n"
    "  --export-cut FILE.ply  write the last frame's cut as rendered (not welded)\n";

static void parse_size(const std::string& text, int& w, int& h) {
    if (std::sscanf(text.c_str(), "%dx%d", &w, &h) != 2 || w < 16 || h < 16 || w > 16384 || h > 16384)
        fail("--size: '%s' is not WIDTHxHEIGHT between 16 and 16384", text.c_str());
}

static std::array<float, 4> parse_color(const std::string& text) {
    int r, g, b;
    if (std::sscanf(text.c_str(), "%d,%d,%d", &r, &g, &b) != 3 || r < 0 || g < 0 || b < 0 || r > 255 || g > 255 ||
        b > 255)
        fail("--background: '%s' is not R,G,B with values 0..255", text.c_str());
    return {r / 255.0f, g / 255.0f, b / 255.0f, 1.0f};
}

// The cut exactly as rendered: every drawn fragment's vertices decoded as the shader does.
static void export_cut(const StreamingSession& session, const Camera& camera, const std::string& path) {
    const CatpMeta& meta = session.index().meta();
    Camera cam = camera;
    cam.fit_clip_planes({meta.bounds_min[0], meta.bounds_min[1], meta.bounds_min[2]},
                        {meta.bounds_max[0], meta.bounds_max[1], meta.bounds_max[2]});
    FrameTransform transform = frame_transform(cam, meta);
    Mesh mesh;
    for (const DrawItem& item : session.items()) {
        const DiamondFragments* f = session.fragments(item.diamond_key);
        if (!f) continue;
        const FragmentMesh& frag = f->slots[item.slot];
        Tetrahedron t = canonical_tetrahedron(diamond_tetrahedron(diamond_info(DiamondId{item.diamond_key}), item.slot));
        std::array<LatticePoint, 4> corners = {t[0], t[1], t[2], t[3]};
        uint32_t base = uint32_t(mesh.positions.size());
        const VertexDecodeParams params = transform.params(corners);
        for (const PackedVertex& v : frag.vertices) {
            DecodedVertex d;
            if (!decode_packed_vertex(v, params, d)) continue;
            mesh.positions.push_back({transform.anchor_world.x + d.position[0], transform.anchor_world.y + d.position[1],
                                      transform.anchor_world.z + d.position[2]});
            mesh.normals.push_back({d.normal[0], d.normal[1], d.normal[2]});
            mesh.colors.push_back({uint8_t(std::lround(d.color[0] * 255.0f)), uint8_t(std::lround(d.color[1] * 255.0f)),
                                   uint8_t(std::lround(d.color[2] * 255.0f))});
        }
        for (uint32_t i : frag.indices) mesh.indices.push_back(base + i);
    }
    write_ply(path, mesh);
}

int cmd_render(int argc, char** argv) {
    Options options(argc, argv, kRenderUsage, {"no-converge"});
    if (options.help()) {
        std::printf("%s", kRenderUsage);
        return 0;
    }
    if (options.positional().size() != 1) fail("expected one dataset (see --help)");
    const std::string location = options.positional()[0];
    std::string path_file = options.get("camera-path", "");
    int orbit = int(options.integer("orbit", 8, 1, 100000));
    std::string up = options.get("up", "z");
    if (up != "y" && up != "z") fail("--up: '%s' is not y or z", up.c_str());
    int width = 640, height = 480;
    bool size_given = options.has("size");
    if (size_given) parse_size(options.get("size", ""), width, height);
    SessionSettings settings;
    settings.tolerance_px = options.number("tolerance", 1.5, 0.05, 1000);
    settings.skip_factor = options.number("skip", 8, 0, 1e6);
    if (options.has("max-triangles"))
        settings.budgets.max_primitives = uint64_t(options.integer("max-triangles", 0, 1, int64_t(1) << 40));
    if (options.has("gpu-budget")) settings.budgets.max_gpu_bytes = options.bytes("gpu-budget", 0);
    if (options.has("cpu-budget")) settings.budgets.max_cpu_bytes = options.bytes("cpu-budget", 0);
    settings.gpu_cache_bytes = options.bytes("gpu-cache", settings.gpu_cache_bytes);
    settings.compressed_cache_bytes = options.bytes("compressed-cache", settings.compressed_cache_bytes);
    bool converge = !options.flag("no-converge");
    double timeout = options.number("timeout", 120, 0.1, 86400);
    std::string out_dir = options.get("out", "");
    std::string stats_path = options.get("stats", "");
    std::string export_path = options.get("export-cut", "");
    RenderSettings render;
    render.background = parse_color(options.get("background", "255,255,255"));
    options.finish();

    HeadlessGlContext context;
    // elapsed_ms in the statistics counts from here: a cold start includes loading the prefix.
    double start = now_seconds();
    StreamingSession session(location, settings);
    const CatpMeta& meta = session.index().meta();
    CameraPath path;
    if (!path_file.empty()) {
        path = load_camera_path(path_file);
    } else if (up == "z") {
        path = orbit_path({meta.bounds_min[0], meta.bounds_min[1], meta.bounds_min[2]},
                          {meta.bounds_max[0], meta.bounds_max[1], meta.bounds_max[2]}, orbit, width, height);
    } else {
        // A y-up model: orbit the box with y and z exchanged, then exchange them back.
        path = orbit_path({meta.bounds_min[0], meta.bounds_min[2], meta.bounds_min[1]},
                          {meta.bounds_max[0], meta.bounds_max[2], meta.bounds_max[1]}, orbit, width, height);
        for (Camera& c : path.frames) {
            std::swap(c.eye.y, c.eye.z);
            std::swap(c.target.y, c.target.z);
            c.up = {0, 1, 0};
        }
    }
    if (out_dir.size()) std::filesystem::create_directories(out_dir);
    std::string stats_text;
    std::unique_ptr<Framebuffer> framebuffer;
    for (size_t i = 0; i < path.frames.size(); ++i) {
        Camera camera = path.frames[i];
        if (size_given) {
            camera.width = width;
            camera.height = height;
        }
        if (!framebuffer || camera.width != framebuffer->width() || camera.height != framebuffer->height())
            framebuffer = std::make_unique<Framebuffer>(camera.width, camera.height);
        double frame_start = now_seconds();
        SessionFrameStats s = session.step(camera);
        int steps = 1;
        while (converge && !session.converged()) {
            if (now_seconds() - frame_start > timeout) {
                std::fprintf(stderr, "render: frame %zu did not converge within %.0f s (%zu requests pending)\n", i,
                             timeout, s.pending);
                break;
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(2));
            s = session.step(camera);
            ++steps;
        }
        framebuffer->bind();
        double draw_start = now_seconds();
        RenderStats r = session.draw(camera, render);
        std::vector<uint8_t> pixels = framebuffer->read_pixels();
        double draw_ms = (now_seconds() - draw_start) * 1000.0;
        if (out_dir.size()) {
            char name[64];
            std::snprintf(name, sizeof name, "/frame_%04zu.png", i);
            write_png(out_dir + name, camera.width, camera.height, pixels);
        }
        // While a node on screen has no data yet (a hole), nothing bounds the error: null.
        char certified[32] = "null";
        if (s.holes == 0) std::snprintf(certified, sizeof certified, "%.4f", s.certified_error_px);
        char line[1024];
        std::snprintf(line, sizeof line,
                      "{\"frame\":%zu,\"triangles\":%llu,\"fragments\":%zu,\"nodes_drawn\":%zu,\"nodes_refined\":%zu,"
                      "\"bytes_fetched\":%llu,\"requests\":%llu,\"pending\":%zu,\"gpu_bytes\":%llu,\"cpu_bytes\":%llu,"
                      "\"cut_ms\":%.3f,\"draw_ms\":%.3f,\"frame_ms\":%.3f,\"steps\":%d,\"certified_error_px\":%s,"
                      "\"tolerance_px\":%.3f,\"converged\":%s,\"elapsed_ms\":%.3f}\n",
                      i, (unsigned long long)r.triangles, r.draws, s.drawn_nodes, s.refined_nodes,
                      (unsigned long long)s.bytes_fetched, (unsigned long long)s.requests, s.pending,
                      (unsigned long long)s.gpu_bytes, (unsigned long long)s.cpu_bytes, s.cut_ms, draw_ms,
                      (now_seconds() - frame_start) * 1000.0, steps, certified, settings.tolerance_px,
                      session.converged() ? "true" : "false", (now_seconds() - start) * 1000.0);
        stats_text += line;
        if (stats_path.empty()) std::fputs(line, stdout);
        if (i + 1 == path.frames.size() && export_path.size()) export_cut(session, camera, export_path);
    }
    if (stats_path.size()) write_file_atomic(stats_path, stats_text.data(), stats_text.size());
    std::fprintf(stderr, "render: %zu frames in %.2f s\n", path.frames.size(), now_seconds() - start);
    return 0;
}

}  // namespace catpaq
