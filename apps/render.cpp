// catpaq render: headless rendering of a dataset (local path or URL) along a camera path, with
// streaming exactly as an interactive client does it; PNG frames and per-frame statistics. Any
// format this build streams (client/builtin_formats.h).
#include <cerrno>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <thread>
#include <unistd.h>

#include "apps/commands.h"
#include "base/atomic_file.h"
#include "base/error.h"
#include "base/options.h"
#include "base/output_path.h"
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
    "  --camera-path FILE     JSON camera path (docs/formats/camera-path.md); default: an orbit\n"
    "  --orbit N              frames of the default orbit (default 8)\n"
    "  --up y|z               the model's up axis, for the default orbit (default: the dataset's,\n"
    "                         recorded by convert --up; z for datasets that record none)\n"
    "  --size WxH             image size (default 640x480; overrides the path's)\n"
    "  --msaa N               anti-aliasing samples per pixel (0, 2, 4, 8; default 0)\n"
    "  --tolerance PX         screen-space error tolerance in pixels (default 1.5)\n"
    "  --skip F               skip levels: nodes within F times the tolerance are not fetched\n"
    "                         when their descendants are drawn instead (default 8; 0: fetch\n"
    "                         every level)\n"
    "  --fetch-whole-nodes    fetch nodes whole, not only the parts a refinement draws (to compare)\n"
    "  --coalesce-gap BYTES   nodes (or parts) queued together whose byte ranges lie within BYTES\n"
    "                         of each other share one request (default 64; -1: one request\n"
    "                         per node, to compare)\n"
    "  --new-requests N       nodes the cut engine may newly request per frame (default 1024: a\n"
    "                         level's small nodes are seen together and coalesced)\n"
    "  --max-triangles N      triangle budget per frame\n"
    "  --gpu-budget SIZE      GPU bytes of the cut (e.g. 256M)\n"
    "  --cpu-budget SIZE      CPU bytes of the cut\n"
    "  --gpu-cache SIZE       GPU buffer cache, cut plus recently used (default 512M)\n"
    "  --compressed-cache SIZE  compressed nodes kept to re-decode evicted ones (default 256M)\n"
    "  --no-converge          one streaming step per frame (progressive, like a live view)\n"
    "                         instead of waiting until nothing is pending before each frame\n"
    "  --timeout SECONDS      longest wait for one frame to settle (default 120)\n"
    "  --out DIR              write frames as DIR/frame_0000.png ... (created if needed)\n"
    "  --stats FILE           one JSON line of statistics per frame, written as each frame ends\n"
    "                         (docs/formats/stats.md; default: standard output)\n"
    "  --background R,G,B     background colour, 0..255 (default 255,255,255)\n"
    "  --splats round|oriented  point datasets: screen-aligned discs (default) or oriented\n"
    "                         ellipses ray-cast with their depth (slower, sharper where they overlap)\n"
    "  --export-cut FILE.ply  write the last frame's cut as rendered (not welded)\n"
    "  --quiet                no line per frame on the terminal\n"
    "Output paths are checked before the first frame. A node that cannot be fetched or decoded\n"
    "(after retries) stops the run with its key and the reason. Exit status: 0 done, 1 failure,\n"
    "2 usage error.\n";

static void parse_size(const std::string& text, int& w, int& h) {
    if (std::sscanf(text.c_str(), "%dx%d", &w, &h) != 2 || w < 16 || h < 16 || w > 16384 || h > 16384)
        usage_error("--size: '%s' is not WIDTHxHEIGHT between 16 and 16384", text.c_str());
}

static SplatShape parse_splat_shape(const std::string& text) {
    if (text == "round") return SplatShape::Round;
    if (text == "oriented") return SplatShape::Oriented;
    usage_error("--splats: '%s' is not round or oriented", text.c_str());
}

static std::array<float, 4> parse_color(const std::string& text) {
    int r, g, b;
    if (std::sscanf(text.c_str(), "%d,%d,%d", &r, &g, &b) != 3 || r < 0 || g < 0 || b < 0 || r > 255 || g > 255 ||
        b > 255)
        usage_error("--background: '%s' is not R,G,B with values 0..255", text.c_str());
    return {r / 255.0f, g / 255.0f, b / 255.0f, 1.0f};
}

// The cut exactly as rendered: the drawn parts' geometry as the dataset's format draws it (CATP:
// every drawn fragment's vertices decoded as the shader does), in world coordinates.
static void export_cut(const StreamingSession& session, const Camera& camera, const std::string& path) {
    DrawnGeometry geometry = session.drawn_geometry({camera.eye.x, camera.eye.y, camera.eye.z});
    Mesh& mesh = geometry.mesh;
    for (Vec3d& p : mesh.positions)
        for (size_t k = 0; k < 3; ++k) p[k] = geometry.origin[k] + p[k];
    write_ply(path, mesh);
}

