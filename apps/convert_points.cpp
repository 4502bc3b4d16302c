// catpaq convert --format points: a point cloud (or a mesh's vertices or surface samples) in, a
// point dataset out (points/builder.h).
#include <cstdio>
#include <string>

#include <nlohmann/json.hpp>

#include "apps/convert_formats.h"
#include "base/error.h"
#include "base/output_path.h"
#include "base/temp_file.h"
#include "mesh/io.h"
#include "mesh/up_axis.h"
#include "points/builder.h"
#include "points/sampling.h"

namespace catpaq {

namespace {

void print_json(const PointsBuildReport& r, const ConvertJob& job, size_t surface_samples) {
    nlohmann::json levels = nlohmann::json::array();
    for (const PointsLevelStats& l : r.levels)
        levels.push_back({{"depth", l.depth}, {"nodes", l.nodes}, {"points", l.points}, {"bytes", l.bytes},
                          {"max_error", l.max_error}, {"mean_radius", l.mean_radius}});
    nlohmann::json out{
        {"format", "points"},
        {"input", {{"path", job.input}, {"points", r.input_points}, {"surface_samples", surface_samples}}},
        {"output", {{"path", job.output}, {"bytes", r.file_bytes}, {"payload_bytes", r.payload_bytes}}},
        {"nodes", r.nodes},
        {"leaves", r.leaves},
        {"depth", r.depth},
        {"leaf_points", {{"min", r.min_leaf_points}, {"mean", r.mean_leaf_points}, {"max", r.max_leaf_points}}},
        {"stored_points", r.stored_points},
        {"bytes_per_stored_point", r.stored_points ? double(r.payload_bytes) / double(r.stored_points) : 0.0},
        {"bytes_per_input_point", r.input_points ? double(r.file_bytes) / double(r.input_points) : 0.0},
        {"bytes_by_attribute",
         {{"position", r.bytes_position},
          {"normal", r.bytes_normal},
          {"color", r.bytes_color},
          {"radius", r.bytes_radius},
          {"header", r.bytes_header}}},
        {"normals_estimated", r.normals_estimated},
        {"radii_estimated", r.radii_estimated},
        {"colors", r.has_colors},
        {"worst_error_to_radius", r.worst_error_to_radius},
        {"seconds", r.seconds},
        {"seconds_by_phase",
         {{"read", r.seconds_read},
          {"partition", r.seconds_partition},
          {"search_tree", r.seconds_search_tree},
          {"nodes", r.seconds_nodes},
          {"write", r.seconds_write}}},
        {"peak_rss", r.peak_rss},
        {"memory_estimate", r.memory_estimate},
        {"out_of_core", r.out_of_core},
        {"chunks", r.chunks},
        {"split_passes", r.split_passes},
        {"dropped_input", r.dropped_input},
        {"levels", levels}};
    std::printf("%s\n", out.dump().c_str());
}

void print_table(const PointsBuildReport& r, const ConvertJob& job, size_t surface_samples) {
    if (surface_samples)
        std::printf("input:      %s: %zu points sampled on the surface\n", job.input.c_str(), r.input_points);
    else
        std::printf("input:      %s: %zu points\n", job.input.c_str(), r.input_points);
    std::printf("attributes: normals %s, radii %s, colours %s\n", r.normals_estimated ? "estimated" : "from the input",
                r.radii_estimated ? "estimated" : "from the input", r.has_colors ? "yes" : "no");
    std::printf("output:     %s: %llu bytes, %zu nodes (%zu leaves, depth %d), leaves of %zu to %zu points\n",
                job.output.c_str(), (unsigned long long)r.file_bytes, r.nodes, r.leaves, r.depth, r.min_leaf_points,
                r.max_leaf_points);
    std::printf("build:      %.2f s (reading included), %.0f input points/s, peak memory %.1f MiB\n", r.seconds,
                r.seconds > 0 ? double(r.input_points) / r.seconds : 0.0, double(r.peak_rss) / (1 << 20));
    if (r.out_of_core)
        std::printf("memory:     out of core (the in-core estimate, %.0f MiB, exceeds the budget): %zu chunks, %zu "
                    "passes over the input above them\n",
                    double(r.memory_estimate) / (1 << 20), r.chunks, r.split_passes);
    std::printf("size:       %.2f bytes per stored point (%llu stored), %.2f per input point; position error at "
                "most %.3g of the node's smallest radius\n",
                r.stored_points ? double(r.payload_bytes) / double(r.stored_points) : 0.0,
                (unsigned long long)r.stored_points,
                r.input_points ? double(r.file_bytes) / double(r.input_points) : 0.0, r.worst_error_to_radius);
    std::printf("%6s %8s %12s %12s %14s %12s %12s\n", "depth", "nodes", "points", "bytes", "bytes/point",
                "max error", "mean radius");
    for (const PointsLevelStats& l : r.levels)
        std::printf("%6d %8zu %12zu %12llu %14.2f %12.4g %12.4g\n", l.depth, l.nodes, l.points,
                    (unsigned long long)l.bytes, l.points ? double(l.bytes) / double(l.points) : 0.0, l.max_error,
                    l.mean_radius);
    std::printf("error and radius are in model units\n");
}

}  // namespace

int convert_points(Options& options, const ConvertJob& job) {
    PointsBuildSettings s;
    s.node_points = size_t(options.integer("node-points", 4096, 16, 1 << 20));
    const std::string split = options.get("split", "balanced");
    if (split == "balanced")
        s.split = PointSplitRule::Balanced;
    else if (split == "midpoint")
        s.split = PointSplitRule::Midpoint;
    else
        usage_error("--split: '%s' is not one of balanced, midpoint", split.c_str());
    s.error_fraction = options.number("error-fraction", 0.25, 1e-3, 1.0);
    const std::string normals = options.get("normals", "auto");
    if (normals == "auto")
        s.orientation = NormalOrientation::Auto;
    else if (normals == "outward")
        s.orientation = NormalOrientation::Outward;
    else if (normals == "up")
        s.orientation = NormalOrientation::Up;
    else
        usage_error("--normals: '%s' is not one of auto, outward, up", normals.c_str());
    const size_t surface_samples = size_t(options.integer("surface-samples", 0, 1, int64_t(1) << 32));
    s.threads = unsigned(options.integer("threads", 0, 0, 1024));
    // As for catp: half the physical memory unless told; a cloud whose in-core estimate exceeds
    // the budget is converted out of core.
    s.memory_budget = options.bytes("memory", physical_memory_bytes() / 2);
    // The up axis: --up, else the input's convention (LAS: z), else y as for catp and aqp.
    UpAxis up = UpAxis::Unknown;
    if (options.has("up") && !parse_up_axis(options.get("up", ""), up))
        usage_error("--up: '%s' is not one of x, y, z, -x, -y, -z", options.get("up", "").c_str());
    s.progress = !job.quiet;
    options.finish();

    prepare_output(job);
    PointsBuildReport r;
    if (surface_samples) {
        // A mesh sampled uniformly by area, as a scanner samples a surface (points/sampling.h).
        std::vector<std::string> dropped;
        const Mesh mesh = read_mesh(job.input, &dropped);
        if (mesh.triangle_count() == 0)
            fail("'%s': --surface-samples needs a mesh with triangles; this file has none", job.input.c_str());
        s.up_axis = uint8_t(up == UpAxis::Unknown ? UpAxis::PosY : up);
        r = build_points(sample_surface(mesh, surface_samples, 1, true, true), job.output, s);
        r.dropped_input = dropped;
    } else {
        PointFileReader reader(job.input);
        s.up_axis = uint8_t(up != UpAxis::Unknown ? up : reader.info().z_up ? UpAxis::PosZ : UpAxis::PosY);
        r = build_points_stream(reader, job.output, s);
    }
    for (const std::string& d : r.dropped_input)
        std::fprintf(stderr, "catpaq convert: warning: '%s': left out: %s\n", job.input.c_str(), d.c_str());
    warn_about_first_frame(job, "--node-points");
    if (job.json)
        print_json(r, job, surface_samples);
    else if (!job.quiet)
        print_table(r, job, surface_samples);
    return 0;
}

}  // namespace catpaq
