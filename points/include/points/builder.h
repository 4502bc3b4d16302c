#pragma once
// The point converter: a point cloud in, a point dataset (points/format.h) out.
//
// 1. The cloud is moved to a local origin (the centre of its bounds, in double precision).
// 2. Partition: a binary kd-tree over the points, split until a node holds at most node_points
//    (seed 000's most balanced plane under an aspect bound, by default; or seed 002's middle of
//    the longest side of the node's tight box). Leaves hold the input points.
// 3. Leaves: points without normals get them by PCA over their k nearest neighbours, oriented
//    consistently within the leaf (orientation propagated along the neighbour graph, strongest
//    agreement first, as Hoppe et al. 1992 do globally) and, per connected piece, towards the
//    outside (away from the cloud's centre) or up (+z, LAS), by majority vote. Points without radii
//    get the distance to their 6th nearest neighbour (radius_neighbour): discs that wide cover a
//    uniformly random sample of a surface but for 2e-4 of its area, so the client draws splats
//    at their stored radius.
// 4. Inner nodes, bottom up (the two halves in parallel): the two children's decoded splats are
//    merged by proximity down to half their number, at most node_points (points/src/splat.h), so
//    quantization at a child is seen by its parent.
// 5. Every node is encoded (points/codec.h) and written to the archive as soon as it is built;
//    the archive appears atomically when complete.
//
// Error bound of a node: the largest distance from an input point it stands for to its splat's
// centre, tracked through every merge and quantization (leaves: the quantization error), and at
// least its children's bounds (monotone). Splat radii cover the children's splats.
//
// Neighbours (step 3 and 4) come from small uniform grids (points/src/grid_knn.h): a leaf's
// over the leaf and the points around it (found through the hierarchy's node boxes, widened
// per point until the neighbours are exact), a node's over its children's splats.
//
// Memory: in core, about 60 bytes per input point at the peak (10M points: 590 MiB, reading
// included: the points in double precision with normals, colours and radii, the partition's
// items, a float copy for the neighbour searches), plus node_points splats per level of the tree
// per thread. A cloud whose estimate exceeds the memory budget is converted out of core
// (points/src/out_of_core.h): read into scratch files, the top of the tree decided by passes
// over them, the rest built one chunk (a subtree that fits the budget) at a time. The dataset
// is byte-identical either way.
#include <cstdint>
#include <string>
#include <vector>

#include "points/codec.h"
#include "points/format.h"
#include "points/point_cloud.h"