// One frame's statistics as a JSON line (docs/formats/stats.md).
static std::string stats_line(size_t frame, const SessionFrameStats& s, const RenderStats& r, double draw_ms,
                              double frame_ms, int steps, double tolerance, double elapsed_ms) {
    // While a node on screen has no data yet (a hole), nothing bounds the error: null.
    char certified[32] = "null";
    if (s.holes == 0) std::snprintf(certified, sizeof certified, "%.4f", s.certified_error_px);
    std::string limits = "[";
    for (const char* name : session_limit_names(s.limits)) limits += (limits.size() > 1 ? ",\"" : "\"") + std::string(name) + "\"";
    limits += "]";
    char line[1536];
    std::snprintf(line, sizeof line,
                  "{\"frame\":%zu,\"triangles\":%llu,\"points\":%llu,\"fragments\":%zu,\"nodes_drawn\":%zu,\"nodes_refined\":%zu,"
                  "\"bytes_fetched\":%llu,\"requests\":%llu,\"pending\":%zu,\"gpu_bytes\":%llu,\"cpu_bytes\":%llu,"
                  "\"cut_ms\":%.3f,\"draw_ms\":%.3f,\"frame_ms\":%.3f,\"steps\":%d,\"certified_error_px\":%s,"
                  "\"tolerance_px\":%.3f,\"settled\":%s,\"tolerance_met\":%s,\"limited_by\":%s,\"failed_nodes\":%zu,"
                  "\"elapsed_ms\":%.3f}\n",
                  frame, (unsigned long long)r.triangles, (unsigned long long)r.points, r.draws, s.drawn_nodes, s.refined_nodes,
                  (unsigned long long)s.bytes_fetched, (unsigned long long)s.requests, s.pending,
                  (unsigned long long)s.gpu_bytes, (unsigned long long)s.cpu_bytes, s.cut_ms, draw_ms, frame_ms, steps,
                  certified, tolerance, s.settled ? "true" : "false", s.tolerance_met ? "true" : "false",
                  limits.c_str(), s.failed_nodes, elapsed_ms);
    return line;
}

// The line a person reads on a terminal: frame, what was drawn, error against the tolerance, time.
static void print_frame_line(size_t frame, size_t frames, const SessionFrameStats& s, const RenderStats& r,
                             double tolerance, double frame_ms) {
    std::string error = s.holes ? "not bounded yet" : strprintf("%.2f px", s.certified_error_px);
    std::string verdict = s.tolerance_met ? "within the tolerance" : "above the tolerance";
    std::vector<const char*> limits = session_limit_names(s.limits);
    if (!s.tolerance_met && !limits.empty()) {
        verdict += " (";
        for (size_t i = 0; i < limits.size(); ++i) verdict += (i ? ", " : "") + std::string(limits[i]);
        verdict += ")";
    }
    const std::string drawn = r.points ? strprintf("%llu points", (unsigned long long)r.points)
                                       : strprintf("%llu triangles", (unsigned long long)r.triangles);
    std::fprintf(stderr, "render: frame %zu/%zu: %s, certified error %s, %s of %.2f px, %.0f ms\n", frame + 1, frames,
                 drawn.c_str(), error.c_str(), verdict.c_str(), tolerance, frame_ms);
}

// Names the first node that failed and why; the caller stops with exit status 1.
static void report_failure(const StreamingSession& session) {
    const NodeFailure& f = session.failures().front();
    std::fprintf(stderr, "catpaq render: error: node %llu (level %u) cannot be loaded: %s\n", (unsigned long long)f.key,
                 unsigned(f.level), f.error.c_str());
    if (session.failures().size() > 1)
        std::fprintf(stderr, "catpaq render: %zu more nodes failed\n", session.failures().size() - 1);
}

