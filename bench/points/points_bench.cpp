// points_bench: the point converter and its node codec on scan-like clouds (random samples of
// the generated scan-like surface, mesh/generators.h, with colours; normals and radii estimated
// by the converter unless --with-normals). Each conversion runs in a fresh child process that
// reads the cloud from a binary PLY, so its peak resident memory (from the kernel) is the
// conversion's, reading included. Parts:
//
//   conversion   input points/s (wall), CPU seconds (all threads), peak memory, bytes per input
//                point and per stored point (all levels), the payload's split by attribute, and
//                as a baseline in this process meshoptimizer's meshopt_simplifyPoints halving the
//                same cloud (one pass, one thread): "ratio" is our points/s over its
//   decode       decode_point_node over every node of the first dataset, one thread, points per
//                second of thread CPU time; baseline: meshoptimizer's vertex codec decoding the
//                same decoded points as 24-byte vertices (float position, octahedral normal, RGB,
//                float radius, 3 bytes of zero padding), and its size
//   split rules  midpoint (seed 002) against balanced (seed 000) on the scan and on an uneven
//                density cloud (a dense sphere inside a sparse blob): nodes, depth, leaf fill,
//                bytes per point, CPU seconds
//   rate/error   bytes per point against the colour precision and the position error (as a
//                fraction of the node's smallest splat radius), on the smallest size
//   out of core  with --budgets, the largest cloud again under each budget: peak memory against
//                the budget, time against the in-core conversion, and whether the dataset is the
//                same (it must be)
//   LAZ          with --laz, the first size's cloud again as LAZ (laz_writer.h: LASzip's
//                pointwise chunked format, POINT10 v2 + RGB12 v2) at the grid step our converter
//                used at the leaves (the median over leaves, and the smallest), offsets at the
//                cloud's minimum, colours as 16 bits (v * 257): its bytes per point beside ours
//                (leaves, all levels, and our position + colour streams), its encoding time (one
//                thread), and laz-perf's decoding of the file compared with what was written
//                (scripts/report/laz_decode.mjs; "not checked" when node or laz-perf is missing)
//   normals      the first size's cloud converted without its normals: the estimated normals of
//                the leaves against the surface's (angle between their lines, share flipped)
//
// usage: points_bench [--sizes 1000000,10000000] [--with-normals] [--split balanced|midpoint]
//                     [--node-points 4096] [--keep DIR] [--skip-rate] [--decode-runs 5]
//                     [--budgets 128M,256M] [--laz] [--normals]
//        points_bench --decode-only DATASET [--decode-runs 5]
//        points_bench --compare DATASET DATASET
// (--skip-rate skips the split, rate and normals parts, --normals runs the normals part anyway; sizes like 3e7 work for larger runs; --decode-only
// runs only the decode part on a dataset kept from an earlier run, for quick codec iterations;
// --compare decodes every node of two conversions of the same cloud, say by builds writing
// different node versions, and fails unless every decoded point is bit for bit the same.)
#include <algorithm>
#include <cinttypes>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <sstream>
#include <string>
#include <sys/resource.h>
#include <sys/wait.h>
#include <thread>
#include <tuple>
#include <unordered_map>
#include <unistd.h>
#include <vector>

#include <meshoptimizer.h>

#include "base/atomic_file.h"
#include "base/child_process.h"
#include "base/error.h"
#include "mesh/io.h"
#include "base/options.h"
#include "base/sysinfo.h"
#include "common_codec/archive.h"
#include "mesh/generators.h"
#include "points/builder.h"
#include "points/dataset.h"
#include "points/sampling.h"
#include "common_codec/octahedral.h"
#include "laz_writer.h"

using namespace catpaq;
namespace fs = std::filesystem;