namespace catpaq {

enum class NormalOrientation : uint8_t {
    Auto,     // Up for inputs whose convention is z up (LAS), else Outward
    Outward,  // away from the centre of the cloud's bounds (closed, star-shaped objects)
    Up,       // towards +z (terrain, aerial scans)
};

struct PointsBuildSettings {
    size_t node_points = 4096;  // the most points in a node (seed 002: "a few thousand")
    // Balanced by default: on the 1M scan it makes 513 nodes against 721 (depth 9 against 10)
    // with no leaf under 1597 points (midpoint: 849) and 0.5% fewer bytes; on an uneven density
    // cloud midpoint leaves go down to 4 points (balanced: 538). Its CPU cost was within 5-10%
    // (bench/points/points_bench, split rules).
    PointSplitRule split = PointSplitRule::Balanced;
    double max_aspect = 4.0;    // Balanced: a child's side across the plane is at least 1/max_aspect of the longest side
    size_t neighbours = 16;     // k of the normal estimate (PCA)
    // A radius reaches this nearest neighbour (the point itself not counted). On uniformly random
    // samples of a plane, discs so wide leave uncovered 4e-3 of it at 4, 2.2e-4 at 6, 1.5e-5 at 8;
    // the mean radius is 1.10, 1.36, 1.57 spacings (estimate.cpp).
    size_t radius_neighbour = 6;
    NormalOrientation orientation = NormalOrientation::Auto;
    ColorBits color_bits;       // default: lossless 8-bit RGB
    double error_fraction = 0.25;  // position error / the node's smallest splat radius (0, 1]
    // The up axis stored for viewers (catp/format.h's UpAxis numbering, 1-6 = +x +y +z -x -y
    // -z); 0: the input's convention (+z for LAS, else unknown).
    uint8_t up_axis = 0;
    unsigned threads = 0;       // 0: all cores
    bool progress = true;       // progress display on a terminal
    // Memory budget (bytes, 0: none). A cloud whose in-core estimate (points_memory_estimate)
    // exceeds it is converted out of core, in chunks sized from the budget.
    uint64_t memory_budget = 0;
    // Out of core with chunks of at most this many points (at least 4 node sizes), whatever the
    // budget (which then only sizes the split passes' histograms); 0: chosen as above. The
    // dataset is the same either way, and for every chunk size.
    size_t chunk_points = 0;
};

// Out of core, the bytes a chunk's point takes at the peak (its data read, its partition's items
// and permutation, its arrays in partition order while its nodes are built, the halo around it).
constexpr uint64_t kOutOfCorePointBytes = 160;
// The widest and narrowest clouds (the longest side of their box, input units) the converter
// takes: it measures distances in single precision, whose squares must stay normal floats; the
// radius floor (a millionth of the diagonal) sets the lower end. Others are refused.
constexpr double kPointMaxExtent = 1e18;
constexpr double kPointMinExtent = 1e-12;
// The smallest budget the converter works out of core with (clouds whose in-core estimate
// exceeds a smaller budget are refused).
constexpr uint64_t kPointsMinimumBudget = uint64_t(48) << 20;

// Peak memory of build_points on `points` input points, reading included: 62 bytes a point and
// 24 MiB (measured peaks, points_bench: 79 MiB at 1M points, 590 MiB at 10M, 5719 MiB at 100M;
// RESULTS section 7).
inline uint64_t points_memory_estimate(size_t points) { return uint64_t(points) * 62 + (uint64_t(24) << 20); }

struct PointsLevelStats {
    int depth = 0;
    size_t nodes = 0, points = 0;
    uint64_t bytes = 0;
    double max_error = 0;       // world units
    double mean_radius = 0;
};

struct PointsBuildReport {
    size_t input_points = 0;
    uint64_t memory_estimate = 0;  // points_memory_estimate(input_points)
    size_t nodes = 0, leaves = 0;
    int depth = 0;                         // of the deepest leaf
    size_t min_leaf_points = 0, max_leaf_points = 0;
    double mean_leaf_points = 0;
    uint64_t file_bytes = 0, payload_bytes = 0;
    uint64_t bytes_position = 0, bytes_normal = 0, bytes_color = 0, bytes_radius = 0, bytes_header = 0;
    uint64_t stored_points = 0;            // in all nodes
    bool normals_estimated = false, radii_estimated = false, has_colors = false;
    // Largest position error of a node divided by that node's smallest splat radius (the codec
    // keeps it at most settings.error_fraction).
    double worst_error_to_radius = 0;
    // seconds_search_tree: what the neighbour searches need beforehand (the float copy, node boxes).
    // seconds: the whole conversion, reading included when the converter reads (build_points_stream).
    double seconds = 0, seconds_read = 0, seconds_partition = 0, seconds_search_tree = 0, seconds_nodes = 0, seconds_write = 0;
    uint64_t peak_rss = 0;
    bool out_of_core = false;
    size_t chunks = 0;        // out of core: the parts partitioned and built one at a time
    size_t split_passes = 0;  // out of core: passes over the input that decided the splits above them
    std::vector<PointsLevelStats> levels;  // by depth, root first
    std::vector<std::string> dropped_input;
};

// Converts `cloud` (validated here: Error if it is not) into a dataset at `output_path` (checked
// first: Error naming it if it is a directory or its directory is missing or not writable).
// `z_up`: the input's convention is z up (for NormalOrientation::Auto and the meta's up axis).
// Refuses with Error: clouds whose points all coincide when they carry no radii (no splat size
// can be estimated), and more than 2^32 points.
PointsBuildReport build_points(PointCloud cloud, const std::string& output_path, const PointsBuildSettings& settings,
                               bool z_up = false);

// Converts what `reader` reads (points/point_cloud.h), batch by batch: in core while the points
// fit the memory budget (settings.memory_budget, against points_memory_estimate), else out of
// core, so that a cloud of any size converts within the budget. The report's dropped_input is
// the reader's.
PointsBuildReport build_points_stream(PointFileReader& reader, const std::string& output_path,
                                      const PointsBuildSettings& settings);

// Reads a point file (points/point_cloud.h) and converts it (build_points_stream).
PointsBuildReport build_points_file(const std::string& input_path, const std::string& output_path,
                                    const PointsBuildSettings& settings);

}  // namespace catpaq