int cmd_render(int argc, char** argv) {
    Options options(argc, argv, kRenderUsage, {"no-converge", "quiet", "fetch-whole-nodes"});
    if (options.help()) {
        std::printf("%s", kRenderUsage);
        return 0;
    }
    if (options.positional().size() != 1) usage_error("expected one dataset");
    const std::string location = options.positional()[0];
    std::string path_file = options.get("camera-path", "");
    int orbit = int(options.integer("orbit", 8, 1, 100000));
    std::string up = options.get("up", "");
    if (!up.empty() && up != "y" && up != "z") usage_error("--up: '%s' is not y or z", up.c_str());
    int width = 640, height = 480;
    bool size_given = options.has("size");
    if (size_given) parse_size(options.get("size", ""), width, height);
    int msaa = int(options.integer("msaa", 0, 0, 64));
    SessionSettings settings;
    settings.tolerance_px = options.number("tolerance", 1.5, 0.05, 1000);
    settings.skip_factor = options.number("skip", 8, 0, 1e6);
    settings.fetch_parts = !options.flag("fetch-whole-nodes");
    if (options.has("new-requests")) {
        settings.budgets.max_new_requests = uint32_t(options.integer("new-requests", 1024, 1, 1 << 20));
        settings.budgets.max_outstanding_requests =
            std::max(settings.budgets.max_outstanding_requests, settings.budgets.max_new_requests);
    }
    settings.fetcher.coalesce_gap_bytes =
        options.integer("coalesce-gap", settings.fetcher.coalesce_gap_bytes, -1, int64_t(1) << 30);
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
    render.splats = parse_splat_shape(options.get("splats", "round"));
    bool quiet = options.flag("quiet");
    options.finish();

    // Every output is checked (and the frame directory made) before anything is loaded.
    if (out_dir.size()) prepare_output_directory(out_dir, "--out");
    if (stats_path.size()) check_output_file(stats_path, "--stats");
    if (export_path.size()) check_output_file(export_path, "--export-cut");
    CameraPath path;
    if (!path_file.empty()) path = load_camera_path(path_file);
    // Statistics are written as each frame ends (a run stopped half-way keeps what it measured).
    std::unique_ptr<FILE, int (*)(FILE*)> stats_file(nullptr, std::fclose);
    if (stats_path.size()) {
        stats_file.reset(std::fopen(stats_path.c_str(), "w"));
        if (!stats_file) fail("--stats '%s': %s", stats_path.c_str(), std::strerror(errno));
    }
    FILE* stats_out = stats_file ? stats_file.get() : stdout;
    // A line per frame for a person, on a terminal, unless the JSON lines already go there.
    const bool frame_lines = !quiet && isatty(fileno(stderr)) && !(stats_out == stdout && isatty(fileno(stdout)));

    HeadlessGlContext context;
    // elapsed_ms in the statistics counts from here: a cold start includes loading the prefix.
    double start = now_seconds();
    StreamingSession session(location, settings);
    const Aabb bounds = session.format().world_bounds();
    if (up.empty()) up = session.format().up_axis() == 1 ? "y" : "z";  // the dataset's
    if (path_file.empty() && up == "z") {
        path = orbit_path({bounds.min[0], bounds.min[1], bounds.min[2]}, {bounds.max[0], bounds.max[1], bounds.max[2]},
                          orbit, width, height);
    } else if (path_file.empty()) {
        // A y-up model: orbit the box with y and z exchanged, then exchange them back.
        path = orbit_path({bounds.min[0], bounds.min[2], bounds.min[1]}, {bounds.max[0], bounds.max[2], bounds.max[1]},
                          orbit, width, height);
        for (Camera& c : path.frames) {
            std::swap(c.eye.y, c.eye.z);
            std::swap(c.target.y, c.target.z);
            c.up = {0, 1, 0};
        }
    }
    std::unique_ptr<Framebuffer> framebuffer;
    for (size_t i = 0; i < path.frames.size(); ++i) {
        Camera camera = path.frames[i];
        if (size_given) {
            camera.width = width;
            camera.height = height;
        }
        if (!framebuffer || camera.width != framebuffer->width() || camera.height != framebuffer->height()) {
            framebuffer = std::make_unique<Framebuffer>(camera.width, camera.height, msaa);
            if (framebuffer->samples() < msaa)
                std::fprintf(stderr, "render: --msaa %d: this GL offers at most %d samples, using those\n", msaa,
                             framebuffer->samples());
            msaa = framebuffer->samples();
        }
        double frame_start = now_seconds();
        SessionFrameStats s = session.step(camera);
        int steps = 1;
        while (converge && !session.settled() && session.failures().empty()) {
            if (now_seconds() - frame_start > timeout) {
                std::fprintf(stderr, "render: frame %zu did not settle within %.0f s (%zu requests pending)\n", i,
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
        double frame_ms = (now_seconds() - frame_start) * 1000.0;
        std::string line = stats_line(i, s, r, draw_ms, frame_ms, steps, settings.tolerance_px,
                                      (now_seconds() - start) * 1000.0);
        if (std::fputs(line.c_str(), stats_out) < 0 || std::fflush(stats_out) != 0)
            fail("cannot write the statistics%s%s: %s", stats_path.size() ? " to " : "", stats_path.c_str(),
                 std::strerror(errno));
        if (frame_lines) print_frame_line(i, path.frames.size(), s, r, settings.tolerance_px, frame_ms);
        if (!session.failures().empty()) {
            report_failure(session);
            return 1;
        }
        if (i + 1 == path.frames.size() && export_path.size()) export_cut(session, camera, export_path);
    }
    if (stats_file && std::fclose(stats_file.release()) != 0)
        fail("cannot write the statistics to %s: %s", stats_path.c_str(), std::strerror(errno));
    std::fprintf(stderr, "render: %zu frames in %.2f s\n", path.frames.size(), now_seconds() - start);
    return 0;
}

}  // namespace catpaq