namespace {

PointCloud make_cloud(size_t points, bool with_normals, bool uneven = false) {
    // About 4 surface samples per mesh vertex: the mesh is a smooth carrier, not the sampling.
    // Uneven: a dense sphere inside a sparse blob (mesh/generators.h), as in a scan with one
    // finely detailed region; samples follow the triangles, so the density varies as theirs.
    Mesh mesh = uneven ? make_uneven_density(std::max<size_t>(points / 2, 20000), 7)
                       : make_scan_like(std::max<size_t>(points / 2, 20000), 7);
    if (!uneven) return sample_surface(mesh, points, 11, with_normals, true);
    // Uniform in triangles rather than in area: the sphere's small triangles get as many points.
    PointCloud cloud;
    for (size_t i = 0; i < points; ++i) {
        size_t t = (i * 2654435761u) % mesh.triangle_count();
        const uint32_t* c = &mesh.indices[3 * t];
        double w0 = double((i * 40503u) % 1000) / 1000.0 * 0.5, w1 = double((i * 9973u) % 1000) / 1000.0 * 0.5;
        Vec3d p;
        for (int k = 0; k < 3; ++k)
            p[k] = (1 - w0 - w1) * mesh.positions[c[0]][k] + w0 * mesh.positions[c[1]][k] + w1 * mesh.positions[c[2]][k];
        cloud.positions.push_back(p);
        cloud.colors.push_back(mesh.colors[c[0]]);
    }
    return cloud;
}

struct Conversion {
    double seconds = 0, cpu_seconds = 0, peak_mib = 0, bytes_per_point = 0, points_per_second = 0;
    double stored_bytes_per_point = 0;  // file bytes / points stored in all nodes
    double nodes = 0, depth = 0;
    double baseline_points_per_second = 0;
    double worst_error_to_radius = 0;
    double share[5] = {};  // position, normal, colour, radius, header: fractions of the payload
    double phases[4] = {};  // partition, search tree, nodes, write: seconds
    double min_leaf = 0, mean_leaf = 0;
    double out_of_core = 0, chunks = 0, split_passes = 0;
};

// The child's side: reads the cloud written by the parent, converts it, prints its figures.
int child_convert(const std::string& input, const std::string& output, const PointsBuildSettings& settings) {
    double cpu0 = cpu_seconds();
    PointsBuildReport r = build_points_file(input, output, settings);  // reading included
    Conversion c;
    c.cpu_seconds = cpu_seconds() - cpu0;
    c.seconds = r.seconds;
    c.points_per_second = double(r.input_points) / r.seconds;
    c.bytes_per_point = double(r.file_bytes) / double(r.input_points);
    c.stored_bytes_per_point = double(r.file_bytes) / double(r.stored_points);
    c.nodes = double(r.nodes);
    c.depth = double(r.depth);
    c.worst_error_to_radius = r.worst_error_to_radius;
    double payload = double(r.payload_bytes);
    const double share[5] = {double(r.bytes_position), double(r.bytes_normal), double(r.bytes_color),
                             double(r.bytes_radius), double(r.bytes_header)};
    for (int i = 0; i < 5; ++i) c.share[i] = share[i] / payload;
    const double phases[4] = {r.seconds_partition, r.seconds_search_tree, r.seconds_nodes, r.seconds_write};
    std::copy(phases, phases + 4, c.phases);
    c.min_leaf = double(r.min_leaf_points);
    c.mean_leaf = r.mean_leaf_points;
    c.out_of_core = r.out_of_core;
    c.chunks = double(r.chunks);
    c.split_passes = double(r.split_passes);
    std::printf("RESULT");
    const double* fields = &c.seconds;
    for (size_t i = 0; i < sizeof(Conversion) / sizeof(double); ++i) std::printf(" %.17g", fields[i]);
    std::printf("\n");
    return 0;
}

// Converts in a child process (a fresh one: TBB's thread pool does not survive a fork) so the
// peak memory is the conversion's (with the cloud it reads); the cloud goes through a PLY file.
Conversion convert_in_child(const std::string& self, const std::string& cloud_path, const std::string& output,
                            const PointsBuildSettings& settings) {
    std::vector<std::string> argv = {self, "--child", cloud_path, "--out", output, "--node-points",
                                     std::to_string(settings.node_points), "--split", point_split_rule_name(settings.split),
                                     "--luma", std::to_string(settings.color_bits.luma), "--chroma",
                                     std::to_string(settings.color_bits.chroma), "--error-fraction",
                                     std::to_string(settings.error_fraction)};
    if (settings.memory_budget) argv.insert(argv.end(), {"--memory", std::to_string(settings.memory_budget)});
    ChildRun run = run_measured(argv, output + ".log");
    size_t at = run.output.find("RESULT");
    if (run.status != 0 || at == std::string::npos) fail("the conversion child failed: %s", run.output.c_str());
    Conversion c;
    std::stringstream in(run.output.substr(at + 6));
    double* fields = &c.seconds;
    for (size_t i = 0; i < sizeof(Conversion) / sizeof(double); ++i) in >> fields[i];
    c.peak_mib = double(run.peak_bytes) / (1 << 20);
    return c;
}

std::string write_cloud(const PointCloud& cloud, const fs::path& dir, const std::string& name) {
    Mesh mesh;
    mesh.positions = cloud.positions;
    mesh.normals = cloud.normals;
    mesh.colors = cloud.colors;
    std::string path = (dir / name).string();
    write_ply(path, mesh, true);
    return path;
}

double simplify_points_baseline(const PointCloud& cloud) {
    std::vector<float> xyz(3 * cloud.size());
    for (size_t i = 0; i < cloud.size(); ++i)
        for (int a = 0; a < 3; ++a) xyz[3 * i + a] = float(cloud.positions[i][a]);
    std::vector<unsigned> kept(cloud.size());
    double t = best_of(1, [&] { meshopt_simplifyPoints(kept.data(), xyz.data(), cloud.size(), 12, cloud.size() / 2); });
    return double(cloud.size()) / t;
}

// The largest cloud again under each budget below its in-core peak: out of core, its peak
// against the budget, its time against the in-core conversion's (same run), and whether it
// wrote the same dataset.
void print_out_of_core(const std::string& self, const std::string& cloud_path, const std::string& in_core_dataset,
                       const PointsBuildSettings& settings, const Conversion& in_core, const std::vector<uint64_t>& budgets) {
    std::printf("\n== out of core (the largest cloud; the in-core conversion above: %.2f s, peak %.0f MiB)\n", in_core.seconds,
                in_core.peak_mib);
    std::printf("%10s %8s %8s %10s %9s %11s %7s %7s %11s %5s\n", "budget MiB", "wall s", "cpu s", "Mpt/s", "peak MiB",
                "peak/budget", "chunks", "passes", "time ratio", "same");
    const std::string expected = read_file(in_core_dataset);
    for (uint64_t budget : budgets) {
        PointsBuildSettings s = settings;
        s.memory_budget = budget;
        const std::string output = in_core_dataset + ".budget.cpq";
        const Conversion c = convert_in_child(self, cloud_path, output, s);
        std::printf("%10.0f %8.2f %8.2f %10.3f %9.0f %11.3f %7.0f %7.0f %11.2f %5s\n", double(budget) / (1 << 20), c.seconds,
                    c.cpu_seconds, c.points_per_second / 1e6, c.peak_mib, c.peak_mib * (1 << 20) / double(budget), c.chunks,
                    c.split_passes, c.seconds / in_core.seconds, read_file(output) == expected ? "yes" : "NO");
        std::fflush(stdout);
        fs::remove(output);
    }
}

struct DecodeResult {
    double points_per_second = 0, meshopt_points_per_second = 0;
    double bytes_per_point = 0, meshopt_bytes_per_point = 0;
    size_t points = 0;
};

DecodeResult measure_decode(const std::string& path, int runs) {
    PointDataset dataset(path);
    std::vector<std::vector<uint8_t>> payloads;
    std::vector<std::vector<uint8_t>> meshopt;
    std::vector<size_t> counts;
    DecodeResult result;
    DecodedPoints decoded;
    uint64_t payload_bytes = 0, meshopt_bytes = 0;
    struct Vertex {
        float p[3];
        uint16_t normal;
        uint8_t rgb[3], pad;
        float radius;
    };
    static_assert(sizeof(Vertex) == 24);  // 3 bytes of zero padding, which its codec removes
    for (size_t i = 0; i < dataset.node_count(); ++i) {
        std::string error;
        const uint8_t* bytes = dataset.node_bytes(i, &error);
        if (!bytes) fail("%s", error.c_str());
        payloads.emplace_back(bytes, bytes + dataset.entries()[i].size);
        payload_bytes += payloads.back().size();
        std::string problem = decode_point_node(bytes, payloads.back().size(), decoded);
        if (!problem.empty()) fail("%s", problem.c_str());
        std::vector<Vertex> vertices(decoded.count);
        for (size_t k = 0; k < decoded.count; ++k) {
            Vertex& v = vertices[k];
            std::memcpy(v.p, &decoded.positions[3 * k], 12);
            v.normal = decoded.normals.empty() ? 0 : decoded.normals[k];
            for (int c = 0; c < 3; ++c) v.rgb[c] = decoded.colors.empty() ? 0 : decoded.colors[3 * k + c];
            v.pad = 0;
            v.radius = decoded.radii[k];
        }
        std::vector<uint8_t> encoded(meshopt_encodeVertexBufferBound(decoded.count, sizeof(Vertex)));
        encoded.resize(meshopt_encodeVertexBuffer(encoded.data(), encoded.size(), vertices.data(), decoded.count, sizeof(Vertex)));
        meshopt_bytes += encoded.size();
        meshopt.push_back(std::move(encoded));
        counts.push_back(decoded.count);
        result.points += decoded.count;
    }
    double ours = best_of(runs, [&] {
        for (const std::vector<uint8_t>& p : payloads)
            if (!decode_point_node(p.data(), p.size(), decoded).empty()) fail("decode failed");
    }, thread_cpu_seconds);
    std::vector<Vertex> vertices;
    double theirs = best_of(runs, [&] {
        for (size_t i = 0; i < meshopt.size(); ++i) {
            vertices.resize(counts[i]);
            if (meshopt_decodeVertexBuffer(vertices.data(), counts[i], sizeof(Vertex), meshopt[i].data(), meshopt[i].size()) != 0)
                fail("meshopt decode failed");
        }
    }, thread_cpu_seconds);
    result.points_per_second = double(result.points) / ours;
    result.meshopt_points_per_second = double(result.points) / theirs;
    result.bytes_per_point = double(payload_bytes) / double(result.points);
    result.meshopt_bytes_per_point = double(meshopt_bytes) / double(result.points);
    return result;
}

void print_decode(const std::string& dataset, int runs) {
    std::printf("\n== decode, one thread (%s)\n", dataset.c_str());
    DecodeResult d = measure_decode(dataset, runs);
    std::printf("ours:      %8.1f M points/s  %6.3f B/point\n", d.points_per_second / 1e6, d.bytes_per_point);
    std::printf("meshopt:   %8.1f M points/s  %6.3f B/point (vertex codec on the same decoded points)\n",
                d.meshopt_points_per_second / 1e6, d.meshopt_bytes_per_point);
    std::printf("ratio:     %8.2f x speed     %6.3f x size\n", d.points_per_second / d.meshopt_points_per_second,
                d.bytes_per_point / d.meshopt_bytes_per_point);
    std::fflush(stdout);
}

// Every node of two datasets decoded and compared attribute by attribute, bit for bit.
int compare_decoded(const std::string& first, const std::string& second) {
    PointDataset a(first), b(second);
    if (a.node_count() != b.node_count()) fail("%zu nodes against %zu", a.node_count(), b.node_count());
    DecodedPoints da, db;
    size_t points = 0, bytes_a = 0, bytes_b = 0;
    for (size_t i = 0; i < a.node_count(); ++i) {
        std::string error;
        const uint8_t* pa = a.node_bytes(i, &error);
        const uint8_t* pb = pa ? b.node_bytes(i, &error) : nullptr;
        if (!pa || !pb) fail("%s", error.c_str());
        bytes_a += a.entries()[i].size;
        bytes_b += b.entries()[i].size;
        for (auto [bytes, size, out] : {std::tuple{pa, a.entries()[i].size, &da}, std::tuple{pb, b.entries()[i].size, &db}}) {
            std::string problem = decode_point_node(bytes, size, *out);
            if (!problem.empty()) fail("node %zu: %s", i, problem.c_str());
        }
        if (a.entries()[i].key != b.entries()[i].key || da.count != db.count || da.flags != db.flags ||
            da.positions != db.positions || da.normals != db.normals || da.colors != db.colors || da.radii != db.radii ||
            da.position_error != db.position_error || da.grid_step != db.grid_step)
            fail("node %zu (key %" PRIu64 ") decodes differently", i, a.entries()[i].key);
        points += da.count;
    }
    std::printf("identical: %zu nodes, %zu points; payload %.3f against %.3f bytes per point\n", a.node_count(), points,
                double(bytes_a) / double(points), double(bytes_b) / double(points));
    return 0;
}

// The grid steps of the leaves (the nodes that hold the input points, quantized once) and what
// the dataset's nodes weigh: leaves alone and all levels.
struct LeafQuantization {
    double median_step = 0, smallest_step = 0, largest_step = 0;
    size_t leaves = 0, leaf_points = 0, stored_points = 0;
    uint64_t leaf_bytes = 0, payload_bytes = 0;
};

LeafQuantization leaf_quantization(const std::string& path) {
    PointDataset dataset(path);
    LeafQuantization q;
    std::vector<double> steps;
    DecodedPoints decoded;
    for (size_t i = 0; i < dataset.node_count(); ++i) {
        std::string problem = dataset.decode(i, decoded);
        if (!problem.empty()) fail("%s", problem.c_str());
        const uint64_t key = dataset.entries()[i].key, bytes = dataset.entries()[i].size;
        q.payload_bytes += bytes;
        q.stored_points += decoded.count;
        if (dataset.find(point_node_child(key, 0)) >= 0) continue;  // an inner node
        steps.push_back(decoded.grid_step);
        q.leaf_points += decoded.count;
        q.leaf_bytes += bytes;
    }
    if (steps.empty()) fail("'%s' has no leaves", path.c_str());
    std::sort(steps.begin(), steps.end());
    q.leaves = steps.size();
    q.median_step = steps[steps.size() / 2];
    q.smallest_step = steps.front();
    q.largest_step = steps.back();
    return q;
}

// The normals the converter estimated at the leaves against the surface's own: the same cloud
// is converted without its normals, each leaf point matched to the input point nearest to it
// (the leaves quantize the input points within a quarter of a splat radius, far below their
// spacing), and their normals compared: the angle between the two lines (sign aside: what PCA
// estimates), and the share pointing the other way (the orientation's failures: the surface is
// closed and its normals point out).
void print_normal_quality(const std::string& self, size_t points, const fs::path& dir, const PointsBuildSettings& settings) {
    PointCloud cloud = make_cloud(points, true);
    const std::vector<Vec3d> truth_positions = cloud.positions;
    const std::vector<Vec3f> truth_normals = cloud.normals;
    cloud.normals.clear();
    const std::string cloud_path = write_cloud(cloud, dir, "normals.ply");
    cloud = PointCloud();
    const std::string output = (dir / "normals.cpq").string();
    const Conversion c = convert_in_child(self, cloud_path, output, settings);
    PointDataset dataset(output);
    const LeafQuantization q = leaf_quantization(output);
    // The input points in a hash grid of cells four leaf steps wide: a leaf point's original is
    // within a step of it, so in its cell or a neighbour's.
    const double h = 4 * q.largest_step;
    auto cell_key = [h](const double p[3]) {
        uint64_t key = 0;
        for (int a = 0; a < 3; ++a) key = key * 0x9E3779B97F4A7C15ull + uint64_t(int64_t(std::floor(p[a] / h)));
        return key;
    };
    std::unordered_multimap<uint64_t, uint32_t> grid;
    grid.reserve(truth_positions.size());
    for (size_t i = 0; i < truth_positions.size(); ++i) grid.emplace(cell_key(truth_positions[i].data()), uint32_t(i));
    const double* origin = dataset.meta().origin;
    DecodedPoints decoded;
    double angle_sum = 0;
    std::vector<double> angles;
    size_t flipped = 0, matched = 0;
    for (size_t i = 0; i < dataset.node_count(); ++i) {
        const uint64_t key = dataset.entries()[i].key;
        if (dataset.find(point_node_child(key, 0)) >= 0) continue;  // an inner node
        std::string problem = dataset.decode(i, decoded);
        if (!problem.empty()) fail("%s", problem.c_str());
        for (size_t k = 0; k < decoded.count; ++k) {
            double p[3];
            for (int a = 0; a < 3; ++a) p[a] = origin[a] + double(decoded.positions[3 * k + a]);
            double best = INFINITY;
            uint32_t nearest = UINT32_MAX;
            for (int dx = -1; dx <= 1; ++dx)
                for (int dy = -1; dy <= 1; ++dy)
                    for (int dz = -1; dz <= 1; ++dz) {
                        const double cell[3] = {p[0] + dx * h, p[1] + dy * h, p[2] + dz * h};
                        auto range = grid.equal_range(cell_key(cell));
                        for (auto it = range.first; it != range.second; ++it) {
                            const Vec3d& t = truth_positions[it->second];
                            const double d2 = (t[0] - p[0]) * (t[0] - p[0]) + (t[1] - p[1]) * (t[1] - p[1]) +
                                              (t[2] - p[2]) * (t[2] - p[2]);
                            if (d2 < best) best = d2, nearest = it->second;
                        }
                    }
            if (nearest == UINT32_MAX) continue;
            float n[3];
            oct_decode(decoded.normals[k], n);
            const Vec3f& t = truth_normals[nearest];
            const double dot = double(n[0]) * t[0] + double(n[1]) * t[1] + double(n[2]) * t[2];
            const double angle = std::acos(std::min(std::fabs(dot), 1.0)) * 180.0 / M_PI;
            angles.push_back(angle);
            angle_sum += angle;
            flipped += dot < 0;
            ++matched;
        }
    }
    if (matched == 0) fail("no leaf point of '%s' matched an input point", output.c_str());
    std::sort(angles.begin(), angles.end());
    std::printf("\n== estimated normals against the surface's (%zu points, %zu leaf points matched)\n", points, matched);
    std::printf("%12s %12s %12s %12s %8s\n", "mean deg", "median deg", "p95 deg", "flipped %", "cpu s");
    std::printf("%12.3f %12.3f %12.3f %12.3f %8.2f\n", angle_sum / double(matched), angles[angles.size() / 2],
                angles[angles.size() * 95 / 100], 100.0 * double(flipped) / double(matched), c.cpu_seconds);
}

// The bits of v (21 of them) spread to every third bit of a 64-bit Morton code.
uint64_t spread_bits(uint64_t v) {
    v &= 0x1FFFFF;
    v = (v | (v << 32)) & 0x1F00000000FFFFull;
    v = (v | (v << 16)) & 0x1F0000FF0000FFull;
    v = (v | (v << 8)) & 0x100F00F00F00F00Full;
    v = (v | (v << 4)) & 0x10C30C30C30C30C3ull;
    v = (v | (v << 2)) & 0x1249249249249249ull;
    return v;
}

// The records along a Morton curve of their integers (the top 21 bits of each axis): a spatially
// coherent order. LAZ predicts each point from the one before, so its size depends on the order
// of the file; the benchmark's samples come in random order, a scanner's in acquisition order,
// which is coherent, and our converter sorts each node along a Morton curve of its own.
std::vector<laz::LasPoint> morton_ordered(const std::vector<laz::LasPoint>& records) {
    int32_t low[3] = {INT32_MAX, INT32_MAX, INT32_MAX}, high[3] = {INT32_MIN, INT32_MIN, INT32_MIN};
    for (const laz::LasPoint& p : records) {
        const int32_t v[3] = {p.x, p.y, p.z};
        for (int a = 0; a < 3; ++a) low[a] = std::min(low[a], v[a]), high[a] = std::max(high[a], v[a]);
    }
    int bits = 0;
    for (int a = 0; a < 3; ++a)
        while (bits < 32 && (uint64_t(int64_t(high[a]) - low[a]) >> bits) != 0) ++bits;
    const int shift = std::max(0, bits - 21);
    std::vector<std::pair<uint64_t, uint32_t>> keys(records.size());
    for (size_t i = 0; i < records.size(); ++i) {
        const laz::LasPoint& p = records[i];
        const int32_t v[3] = {p.x, p.y, p.z};
        uint64_t code = 0;
        for (int a = 0; a < 3; ++a) code |= spread_bits(uint64_t(int64_t(v[a]) - low[a]) >> shift) << a;
        keys[i] = {code, uint32_t(i)};
    }
    std::sort(keys.begin(), keys.end());
    std::vector<laz::LasPoint> ordered(records.size());
    for (size_t i = 0; i < keys.size(); ++i) ordered[i] = records[keys[i].second];
    return ordered;
}

// LAZ beside ours on the first size's cloud (made again: same arguments, same points), at the
// leaves' median grid step and at their smallest. LAZ holds positions and colours (and POINT10's
// other fields, constant here, which cost next to nothing); ours also hold normals and radii, so
// the position + colour part of our payload is given beside the whole.
void print_laz_comparison(size_t points, bool with_normals, const std::string& dataset, const Conversion& ours,
                          const fs::path& dir) {
    std::printf("\n== LAZ at our quantization (%zu points, the first cloud again; LASzip pointwise chunked, POINT10 v2 + "
                "RGB12 v2, chunks of %u; colours as v * 257; offsets at the cloud's minimum)\n",
                points, laz::kDefaultChunkPoints);
    const LeafQuantization q = leaf_quantization(dataset);
    std::printf("leaf grid step: median %.6g, smallest %.6g, largest %.6g (%zu leaves, %zu points)\n", q.median_step,
                q.smallest_step, q.largest_step, q.leaves, q.leaf_points);
    const double position_color_share = ours.share[0] + ours.share[2];
    std::printf("ours, leaves: %.3f B/point (position, normal, colour, radius, node header)\n",
                double(q.leaf_bytes) / double(q.leaf_points));
    std::printf("ours, all levels: %.3f B/stored point, %.3f B/input point; position+colour %.3f B/stored point, "
                "%.3f B/input point\n",
                ours.stored_bytes_per_point, ours.bytes_per_point,
                position_color_share * double(q.payload_bytes) / double(q.stored_points),
                position_color_share * double(q.payload_bytes) / double(points));
    std::printf("ours, payload split (all levels): position %.1f%%, normal %.1f%%, colour %.1f%%, radius %.1f%%, header "
                "%.1f%%\n",
                100 * ours.share[0], 100 * ours.share[1], 100 * ours.share[2], 100 * ours.share[3], 100 * ours.share[4]);
    std::printf("ours, leaves, position+colour: about %.3f B/point (the all-level split applied to the leaves)\n",
                position_color_share * double(q.leaf_bytes) / double(q.leaf_points));
    std::fflush(stdout);

    const PointCloud cloud = make_cloud(points, with_normals);
    const Bounds bounds = cloud.bounds();
    std::string decoder_problem;
    laz::LazPerfDecoder decoder;
    try {
        decoder = laz::find_lazperf_decoder(CATPAQ_SOURCE_DIR);
    } catch (const Error& e) {
        decoder_problem = e.what();
    }
    std::printf("%-14s %-7s %12s %10s %16s %10s  %s\n", "LAZ step", "order", "scale", "B/point", "point data B/pt",
                "encode s", "laz-perf");
    struct Row {
        const char* name;
        double step;
        bool morton;
    };
    const Row rows[] = {{"median leaf", q.median_step, false}, {"median leaf", q.median_step, true},
                        {"smallest leaf", q.smallest_step, false}, {"smallest leaf", q.smallest_step, true}};
    for (const auto& [name, step, morton] : rows) {
        laz::LasLayout layout;
        for (int a = 0; a < 3; ++a) {
            layout.scale[a] = step;
            layout.offset[a] = bounds.min[a];
        }
        std::vector<laz::LasPoint> records = laz::quantize_points(cloud.positions, cloud.colors, layout);
        if (morton) records = morton_ordered(records);
        std::string bytes;
        const double seconds = best_of(1, [&] { bytes = laz::encode_laz(records, layout); });
        const std::string path = (dir / "scan.laz").string();
        write_file_atomic(path, bytes.data(), bytes.size());
        uint32_t point_data_offset = 0;  // the header's offset to the point data (u32 at byte 96)
        std::memcpy(&point_data_offset, bytes.data() + 96, 4);
        const uint64_t point_data = bytes.size() - point_data_offset;
        std::string check = "not checked (" + decoder_problem + ")";
        if (decoder_problem.empty()) {
            std::string expected;
            expected.reserve(records.size() * laz::las_record_length(true));
            for (const laz::LasPoint& p : records) laz::append_las_record(p, true, expected);
            const laz::DecodedLas decoded = laz::decode_with_lazperf(decoder, path, (dir / "scan.records").string());
            if (decoded.points != records.size() || decoded.records != expected)
                fail("laz-perf decodes the LAZ of step %g to other points than were written", step);
            check = "identical";
        }
        std::printf("%-14s %-7s %12.6g %10.3f %16.3f %10.3f  %s\n", name, morton ? "Morton" : "input", step,
                    double(bytes.size()) / double(records.size()), double(point_data) / double(records.size()), seconds,
                    check.c_str());
        std::fflush(stdout);
        fs::remove(path);
    }
}

std::vector<size_t> parse_sizes(const std::string& text) {
    std::vector<size_t> sizes;
    std::stringstream in(text);
    std::string item;
    while (std::getline(in, item, ',')) sizes.push_back(size_t(std::stod(item)));
    return sizes;
}

}  // namespace

