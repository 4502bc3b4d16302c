// catp_build_bench: the CATP converter, end to end from a PLY file on disk (reading included), on
// the bundled bunny and generated scan-like meshes of growing size, under a memory budget.
// Prints input triangles/s, output bytes, bits per vertex, peak memory against the budget and
// the scratch bytes spilled to disk, and, as a machine-independent reference, the same run's
// throughput of meshoptimizer's simplifier halving the same mesh (one pass, single thread): the
// ratio says how much slower than "one simplification pass" the whole pipeline is.
//
// usage: catp_build_bench [--sizes 100000,1000000,10000000] [--memory 1G] [--bunny PATH] [--keep DIR]
// Each step runs in a child process so the build's peak memory is its own: the scan meshes are
// generated and written as binary PLY first (kept in DIR with --keep, and reused from there).
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>

#include <meshoptimizer.h>

#include "base/options.h"
#include "base/sysinfo.h"
#include "catp/builder.h"
#include "common_codec/archive.h"
#include "mesh/generators.h"
#include "mesh/io.h"

using namespace catpaq;
namespace fs = std::filesystem;

struct Result {
    double seconds = 0, triangles_per_second = 0, bits_per_vertex = 0, peak_mib = 0, file_bytes = 0;
    double meshopt_triangles_per_second = 0, budget_mib = 0, spilled_mib = 0;
    int leaf_level = 0, block_level = 0;
    size_t stored_vertices = 0;
    double phases[6] = {};  // read, bin, clip, leaf nodes, coarsen, write: seconds
    double cpu_seconds = 0;  // user + system time of the build
    FirstFrame first_frame;  // of the dataset built
    uint32_t nodes = 0;
};

static Result run_one(const std::string& input, const std::string& output, uint64_t budget) {
    Result r;
    CatpBuildSettings settings;
    settings.progress = false;
    // The budget bounds the whole child process, as `catpaq convert --memory` does.
    uint64_t own = current_rss_bytes();
    settings.memory_budget = budget > own ? budget - own : 0;
    double cpu0 = cpu_seconds();
    CatpBuildReport report = build_catp_file(input, output, settings);
    r.cpu_seconds = cpu_seconds() - cpu0;
    const double phases[6] = {report.seconds_read, report.seconds_bin, report.seconds_clip, report.seconds_leaf_nodes,
                              report.seconds_coarsen, report.seconds_write};
    std::copy(phases, phases + 6, r.phases);
    r.seconds = report.seconds;
    r.triangles_per_second = double(report.input_triangles) / report.seconds;
    for (const CatpLevelStats& l : report.levels) r.stored_vertices += l.vertices;
    r.bits_per_vertex = 8.0 * double(report.file_bytes) / double(std::max<size_t>(1, r.stored_vertices));
    r.peak_mib = double(report.peak_rss) / (1 << 20);
    r.file_bytes = double(report.file_bytes);
    r.leaf_level = report.leaf_level;
    r.block_level = report.block_level;
    r.budget_mib = double(report.memory_budget + own) / (1 << 20);
    {
        ArchiveReader archive(output);
        r.first_frame = archive_first_frame(archive.header(), archive.entries());
        r.nodes = archive.header().node_count;
    }
    r.spilled_mib = double(report.bytes_spilled) / (1 << 20);
    // Baseline in the same process (after the build, so it does not count in the build's peak):
    // meshopt_simplify to half, float positions.
    Mesh mesh = read_mesh(input);
    std::vector<float> positions(mesh.positions.size() * 3);
    for (size_t v = 0; v < mesh.positions.size(); ++v)
        for (int i = 0; i < 3; ++i) positions[3 * v + i] = float(mesh.positions[v][i]);
    std::vector<uint32_t> out(mesh.indices.size());
    double t0 = now_seconds();
    meshopt_simplify(out.data(), mesh.indices.data(), mesh.indices.size(), positions.data(), mesh.positions.size(),
                     12, mesh.indices.size() / 2, 1e-2f, 0, nullptr);
    r.meshopt_triangles_per_second = double(mesh.triangle_count()) / (now_seconds() - t0);
    return r;
}

// Writes the generated scan mesh as PLY, in a child so the generator's memory is not ours.
static bool make_input(const std::string& path, size_t triangles) {
    if (fs::exists(path)) return true;
    pid_t pid = fork();
    if (pid == 0) {
        try {
            write_ply(path, make_scan_like(triangles, 1), true);
        } catch (const std::exception& e) {
            std::fprintf(stderr, "error: %s\n", e.what());
            _exit(1);
        }
        _exit(0);
    }
    int status = 0;
    waitpid(pid, &status, 0);
    return WIFEXITED(status) && WEXITSTATUS(status) == 0;
}

