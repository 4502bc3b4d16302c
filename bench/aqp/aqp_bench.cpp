// aqp_bench: the AQP converter on the bundled bunny and a generated scan-like mesh. Prints build
// time (wall and CPU) by phase, input triangles per second, bytes and bits per sample, the error
// bound per level (relative to the bounding box diagonal), the parameterization's distortion
// (angle: singular value ratio s1/s2; area: max(s1 s2, 1/(s1 s2)) with the domain scaled to the
// surface's area; area-weighted mean, 99th percentile by area, max), and as a reference measured
// in the same run, the CATP converter on the same mesh (time, bytes, finest and coarsest bounds).
//
// usage: aqp_bench [--scan TRIANGLES] [--bunny PATH] [--domain N] [--level K] [--no-catp] [--keep DIR]
// Outputs go to a temporary directory (DIR with --keep).
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>

#include "aqp/build.h"
#include "base/error.h"
#include "base/sysinfo.h"
#include "catp/builder.h"
#include "mesh/generators.h"
#include "mesh/io.h"

using namespace catpaq;
using namespace catpaq::aqp;
namespace fs = std::filesystem;

namespace {

struct Settings {
    size_t scan_triangles = 1000000;
    std::string bunny = std::string(CATPAQ_SOURCE_DIR) + "/data/bunny.ply";
    size_t domain = 0;
    int level = -1;
    bool catp = true;
    std::string dir;
};

void report_aqp(const std::string& name, const Mesh& mesh, const AqpBuildReport& r, double cpu) {
    const DomainReport& d = r.domain;
    std::printf("model %s: %zu triangles, %zu vertices\n", name.c_str(), mesh.triangle_count(), mesh.vertex_count());
    std::printf("  build %.2f s wall, %.2f s cpu (%.2f cores), %.0f input triangles/s, peak %.0f MiB\n", r.seconds, cpu,
                cpu / r.seconds, double(mesh.triangle_count()) / r.seconds, double(r.peak_rss) / (1 << 20));
    std::printf("  phases: clean %.2f, parameterize %.2f (simplify %.2f, smooth %.2f), resample %.2f, errors %.2f, encode %.2f s\n",
                r.seconds_clean, r.seconds_parameterize, d.seconds_simplify, d.seconds_smooth, r.seconds_resample,
                r.seconds_errors, r.seconds_encode);
    const int side = (1 << r.patch_level) + 1;
    std::printf("  domain: %zu base triangles, %zu patches of %dx%d samples, %zu samples (%.2f per input vertex)\n",
                d.base_triangles, r.patches, side, side, r.samples, double(r.samples) / double(mesh.vertex_count()));
    std::printf("  size: %llu bytes file, %llu payload, %.2f bits/sample, %.2f bits per input triangle\n",
                (unsigned long long)r.file_bytes, (unsigned long long)r.payload_bytes, r.bits_per_sample,
                8.0 * double(r.payload_bytes) / double(mesh.triangle_count()));
    std::printf("  quantization: step %.3g (%.3g of the mean edge), precision %.3g\n", r.step, r.step / r.mean_edge,
                r.precision);
    const ParamCheck& c = d.check;
    std::printf("  distortion: angle mean %.3f p99 %.3f max %.3g; area mean %.3f p99 %.3f max %.3g\n", c.angle_distortion_mean,
                c.angle_distortion_p99, c.angle_distortion_max, c.area_distortion_mean, c.area_distortion_p99,
                c.area_distortion_max);
    std::printf("  %5s %10s %10s %12s %16s %16s\n", "level", "samples", "bytes", "bits/sample", "max error/diag", "mean error/diag");
    for (const AqpLevelStats& l : r.levels)
        std::printf("  %5d %10zu %10llu %12.2f %16.3e %16.3e\n", l.level, l.samples, (unsigned long long)l.bytes,
                    8.0 * double(l.bytes) / double(l.samples), l.max_error / r.diagonal, l.mean_error / r.diagonal);
    for (const std::string& w : r.warnings) std::printf("  warning: %s\n", w.c_str());
    for (const std::string& s : r.clean.summary()) std::printf("  cleaned: %s\n", s.c_str());
}

void report_catp(const Mesh& mesh, const std::string& path) {
    CatpBuildSettings settings;
    settings.progress = false;
    const double cpu0 = cpu_seconds();
    CatpBuildReport r = build_catp(mesh, path, settings);
    const double cpu = cpu_seconds() - cpu0;
    std::printf("  reference, CATP on the same mesh: %.2f s wall, %.2f s cpu, %llu bytes, %d levels, bounds/diag finest "
                "%.3e coarsest %.3e\n",
                r.seconds, cpu, (unsigned long long)r.file_bytes, int(r.levels.size()), r.levels.back().max_error / r.diagonal,
                r.levels.front().max_error / r.diagonal);
}

void run(const std::string& name, const Mesh& mesh, const Settings& s) {
    AqpBuildOptions options;
    options.progress = false;
    options.domain_triangles = s.domain;
    options.patch_level = s.level;
    AqpBuildReport r;
    const double cpu0 = cpu_seconds();
    try {
        build_aqp_dataset(mesh, (fs::path(s.dir) / (name + ".cpq")).string(), options, &r);
    } catch (const Error& e) {
        std::printf("model %s: refused: %s\n", name.c_str(), e.what());
        return;
    }
    report_aqp(name, mesh, r, cpu_seconds() - cpu0);
    if (s.catp) report_catp(mesh, (fs::path(s.dir) / (name + "_catp.cpq")).string());
    std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
    Settings s;
    bool keep = false;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto value = [&]() -> std::string {
            if (i + 1 >= argc) {
                std::fprintf(stderr, "aqp_bench: %s needs a value\n", a.c_str());
                std::exit(2);
            }
            return argv[++i];
        };
        if (a == "--scan") s.scan_triangles = std::stoul(value());
        else if (a == "--bunny") s.bunny = value();
        else if (a == "--domain") s.domain = std::stoul(value());
        else if (a == "--level") s.level = std::stoi(value());
        else if (a == "--no-catp") s.catp = false;
        else if (a == "--keep") s.dir = value(), keep = true;
        else {
            std::fprintf(stderr, "usage: aqp_bench [--scan TRIANGLES] [--bunny PATH] [--domain N] [--level K] [--no-catp] [--keep DIR]\n");
            return 2;
        }
    }
    if (!keep) s.dir = (fs::temp_directory_path() / ("aqp_bench_" + std::to_string(getpid()))).string();
    fs::create_directories(s.dir);
    try {
        run("bunny", read_mesh(s.bunny), s);
        if (s.scan_triangles) run("scan" + std::to_string(s.scan_triangles), make_scan_like(s.scan_triangles, 1), s);
    } catch (const Error& e) {
        std::fprintf(stderr, "aqp_bench: %s\n", e.what());
        return 1;
    }
    if (!keep) fs::remove_all(s.dir);
    return 0;
}