int main(int argc, char** argv) {
    try {
        Options options(argc, argv,
                        "usage: points_bench [--sizes 1000000,10000000] [--with-normals] [--split balanced|midpoint]\n"
                        "                    [--node-points 4096] [--keep DIR] [--skip-rate] [--decode-runs 5]\n"
                        "                    [--budgets 128M,256M] [--laz] [--normals]\n"
                        "       points_bench --decode-only DATASET [--decode-runs 5]\n"
                        "       points_bench --compare DATASET DATASET\n",
                        {"with-normals", "skip-rate", "laz", "normals"});
        if (options.help()) {
            std::printf("%s", options.usage().c_str());
            return 0;
        }
        if (options.has("child")) {  // internal: one conversion in a fresh process
            PointsBuildSettings settings;
            settings.progress = false;
            std::string input = options.require("child"), output = options.require("out");
            settings.node_points = size_t(options.integer("node-points", 4096, 16, 1 << 20));
            settings.split = options.get("split", "balanced") == "balanced" ? PointSplitRule::Balanced : PointSplitRule::Midpoint;
            settings.color_bits.luma = uint8_t(options.integer("luma", 8, 1, 8));
            settings.color_bits.chroma = uint8_t(options.integer("chroma", 9, 1, 9));
            settings.error_fraction = options.number("error-fraction", 0.25, 1e-3, 1.0);
            settings.memory_budget = options.bytes("memory", 0);
            options.finish();
            return child_convert(input, output, settings);
        }
        const std::string self = fs::canonical("/proc/self/exe").string();
        std::vector<size_t> sizes = parse_sizes(options.get("sizes", "1000000,10000000"));
        const bool with_normals = options.flag("with-normals");
        const bool skip_rate = options.flag("skip-rate");
        const bool laz_comparison = options.flag("laz");
        const bool normal_quality = options.flag("normals");
        std::vector<uint64_t> budgets;
        {
            std::stringstream list(options.get("budgets", ""));
            for (std::string b; std::getline(list, b, ',');) budgets.push_back(parse_size(b, "--budgets"));
        }
        PointsBuildSettings settings;
        settings.progress = false;
        settings.node_points = size_t(options.integer("node-points", 4096, 16, 1 << 20));
        std::string split = options.get("split", "balanced");
        if (split == "balanced") settings.split = PointSplitRule::Balanced;
        else if (split != "midpoint") usage_error("--split: midpoint or balanced");
        const int runs = int(options.integer("decode-runs", 5, 1, 100));
        std::string keep = options.get("keep", "");
        const std::string decode_only = options.get("decode-only", "");
        const std::string compare = options.get("compare", "");
        std::vector<std::string> rest = options.positional();
        options.finish();
        if (!compare.empty()) {
            if (rest.size() != 1) usage_error("--compare takes two datasets");
            return compare_decoded(compare, rest[0]);
        }
        if (!decode_only.empty()) {
            print_decode(decode_only, runs);
            return 0;
        }
        fs::path dir = keep.empty() ? fs::temp_directory_path() / ("points_bench_" + std::to_string(getpid())) : fs::path(keep);
        fs::create_directories(dir);

        std::printf("points_bench on %s, %u threads; clouds: random samples of the scan-like surface with colours, normals %s\n",
                    cpu_model().c_str(), std::thread::hardware_concurrency(), with_normals ? "given" : "estimated");
        std::printf("\n== conversion (%s split, %zu points per node)\n", point_split_rule_name(settings.split), settings.node_points);
        std::printf("%10s %8s %8s %10s %9s %7s %6s %9s %9s %10s %8s  %s\n", "points", "wall s", "cpu s", "Mpt/s", "peak MiB",
                    "B/pt", "nodes", "B/stored", "err/r", "simpl Mpt/s", "ratio", "payload: pos/nrm/col/rad/hdr");
        std::string last_dataset;
        Conversion first_conversion;
        for (size_t n : sizes) {
            PointCloud cloud = make_cloud(n, with_normals);
            double baseline = simplify_points_baseline(cloud);
            std::string cloud_path = write_cloud(cloud, dir, "scan_" + std::to_string(n) + ".ply");
            PointCloud().positions.swap(cloud.positions);
            std::string output = (dir / ("scan_" + std::to_string(n) + ".cpq")).string();
            Conversion c = convert_in_child(self, cloud_path, output, settings);
            std::printf("%10zu %8.2f %8.2f %10.3f %9.0f %7.3f %6.0f %9.3f %9.3f %10.3f %8.2f  %.0f%%/%.0f%%/%.0f%%/%.0f%%/%.0f%%\n", n,
                        c.seconds, c.cpu_seconds, c.points_per_second / 1e6, c.peak_mib, c.bytes_per_point, c.nodes,
                        c.stored_bytes_per_point, c.worst_error_to_radius, baseline / 1e6, c.points_per_second / baseline,
                        100 * c.share[0], 100 * c.share[1], 100 * c.share[2], 100 * c.share[3], 100 * c.share[4]);
            std::printf("%10s phases (wall s): partition %.2f, search tree %.2f, nodes %.2f, write %.2f\n", "", c.phases[0],
                        c.phases[1], c.phases[2], c.phases[3]);
            {
                // What a client needs before it draws the whole cloud (the mission: at most 64 KiB).
                ArchiveReader reader(output);
                const FirstFrame first = archive_first_frame(reader.header(), reader.entries());
                std::printf("%10s first frame: %" PRIu64 " bytes (prefix %" PRIu64 ", level 0 %" PRIu64 ")\n", "",
                            first.bytes(), first.prefix_bytes, first.level0_bytes);
            }
            std::fflush(stdout);
            if (last_dataset.empty()) {
                last_dataset = output;
                first_conversion = c;
            }
            if (n == sizes.back() && !budgets.empty()) print_out_of_core(self, cloud_path, output, settings, c, budgets);
        }

        print_decode(last_dataset, runs);
        if (laz_comparison) print_laz_comparison(sizes.front(), with_normals, last_dataset, first_conversion, dir);

        if (!skip_rate || normal_quality) print_normal_quality(self, sizes.front(), dir, settings);
        if (!skip_rate) {
            std::printf("\n== split rules (%zu points; CPU s of the whole conversion)\n", sizes.front());
            std::printf("%-9s %-9s %6s %6s %9s %9s %8s %8s\n", "cloud", "split", "nodes", "depth", "min leaf", "mean leaf",
                        "B/pt", "cpu s");
            for (bool uneven : {false, true}) {
                std::string cloud_path = write_cloud(make_cloud(sizes.front(), with_normals, uneven), dir, "split.ply");
                for (PointSplitRule rule : {PointSplitRule::Midpoint, PointSplitRule::Balanced}) {
                    PointsBuildSettings s = settings;
                    s.split = rule;
                    Conversion c = convert_in_child(self, cloud_path, (dir / "split.cpq").string(), s);
                    std::printf("%-9s %-9s %6.0f %6.0f %9.0f %9.0f %8.3f %8.2f\n", uneven ? "uneven" : "scan",
                                point_split_rule_name(rule), c.nodes, c.depth, c.min_leaf, c.mean_leaf, c.bytes_per_point,
                                c.cpu_seconds);
                }
            }
            std::printf("\n== bytes per point against error (%zu points)\n", sizes.front());
            std::string cloud_path = write_cloud(make_cloud(sizes.front(), with_normals), dir, "rate.ply");
            std::printf("%-14s %-12s %8s %10s %9s\n", "colour bits", "error/radius", "B/pt", "B/stored", "err/r");
            struct Variant {
                ColorBits bits;
                double fraction;
            };
            const Variant variants[] = {{{8, 9}, 0.25}, {{6, 7}, 0.25}, {{5, 6}, 0.25}, {{8, 9}, 0.5},
                                        {{8, 9}, 0.125}, {{5, 6}, 0.5}};
            for (const Variant& v : variants) {
                PointsBuildSettings s = settings;
                s.color_bits = v.bits;
                s.error_fraction = v.fraction;
                Conversion c = convert_in_child(self, cloud_path, (dir / "rate.cpq").string(), s);
                std::printf("%2u/%-11u %-12.3f %8.3f %10.3f %9.3f\n", v.bits.luma, v.bits.chroma, v.fraction,
                            c.bytes_per_point, c.stored_bytes_per_point, c.worst_error_to_radius);
            }
        }
        if (keep.empty()) fs::remove_all(dir);
        return 0;
    } catch (const UsageError& e) {
        std::fprintf(stderr, "points_bench: %s\n", e.what());
        return 2;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "points_bench: %s\n", e.what());
        return 1;
    }
}