// Runs the build in a child so peak memory is measured per build; results come back by pipe.
static bool run_in_child(const std::string& input, const std::string& output, uint64_t budget, Result& out) {
    int fds[2];
    if (pipe(fds) != 0) return false;
    pid_t pid = fork();
    if (pid == 0) {
        close(fds[0]);
        Result r;
        try {
            r = run_one(input, output, budget);
        } catch (const std::exception& e) {
            std::fprintf(stderr, "error: %s\n", e.what());
            _exit(1);
        }
        ssize_t written = write(fds[1], &r, sizeof r);
        _exit(written == ssize_t(sizeof r) ? 0 : 1);
    }
    close(fds[1]);
    ssize_t n = read(fds[0], &out, sizeof out);
    close(fds[0]);
    int status = 0;
    waitpid(pid, &status, 0);
    return n == ssize_t(sizeof out) && WIFEXITED(status) && WEXITSTATUS(status) == 0;
}

static const char* kUsage =
    "usage: catp_build_bench [--sizes 100000,1000000,10000000] [--memory 1G] [--bunny PATH] [--keep DIR]\n";

int main(int argc, char** argv) try {
    Options options(argc, argv, kUsage);
    if (options.help()) {
        std::printf("%s", kUsage);
        return 0;
    }
    std::vector<size_t> sizes;
    std::string list = options.get("sizes", "100000,1000000,10000000");
    for (size_t start = 0; start < list.size();) {
        size_t comma = list.find(',', start);
        sizes.push_back(std::stoull(list.substr(start, comma - start)));
        start = comma == std::string::npos ? list.size() : comma + 1;
    }
    uint64_t budget = options.bytes("memory", uint64_t(1) << 30);
    std::string bunny = options.get("bunny", std::string(CATPAQ_SOURCE_DIR) + "/data/bunny.ply");
    bool keep = options.has("keep");
    std::string dir = options.get("keep", (fs::temp_directory_path() / ("catp_build_bench_" + std::to_string(getpid()))).string());
    options.finish();
    fs::create_directories(dir);
    std::printf("catp_build_bench on %s (%ld cores)\n", cpu_model().c_str(), sysconf(_SC_NPROCESSORS_ONLN));
    std::printf("memory budget %.0f MiB; builds read binary PLY files (reading included in the time)\n",
                double(budget) / (1 << 20));
    std::printf("%-12s %11s %8s %12s %11s %10s %10s %11s %8s %9s %14s %8s\n", "input", "triangles", "seconds", "tri/s",
                "bits/vert", "MiB peak", "MiB budget", "MiB spilled", "leaf lvl", "block lvl", "meshopt tri/s", "ratio");
    std::vector<std::pair<std::string, size_t>> runs = {{"bunny", 0}};
    std::vector<std::pair<std::string, Result>> done;
    for (size_t s : sizes) runs.push_back({"scan" + std::to_string(s), s});
    for (auto& [name, size] : runs) {
        Result r;
        std::string input = name == "bunny" ? bunny : dir + "/" + name + ".ply";
        if ((size && !make_input(input, size)) || !run_in_child(input, dir + "/" + name + ".cpq", budget, r)) {
            std::printf("%-12s failed\n", name.c_str());
            continue;
        }
        double triangles = r.triangles_per_second * r.seconds;
        std::printf("%-12s %11.0f %8.2f %12.0f %11.2f %10.1f %10.0f %11.1f %8d %9d %14.0f %8.3f\n", name.c_str(),
                    triangles, r.seconds, r.triangles_per_second, r.bits_per_vertex, r.peak_mib, r.budget_mib,
                    r.spilled_mib, r.leaf_level, r.block_level, r.meshopt_triangles_per_second,
                    r.triangles_per_second / r.meshopt_triangles_per_second);
        std::fflush(stdout);
        done.push_back({name, r});
    }
    std::printf("ratio = full CATP build throughput / meshopt_simplify (one 50%% pass, 1 thread) throughput\n\n");
    // Where the time goes, and how well the cores are used (CPU time over wall time).
    std::printf("%-12s %8s %8s %8s %8s %8s %8s %10s\n", "phases (s)", "read", "bin", "clip", "nodes", "coarsen",
                "write", "cores used");
    for (auto& [name, r] : done)
        std::printf("%-12s %8.2f %8.2f %8.2f %8.2f %8.2f %8.2f %10.2f\n", name.c_str(), r.phases[0], r.phases[1],
                    r.phases[2], r.phases[3], r.phases[4], r.phases[5], r.cpu_seconds / r.seconds);
    // What a client fetches before it draws the whole model (common_codec/archive.h): the
    // prefix grows with the node count, the mission's bound is 64 KiB.
    std::printf("\n%-12s %8s %12s %12s %12s %12s\n", "first frame", "nodes", "prefix B", "level 0 B", "total B",
                "<= 64 KiB");
    for (auto& [name, r] : done)
        std::printf("%-12s %8u %12llu %12llu %12llu %12s\n", name.c_str(), r.nodes, (unsigned long long)r.first_frame.prefix_bytes,
                    (unsigned long long)r.first_frame.level0_bytes, (unsigned long long)r.first_frame.bytes(),
                    r.first_frame.bytes() <= 65536 ? "yes" : "no");
    if (!keep) fs::remove_all(dir);
    return 0;
} catch (const std::exception& e) {
    std::fprintf(stderr, "catp_build_bench: %s\n", e.what());
    return 2;
}
