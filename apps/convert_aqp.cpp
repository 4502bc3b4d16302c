// catpaq convert --format aqp: a mesh in, an Adaptive Quad Patches dataset out (aqp/build.h).
#include <cctype>
#include <cstdio>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "apps/convert_formats.h"
#include "aqp/build.h"
#include "aqp/format.h"
#include "aqp/reduce.h"
#include "aqp_reconstruct/poisson.h"
#include "base/error.h"
#include "base/temp_file.h"
#include "mesh/io.h"
#include "mesh/up_axis.h"
#include "mesh/precision.h"
#include "points/point_cloud.h"

namespace catpaq {

namespace {

// What cleaning did to the input (aqp/clean.h), as JSON: every count, zero or not, so that a
// script can rely on the keys.
nlohmann::json clean_json(const aqp::CleanReport& c) {
    return {{"input_vertices", c.input_vertices},
            {"input_triangles", c.input_triangles},
            {"welded_vertices", c.welded_vertices},
            {"degenerate_triangles", c.degenerate_triangles},
            {"duplicate_triangles", c.duplicate_triangles},
            {"nonmanifold_edges", c.nonmanifold_edges},
            {"nonmanifold_vertices", c.nonmanifold_vertices},
            {"split_vertices", c.split_vertices},
            {"nonmanifold_triangles_removed", c.nonmanifold_triangles_removed},
            {"flipped_triangles", c.flipped_triangles},
            {"dropped_components", c.dropped_components},
            {"dropped_component_triangles", c.dropped_component_triangles},
            {"unreferenced_vertices", c.unreferenced_vertices},
            {"vertices", c.vertices},
            {"triangles", c.triangles},
            {"components", c.components},
            {"border_edges", c.border_edges},
            {"border_loops", c.border_loops},
            {"genus", c.genus},
            {"summary", c.summary()}};
}

// The file name's extension, from its last dot, in lower case ("" without one).
std::string lower_extension(const std::string& path) {
    std::string ext = path.substr(path.find_last_of('.') == std::string::npos ? path.size() : path.find_last_of('.'));
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    return ext;
}

// True for files read as point clouds: the point formats by extension, and a PLY without faces
// (its header says so).
bool is_point_input(const std::string& path) {
    const std::string ext = lower_extension(path);
    if (ext == ".xyz" || ext == ".txt" || ext == ".pts" || ext == ".las" || ext == ".laz") return true;
    return ext == ".ply" && PlyStream(path).face_count() == 0;
}

nlohmann::json poisson_json(const aqp::PoissonReport* p, uint64_t file_points) {
    if (!p) return nullptr;
    return {{"file_points", file_points},  // in the file (input_points: those reconstructed, a sample when fewer)
            {"input_points", p->input_points},       {"normals_estimated", p->normals_estimated},
            {"repeated_dropped", p->repeated_dropped}, {"unoriented_dropped", p->unoriented_dropped},
            {"average_spacing", p->average_spacing},  {"evaluations", p->evaluations},
            {"vertices", p->vertices},               {"triangles", p->triangles},
            {"seconds", p->seconds}};
}

nlohmann::json reduction_json(const aqp::ReduceReport* p) {
    if (!p) return nullptr;
    return {{"input_vertices", p->input_vertices},     {"input_triangles", p->input_triangles},
            {"round1_triangles", p->round1_triangles}, {"vertices", p->vertices},
            {"triangles", p->triangles},               {"blocks", p->blocks},
            {"largest_block", p->largest_block},       {"vertex_distance", p->vertex_distance},
            {"memory_estimate", p->memory_estimate},   {"scratch_bytes", p->scratch_bytes},
            {"seconds", p->seconds}};
}

void print_json(const aqp::AqpBuildReport& r, const ConvertJob& job, const std::vector<std::string>& dropped,
                const aqp::PoissonReport* poisson, uint64_t file_points, const aqp::ReduceReport* reduction) {
    const aqp::ParamCheck& pc = r.domain.check;
    nlohmann::json levels = nlohmann::json::array();
    for (const aqp::AqpLevelStats& l : r.levels)
        levels.push_back({{"level", l.level}, {"nodes", l.nodes}, {"samples", l.samples}, {"bytes", l.bytes},
                          {"max_error", l.max_error}, {"mean_error", l.mean_error}});
    nlohmann::json out{
        {"format", "aqp"},
        {"input",
         {{"path", job.input},
          {"vertices", reduction ? reduction->input_vertices : r.clean.input_vertices},
          {"triangles", reduction ? reduction->input_triangles : r.clean.input_triangles}}},
        {"output", {{"path", job.output}, {"bytes", r.file_bytes}, {"payload_bytes", r.payload_bytes}}},
        {"poisson", poisson_json(poisson, file_points)},
        {"reduction", reduction_json(reduction)},
        {"clean", clean_json(r.clean)},
        {"domain",
         {{"base_vertices", r.domain.base_vertices},
          {"base_triangles", r.domain.base_triangles},
          {"base_border_edges", r.domain.base_border_edges},
          {"bijective", pc.bijective()},
          {"angle_distortion_mean", pc.angle_distortion_mean},
          {"angle_distortion_p99", pc.angle_distortion_p99},
          {"angle_distortion_max", pc.angle_distortion_max},
          {"area_distortion_mean", pc.area_distortion_mean},
          {"area_distortion_p99", pc.area_distortion_p99},
          {"area_distortion_max", pc.area_distortion_max}}},
        {"patches", r.patches},
        {"patch_level", r.patch_level},
        {"samples", r.samples},
        {"bits_per_sample", r.bits_per_sample},
        {"step", r.step},
        {"precision", r.precision},
        {"precision_asked", r.precision_asked},
        {"mean_edge", r.mean_edge},
        {"diagonal", r.diagonal},
        {"collapsed_triangles", r.collapsed_triangles},
        {"seconds", r.seconds},
        {"seconds_by_phase",
         {{"clean", r.seconds_clean},
          {"simplify", r.domain.seconds_simplify},
          {"smooth", r.domain.seconds_smooth},
          {"parameterize", r.seconds_parameterize},
          {"resample", r.seconds_resample},
          {"errors", r.seconds_errors},
          {"encode", r.seconds_encode}}},
        {"peak_rss", r.peak_rss},
        {"memory_estimate", r.memory_estimate},
        {"dropped_input", dropped},
        {"warnings", r.warnings},
        {"levels", levels}};
    std::printf("%s\n", out.dump().c_str());
}

void print_table(const aqp::AqpBuildReport& r, const ConvertJob& job, const aqp::PoissonReport* poisson,
                 const aqp::ReduceReport* reduction) {
    const aqp::ParamCheck& pc = r.domain.check;
    if (poisson) {
        std::printf("points:     %s: %zu points; Poisson surface (CGAL) of %zu vertices, %zu triangles in %.2f s "
                    "(spacing %.4g",
                    job.input.c_str(), poisson->input_points, poisson->vertices, poisson->triangles, poisson->seconds,
                    poisson->average_spacing);
        if (poisson->repeated_dropped)
            std::printf("; %zu repeated points left out", poisson->repeated_dropped);
        if (poisson->normals_estimated)
            std::printf("; normals estimated, %zu points left out unoriented", poisson->unoriented_dropped);
        std::printf(")\n");
    }
    if (reduction) {
        std::printf("input:      %s: %llu vertices, %llu triangles, above the memory budget in core\n", job.input.c_str(),
                    (unsigned long long)reduction->input_vertices, (unsigned long long)reduction->input_triangles);
        std::printf("reduced:    out of core to %llu vertices, %llu triangles in %.2f s (%u blocks simplified in two "
                    "rounds; removed vertices at most %.4g from the result, added to the errors below)\n",
                    (unsigned long long)reduction->vertices, (unsigned long long)reduction->triangles, reduction->seconds,
                    reduction->blocks, reduction->vertex_distance);
    } else {
        std::printf("input:      %s: %zu vertices, %zu triangles\n", job.input.c_str(), r.clean.input_vertices,
                    r.clean.input_triangles);
    }
    std::printf("cleaned:    %zu vertices, %zu triangles, %zu component%s, genus %d, %zu border loops\n",
                r.clean.vertices, r.clean.triangles, r.clean.components, r.clean.components == 1 ? "" : "s",
                r.clean.genus, r.clean.border_loops);
    for (const std::string& line : r.clean.summary()) std::printf("            %s\n", line.c_str());
    std::printf("output:     %s: %llu bytes, %zu patches of %d x %d samples (level %d)\n", job.output.c_str(),
                (unsigned long long)r.file_bytes, r.patches, (1 << r.patch_level) + 1, (1 << r.patch_level) + 1,
                r.patch_level);
    std::printf("domain:     %zu base triangles; angle distortion mean %.3g, 99%% %.3g; area distortion mean %.3g, "
                "99%% %.3g\n",
                r.domain.base_triangles, pc.angle_distortion_mean, pc.angle_distortion_p99, pc.area_distortion_mean,
                pc.area_distortion_p99);
    std::printf("precision:  %.4g model units (%.3g mean edges of %.4g), step %.4g\n", r.precision,
                r.mean_edge > 0 ? r.precision / r.mean_edge : 0.0, r.mean_edge, r.step);
    std::printf("build:      %.2f s (reading excluded), %.0f input triangles/s, peak memory %.1f MiB\n", r.seconds,
                r.seconds > 0 ? double(r.clean.input_triangles) / r.seconds : 0.0, double(r.peak_rss) / (1 << 20));
    std::printf("phases:     clean %.2f s, parameterize %.2f s, resample %.2f s, errors %.2f s, encode %.2f s\n",
                r.seconds_clean, r.seconds_parameterize, r.seconds_resample, r.seconds_errors, r.seconds_encode);
    std::printf("size:       %.2f bits per finest sample over all levels (%zu distinct samples)\n", r.bits_per_sample,
                r.samples);
    std::printf("%6s %8s %12s %12s %14s %12s %12s\n", "level", "nodes", "samples", "bytes", "bits/sample",
                "max error", "mean error");
    for (const aqp::AqpLevelStats& l : r.levels)
        std::printf("%6d %8zu %12zu %12llu %14.2f %12.4g %12.4g\n", l.level, l.nodes, l.samples,
                    (unsigned long long)l.bytes, l.samples ? 8.0 * double(l.bytes) / double(l.samples) : 0.0,
                    l.max_error, l.mean_error);
    std::printf("error is in model units; the bounding-box diagonal is %.6g\n", r.diagonal);
}

// The triangles a reduction aims at under `budget`: as many as both the in-core converter's
// estimate (with room for a result up to 10% above its target) and the reduction's own allow.
uint64_t aqp_triangles_within(uint64_t budget, uint64_t input_vertices, uint64_t input_faces) {
    auto fits = [&](uint64_t t) {
        return aqp::aqp_memory_estimate(t + t / 10) <= budget &&
               aqp::reduce_memory_estimate(input_vertices, t, budget) <= budget;
    };
    uint64_t lo = 0, hi = input_faces;
    while (lo < hi) {
        const uint64_t mid = hi - (hi - lo) / 2;
        if (fits(mid)) lo = mid;
        else hi = mid - 1;
    }
    return lo;
}
// Fewer points than this are not worth a reconstruction (a sample this small of a large cloud
// would lose most of it).
constexpr uint64_t kMinReconstructedPoints = 10000;
// Fewer triangles than this are not worth a reduction (the domain alone wants a few hundred).
constexpr uint64_t kMinReducedTriangles = 20000;
// The smallest budget under which a file of this size reduces to `least` triangles (fewer than
// its faces: a large enough budget reaches them).
uint64_t aqp_budget_for_reduction(uint64_t input_vertices, uint64_t input_faces, uint64_t least) {
    uint64_t budget = aqp::aqp_memory_estimate(0);
    while (aqp_triangles_within(budget, input_vertices, input_faces) < least) budget += uint64_t(1) << 20;
    return budget;
}

}  // namespace

int convert_aqp(Options& options, const ConvertJob& job) {
    aqp::AqpBuildOptions o;
    const std::string precision = options.get("precision", "0.1e");
    if (!parse_precision(precision, o.precision))
        usage_error("--precision: '%s' is not a positive distance in model units (0.001) or in mean edges (0.1e)",
                    precision.c_str());
    o.patch_level = int(options.integer("patch-level", -1, 1, aqp::kMaxPatchLevel));
    o.domain_triangles = size_t(options.integer("domain-triangles", 0, 4, 10000000));
    o.tile_samples = size_t(options.integer("tile-samples", int64_t(o.tile_samples), 0, int64_t(1) << 30));
    o.threads = unsigned(options.integer("threads", 0, 0, 1024));
    const std::string up = options.get("up", "y");
    UpAxis axis;
    if (!parse_up_axis(up, axis)) usage_error("--up: '%s' is not one of x, y, z, -x, -y, -z", up.c_str());
    o.up_axis = uint32_t(axis);
    // As for catp and points: half the physical memory unless told.
    o.memory_budget = options.bytes("memory", physical_memory_bytes() / 2);
    o.progress = !job.quiet;
    options.finish();

    prepare_output(job);
    // The budget is checked before the mesh is read where the file says its size (PLY): a mesh
    // whose in-core estimate exceeds it is reduced out of core to what fits (aqp/reduce.h), and
    // converted from that. (Faces count as one triangle each: polygons only make the estimate
    // low, and the converter checks again on the triangles.) Other mesh formats are read whole.
    std::vector<std::string> dropped;
    Mesh input;
    std::unique_ptr<aqp::ReduceReport> reduction;
    const bool points = is_point_input(job.input);
    if (o.memory_budget && !points && lower_extension(job.input) == ".ply") {
        const PlyStream ply(job.input);
        const uint64_t faces = ply.face_count();
        // A mesh that small is not worth reducing: the in-core estimate is what it needs.
        if (faces <= kMinReducedTriangles && aqp::aqp_memory_estimate(faces) > o.memory_budget)
            fail("converting %llu triangles to AQP needs about %llu MiB (AQP converts in core), above the budget of %llu "
                 "MiB: give --memory %lluM or more",
                 (unsigned long long)faces, (unsigned long long)(aqp::aqp_memory_estimate(faces) >> 20),
                 (unsigned long long)(o.memory_budget >> 20),
                 (unsigned long long)((aqp::aqp_memory_estimate(faces) + (uint64_t(1) << 20) - 1) >> 20));
        if (faces && aqp::aqp_memory_estimate(faces) > o.memory_budget) {
            aqp::ReduceOptions ro;
            ro.target_triangles = aqp_triangles_within(o.memory_budget, ply.vertex_count(), faces);
            ro.memory_budget = o.memory_budget;
            ro.scratch_near = job.output;
            ro.threads = o.threads;
            ro.progress = o.progress;
            if (ro.target_triangles < kMinReducedTriangles) {
                const uint64_t needed = aqp_budget_for_reduction(ply.vertex_count(), faces, kMinReducedTriangles);
                fail("converting %llu triangles to AQP needs about %llu MiB in core, above the budget of %llu MiB, and "
                     "reducing them out of core first to a mesh that fits needs at least %llu MiB: give --memory "
                     "%lluM or more",
                     (unsigned long long)faces, (unsigned long long)(aqp::aqp_memory_estimate(faces) >> 20),
                     (unsigned long long)(o.memory_budget >> 20), (unsigned long long)(needed >> 20),
                     (unsigned long long)((needed + (uint64_t(1) << 20) - 1) >> 20));
            }
            dropped = ply.dropped();
            reduction = std::make_unique<aqp::ReduceReport>();
            input = aqp::reduce_ply_out_of_core(job.input, ro, reduction.get());
            o.input_error = reduction->vertex_distance;
        }
    }
    // A mesh is converted as it is; a point cloud (with normals, or they are estimated) becomes a
    // closed surface by Poisson reconstruction first, as the paper does for scans.
    std::unique_ptr<aqp::PoissonReport> poisson;
    if (!reduction && !points) input = read_mesh(job.input, &dropped);
    uint64_t cloud_points = 0;
    if (points) {
        // The reconstruction works in core: a cloud above the budget is sampled uniformly (in one
        // pass over the file) to the points that fit.
        const uint64_t fixed = aqp::poisson_memory_estimate(0), per_point = aqp::poisson_memory_estimate(1) - fixed;
        const uint64_t fit = o.memory_budget > fixed ? (o.memory_budget - fixed) / per_point : 0;
        PointReadInfo info;
        const PointCloud cloud = read_point_sample(job.input, size_t(std::clamp<uint64_t>(fit, 1, SIZE_MAX)), &info,
                                                   &cloud_points);
        if (cloud_points > cloud.size() && cloud.size() < kMinReconstructedPoints)
            fail("reconstructing a surface from the %llu points of '%s' needs at least %llu MiB (the budget is %llu "
                 "MiB): give --memory %lluM or more",
                 (unsigned long long)cloud_points, job.input.c_str(),
                 (unsigned long long)(aqp::poisson_memory_estimate(kMinReconstructedPoints) >> 20),
                 (unsigned long long)(o.memory_budget >> 20),
                 (unsigned long long)((aqp::poisson_memory_estimate(kMinReconstructedPoints) >> 20) + 1));
        dropped = info.dropped;
        if (cloud_points > cloud.size())
            std::fprintf(stderr,
                         "catpaq convert: warning: '%s': %llu points need about %llu MiB to reconstruct, above the budget "
                         "of %llu MiB: a uniform sample of %zu is reconstructed\n",
                         job.input.c_str(), (unsigned long long)cloud_points,
                         (unsigned long long)(aqp::poisson_memory_estimate(cloud_points) >> 20),
                         (unsigned long long)(o.memory_budget >> 20), cloud.size());
        if (!job.quiet) std::fprintf(stderr, "catpaq convert: %zu points: Poisson reconstruction...\n", cloud.size());
        poisson = std::make_unique<aqp::PoissonReport>();
        input = aqp::poisson_reconstruct(cloud.positions, cloud.normals, aqp::PoissonOptions{}, poisson.get());
        if (cloud.has_colors())
            dropped.push_back("point colours (the reconstructed surface has none)");
    }
    for (const std::string& d : dropped)
        std::fprintf(stderr, "catpaq convert: warning: '%s': left out: %s\n", job.input.c_str(), d.c_str());
    aqp::AqpBuildReport r;
    aqp::build_aqp_dataset(input, job.output, o, &r);
    for (const std::string& w : r.warnings) std::fprintf(stderr, "catpaq convert: warning: %s\n", w.c_str());
    warn_about_first_frame(job, "--tile-samples");
    if (job.json)
        print_json(r, job, dropped, poisson.get(), cloud_points, reduction.get());
    else if (!job.quiet)
        print_table(r, job, poisson.get(), reduction.get());
    return 0;
}

}  // namespace catpaq
