// catpaq convert: a mesh in, a streamable multiresolution dataset out.
#include <cstdio>
#include <string>

#include "apps/commands.h"
#include "base/error.h"
#include "base/options.h"
#include "base/output_path.h"
#include "base/sysinfo.h"
#include "catp/builder.h"
#include "common_codec/archive.h"
#include "catp/lattice.h"
#include "mesh/io.h"

#include <nlohmann/json.hpp>

#include "apps/convert_formats.h"
#include "common_codec/archive.h"

namespace catpaq {

static const char* kConvertUsage =
    "usage: catpaq convert INPUT -o OUTPUT.cpq [--format catp|aqp|points] [options]\n"
    "  Converts a mesh (PLY, OBJ, OFF, STL) into a streamable multiresolution dataset: CATP\n"
    "  (default) or AQP; or a point cloud (PLY, XYZ, PTS, LAS; or a mesh's vertices or surface\n"
    "  samples) into a point dataset.\n"
    "options:\n"
    "  -o, --output FILE        output dataset (.cpq), written atomically\n"
    "  --format F               catp (Compact Adaptive TetraPuzzles), aqp (Adaptive Quad Patches)\n"
    "                           or points (a kd-tree of splats)\n"
    "  --threads N              worker threads (default: all cores)\n"
    "  --up AXIS                the model's up axis, stored for viewers: x, y, z, -x, -y, -z (default y;\n"
    "                           points: z for LAS, else y)\n"
    "  --json                   the report as one JSON object on stdout (progress stays on stderr)\n"
    "  --quiet                  no progress bar or report\n"
    "catp and aqp:\n"
    "  --precision P            the finest level's largest quantization distance: P in model\n"
    "                           units, or Pe in mean input edges (default 0.1e)\n"
    "  --memory SIZE            memory budget, e.g. 512M or 4G (catp: default half the physical\n"
    "                           memory, PLY input is streamed and scratch data beyond the budget goes\n"
    "                           to anonymous files next to the output; aqp: default half the\n"
    "                           physical memory, works in core (about 400 bytes a triangle): a PLY\n"
    "                           above the budget is first simplified out of core, block by block\n"
    "                           from scratch files next to the output, to what fits, a point\n"
    "                           cloud (about 5200 bytes a point to reconstruct) sampled to what\n"
    "                           fits; points:\n"
    "                           default half the physical memory; a cloud whose in-core estimate,\n"
    "                           about 62 bytes a point, exceeds it is read into scratch files next\n"
    "                           to the output and built one part at a time, the same dataset)\n"
    "catp:\n"
    "  --vertex-layout L        auto (default: position48 without colours; with colours rgb24 when\n"
    "                           its grid reaches the precision, else rgb18), rgb24 (8-bit colour,\n"
    "                           deeper leaves if needed), rgb18 (6-bit colour, 4x finer positions),\n"
    "                           position48 (no colour, 35x finer positions)\n"
    "  --leaf-triangles N       target triangles per leaf fragment (default 2000)\n"
    "  --leaf-level L           force the leaf level of the diamond hierarchy\n"
    "aqp (closed surfaces; a point cloud, a PLY without faces, XYZ, PTS or LAS, is first\n"
    "reconstructed as one by Poisson's method, and refused when it does not enclose a volume):\n"
    "  --patch-level K          finest level: patches of (2^K+1)^2 samples, 1 to 10 (default: about\n"
    "                           twice the input's vertices in samples)\n"
    "  --domain-triangles N     base domain triangles (default 0.6 sqrt(input triangles), built\n"
    "                           again with 1.3x up to three times when the map folds); fewer\n"
    "                           when patches outgrow their charts, more for folds\n"
    "  --tile-samples N         each level's nodes group 4^s neighbouring patches, as many as keep a\n"
    "                           node within N stored samples (default 512; 0: one patch per node)\n"
    "points:\n"
    "  --node-points N          the most points in a node (default 4096)\n"
    "  --split RULE             balanced (default; seed 000) or midpoint (seed 002)\n"
    "  --error-fraction F       position error over the node's smallest splat radius (default 0.25)\n"
    "  --normals ORIENT         orientation of estimated normals: auto (default), outward, up\n"
    "  --surface-samples N      for a mesh input: N points sampled on its surface instead of its vertices\n";

// Thin geometry the quantization grid cannot hold is drawn at no level: say how much, and what
// it does to the error bounds (which include it) or to levels that draw nothing at all.
static void warn_about_lost_geometry(const CatpBuildReport& r) {
    if (r.lost_beyond_step) {
        const CatpLevelStats& finest = r.levels.back();
        std::fprintf(stderr,
                     "catpaq convert: warning: thin geometry is lost: %zu pieces of input triangles (area %.3g) "
                     "are thinner than the quantization step and are drawn at no level; the stored error bounds "
                     "include their distance to what is drawn (up to %.6g at the finest level, whose largest bound is "
                     "%.6g)\n",
                     r.lost_triangles, r.lost_area, r.lost_error, finest.max_error);
    }
    std::string empty;
    for (const CatpLevelStats& l : r.levels)
        if (l.diamonds && l.empty_diamonds == l.diamonds) empty += (empty.empty() ? "" : ", ") + std::to_string(l.level);
    if (!empty.empty())
        std::fprintf(stderr,
                     "catpaq convert: warning: level%s %s draw%s nothing at all (all of the surface there is thinner "
                     "than the quantization step): no error bound holds for %s\n",
                     empty.find(',') != std::string::npos ? "s" : "", empty.c_str(),
                     empty.find(',') != std::string::npos ? "" : "s",
                     empty.find(',') != std::string::npos ? "them" : "it");
}

// The options only some formats take, and which: given to another format they are refused by
// name rather than ignored.
struct FormatOption {
    const char* name;
    const char* formats;
};
static const FormatOption kFormatOptions[] = {
    {"precision", "catp aqp"},      {"memory", "catp aqp points"},       {"vertex-layout", "catp"},
    {"leaf-triangles", "catp"},   {"leaf-level", "catp"},
    {"patch-level", "aqp"},         {"domain-triangles", "aqp"},  {"tile-samples", "aqp"},
    {"node-points", "points"},
    {"split", "points"},            {"error-fraction", "points"}, {"normals", "points"},
    {"surface-samples", "points"},
};

// The CATP report as JSON (convert --json): the same figures as the table.
static void print_catp_json(const CatpBuildReport& r, const ConvertJob& job, uint64_t own) {
    nlohmann::json levels = nlohmann::json::array();
    for (const CatpLevelStats& l : r.levels)
        if (l.diamonds)
            levels.push_back({{"level", l.level}, {"diamonds", l.diamonds}, {"fragments", l.fragments},
                              {"triangles", l.triangles}, {"vertices", l.vertices}, {"bytes", l.bytes},
                              {"max_error", l.max_error}});
    nlohmann::json out{{"format", "catp"},
                       {"input", {{"path", job.input}, {"vertices", r.input_vertices}, {"triangles", r.input_triangles}}},
                       {"output", {{"path", job.output}, {"bytes", r.file_bytes}, {"diamonds", r.nodes}}},
                       {"leaf_level", r.leaf_level},
                       {"coarsest_leaf_level", r.coarsest_leaf_level},
                       {"density_leaf_level", r.density_leaf_level},
                       {"blocks", r.blocks},
                       {"block_level", r.block_level},
                       {"leaves_across_blocks", r.leaves_across_blocks},
                       {"precision", r.precision},
                       {"mean_edge", r.mean_edge},
                       {"vertex_layout", r.layout.name()},
                       {"grid", r.layout.grid},
                       {"leaf_step", r.leaf_step},
                       {"seconds", r.seconds},
                       {"peak_rss", r.peak_rss},
                       {"memory_budget", r.memory_budget + own},
                       {"bytes_spilled", r.bytes_spilled},
                       {"diagonal", r.diagonal},
                       {"dropped_input", r.dropped_input},
                       {"warnings", r.warnings},
                       {"levels", levels}};
    std::printf("%s\n", out.dump().c_str());
}

int cmd_convert(int argc, char** argv) {
    // Accept -o as an alias of --output.
    std::vector<char*> args(argv, argv + argc);
    std::string output_flag = "--output";
    for (auto& a : args)
        if (std::string(a) == "-o") a = output_flag.data();
    Options options(int(args.size()), args.data(), kConvertUsage, {"quiet", "json"});
    if (options.help()) {
        std::printf("%s", kConvertUsage);
        return 0;
    }
    if (options.positional().size() != 1) usage_error("expected one input file");
    ConvertJob job;
    job.input = options.positional()[0];
    job.output = options.require("output");
    // Refused at once, before reading anything: a directory, a missing or read-only directory.
    check_output_file(job.output, "-o");
    const std::string format = options.get("format", "catp");
    if (format != "catp" && format != "aqp" && format != "points")
        usage_error("unknown --format '%s' (available: catp, aqp, points)", format.c_str());
    for (const FormatOption& o : kFormatOptions)
        if (options.has(o.name) && (" " + std::string(o.formats) + " ").find(" " + format + " ") == std::string::npos) {
            std::string applies = o.formats;
            if (size_t space = applies.find(' '); space != std::string::npos) applies.replace(space, 1, " and ");
            usage_error("--%s applies to --format %s, not %s", o.name, applies.c_str(), format.c_str());
        }
    job.quiet = options.flag("quiet");
    job.json = options.flag("json");
    if (format == "aqp") return convert_aqp(options, job);
    if (format == "points") return convert_points(options, job);
    return convert_catp(options, job);
}

void prepare_output(const ConvertJob& job) {
    for (const std::string& stale : remove_stale_temporaries(job.output))
        std::fprintf(stderr, "catpaq convert: removed '%s', left by an interrupted run\n", stale.c_str());
}

void warn_about_first_frame(const ConvertJob& job, const char* fewer_nodes) {
    ArchiveReader reader(job.output);
    const FirstFrame first = archive_first_frame(reader.header(), reader.entries());
    if (first.bytes() <= kFirstRequestBytes) return;
    std::fprintf(stderr,
                 "catpaq convert: warning: a client needs %llu bytes before it draws the model (the prefix, %llu "
                 "bytes listing all %zu nodes, and level 0), over the 64 KiB of a first request; larger nodes "
                 "(%s) make fewer\n",
                 (unsigned long long)first.bytes(), (unsigned long long)first.prefix_bytes, reader.entries().size(),
                 fewer_nodes);
}

// CATP: build_catp_file (catp/builder.h) with the options above; the report as a table or JSON.
int convert_catp(Options& options, const ConvertJob& job) {
    CatpBuildSettings settings;
    settings.leaf_triangles = size_t(options.integer("leaf-triangles", 2000, 50, 1000000));
    settings.leaf_level = int(options.integer("leaf-level", -1, -1, kMaxLevel - 3));
    settings.threads = unsigned(options.integer("threads", 0, 0, 1024));
    const std::string precision = options.get("precision", "0.1e");
    if (!parse_precision(precision, settings.precision))
        fail("--precision: '%s' is not a positive distance in model units (0.001) or in mean edges (0.1e)",
             precision.c_str());
    const std::string layout = options.get("vertex-layout", "auto");
    if (!parse_layout_choice(layout, settings.layout))
        fail("--vertex-layout: '%s' is not one of auto, rgb24, rgb18, position48", layout.c_str());
    const std::string up = options.get("up", "y");
    if (!parse_up_axis(up, settings.up)) fail("--up: '%s' is not one of x, y, z, -x, -y, -z", up.c_str());
    // --memory bounds the whole process: the program's own code and libraries come first, as
    // resident now plus the pages of code the build has still to load (measured: the file-backed
    // part of the resident memory grows by 1-2 MiB after this point). The resident size is
    // rounded up to 4 MiB: it varies by some pages from run to run (12.2 to 12.6 MiB when the
    // input is opened). The smallest budget the tool names must be one the next run accepts, also
    // when the resident size straddles a multiple of 4 MiB (it did at 12 MiB: the tool named 102
    // MiB in a third of the runs and refused 102 in the others, asking 106): so a budget is
    // accepted for the size measured, and the one named in a refusal is the one for the size plus
    // kOwnVariation.
    constexpr uint64_t kCodeStillToLoad = uint64_t(2) << 20, kOwnGranule = uint64_t(4) << 20;
    constexpr uint64_t kOwnVariation = uint64_t(1) << 20;
    auto own_for = [&](uint64_t resident) {
        return (resident + kOwnGranule - 1) / kOwnGranule * kOwnGranule + kCodeStillToLoad;
    };
    const uint64_t resident = current_rss_bytes();
    uint64_t own = own_for(resident);
    if (options.has("memory")) {
        uint64_t process_budget = options.bytes("memory", 0);
        if (process_budget < own + minimum_memory_budget(settings.threads)) {
            const uint64_t named_own = own_for(resident + kOwnVariation);
            const uint64_t needed = named_own + minimum_memory_budget(settings.threads);
            usage_error("--memory: at least %llu MiB are needed (%llu MiB for the converter's data and threads, %llu MiB "
                 "for the program itself)",
                 (unsigned long long)((needed + (1 << 20) - 1) >> 20),
                 (unsigned long long)(minimum_memory_budget(settings.threads) >> 20),
                 (unsigned long long)(named_own >> 20));
        }
        settings.memory_budget = process_budget - own;
    }
    settings.progress = !job.quiet;
    options.finish();

    prepare_output(job);
    const std::string& input = job.input;
    const std::string& output = job.output;
    CatpBuildReport r = build_catp_file(input, output, settings);
    for (const std::string& w : r.warnings) std::fprintf(stderr, "catpaq convert: warning: %s\n", w.c_str());
    for (const std::string& d : r.dropped_input)
        std::fprintf(stderr, "catpaq convert: warning: '%s': left out: %s\n", input.c_str(), d.c_str());
    warn_about_lost_geometry(r);
    warn_about_first_frame(job, "--leaf-triangles");
    if (job.json) {
        print_catp_json(r, job, own);
        return 0;
    }
    if (job.quiet) return 0;
    size_t vertices = 0, triangles = 0;
    for (const CatpLevelStats& l : r.levels) {
        vertices += l.vertices;
        triangles += l.triangles;
    }
    std::printf("input:      %s: %zu vertices, %zu triangles\n", input.c_str(), r.input_vertices, r.input_triangles);
    std::printf("output:     %s: %llu bytes, %zu diamonds, deepest leaves at level %d\n", output.c_str(),
                (unsigned long long)r.file_bytes, r.nodes, r.leaf_level);
    std::printf("precision:  %.4g model units (%.3g mean edges of %.4g): vertex layout %s, grid %d, leaf step %.4g\n",
                r.precision, r.precision / r.mean_edge, r.mean_edge, r.layout.name(), r.layout.grid, r.leaf_step);
    std::printf("leaves:     levels %d to %d, following the density (even at level %d)\n", r.coarsest_leaf_level,
                r.leaf_level, r.density_leaf_level);
    uint64_t process_budget = r.memory_budget + own;
    std::printf("build:      %.2f s (reading included), %.0f input triangles/s, peak memory %.1f MiB of a %.0f MiB budget\n",
                r.seconds, double(r.input_triangles) / r.seconds, double(r.peak_rss) / (1 << 20),
                double(process_budget) / (1 << 20));
    std::printf("out of core: %zu blocks at level %d, triangles binned %s, %.1f MiB of scratch data written to disk",
                r.blocks, r.block_level, r.compact_bins ? "by vertex index" : "with their vertices",
                double(r.bytes_spilled) / (1 << 20));
    if (r.leaves_across_blocks) std::printf(", %zu leaves across blocks", r.leaves_across_blocks);
    std::printf("\n");
    std::printf("phases:     read %.2f s, bin %.2f s, clip %.2f s, leaf nodes %.2f s, coarsen %.2f s, write %.2f s\n",
                r.seconds_read, r.seconds_bin, r.seconds_clip, r.seconds_leaf_nodes, r.seconds_coarsen,
                r.seconds_write);
    std::printf("size:       %.2f bits per stored vertex over all levels (%zu vertices, %zu triangles)\n",
                vertices ? 8.0 * double(r.file_bytes) / double(vertices) : 0.0, vertices, triangles);
    std::printf("%6s %9s %10s %10s %12s %14s %12s\n", "level", "diamonds", "fragments", "triangles", "bytes",
                "bits/vertex", "error");
    for (const CatpLevelStats& l : r.levels) {
        if (!l.diamonds) continue;
        std::printf("%6d %9zu %10zu %10zu %12llu %14.2f %12.4g\n", l.level, l.diamonds, l.fragments, l.triangles,
                    (unsigned long long)l.bytes, l.vertices ? 8.0 * double(l.bytes) / double(l.vertices) : 0.0,
                    l.max_error);
    }
    std::printf("error is in model units; the bounding-box diagonal is %.6g\n", r.diagonal);
    return 0;
}

}  // namespace catpaq
