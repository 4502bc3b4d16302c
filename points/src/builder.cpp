// The point converter (points/builder.h): partition, leaf estimates, bottom-up merging, encoding.
#include "points/builder.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cassert>
#include <cmath>
#include <cstring>
#include <memory>
#include <mutex>

#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_reduce.h>

#include "base/default_init.h"
#include "base/error.h"
#include "base/output_path.h"
#include "base/progress.h"
#include "base/sysinfo.h"
#include "common_codec/archive.h"
#include "common_codec/octahedral.h"
#include "estimate.h"
#include "kdtree.h"
#include "out_of_core.h"
#include "partition.h"
#include "splat.h"

namespace catpaq {

using namespace points_detail;

namespace {

// What the builder records per hierarchy node for the metadata and the report.
struct NodeRecord {
    float box_min[3], box_max[3];
    float error = 0;
    float mean_radius = 0;
    uint32_t count = 0;
    uint64_t bytes = 0;
    double error_to_radius = 0;
    PointEncodeStats stats;
};

// A parent keeps half its children's splats, up to node_points: every level then halves the
// density (the error grows steadily level by level), also above leaves the midpoint rule left
// partly filled, whose parent would otherwise keep nearly all of them.
size_t parent_points_for(size_t children_points, size_t node_points) {
    return std::min(node_points, (children_points + 1) / 2);
}

float round_up(double v) {
    float f = float(v);
    return double(f) < v ? std::nextafter(f, INFINITY) : f;
}

PartitionSettings partition_settings_of(const PointsBuildSettings& settings) {
    PartitionSettings partition;
    partition.node_points = settings.node_points;
    partition.split = settings.split;
    partition.max_aspect = settings.max_aspect;
    return partition;
}

class Builder {
public:
    Builder(const PointsBuildSettings& settings, bool z_up, Progress* progress)
        : settings_(settings), z_up_(z_up), progress_(progress) {}

    // In core: `cloud` is moved to the origin and permuted into partition order.
    PointsBuildReport run_in_core(PointCloud& cloud, const std::string& output_path);
    // Out of core: `store` holds the input read so far.
    PointsBuildReport run_out_of_core(OutOfCorePoints& store, const std::string& output_path);

private:
    void prepare(const PointInputSummary& input, PointsBuildReport& report);
    void partition_in_core(PointCloud& cloud);
    void node_boxes(bool leaves);
    PointsBuildReport finish(PointsBuildReport& report, double start);
    void halo(const float lo[3], const float hi[3], size_t begin, size_t end, std::vector<uint32_t>& ids) const;
    size_t nearest_all(const float q[3], size_t k, uint32_t* index, float* distance2) const;
    PointsMeta make_meta(const PointsBuildReport& report) const;
    std::vector<size_t> index_order() const;
    void summarize(PointsBuildReport& report) const;

    std::vector<Splat> build_node(size_t index);
    std::vector<Splat> build_top(size_t index, OutOfCorePoints& store);
    std::vector<Splat> merge_children(size_t index, std::vector<Splat> left, std::vector<Splat> right);
    size_t parent_points(size_t children_points) const { return parent_points_for(children_points, settings_.node_points); }
    std::vector<Splat> leaf_splats(const HNode& node);
    std::vector<Splat> finish_node(size_t index, std::vector<Splat> splats, float children_error,
                                   const float* children_box_min, const float* children_box_max);

    const PointsBuildSettings& settings_;
    bool z_up_;
    Progress* progress_;
    double origin_[3] = {0, 0, 0};
    Bounds bounds_;
    double radius_floor_ = 0;  // no splat is smaller (a tiny fraction of the model's size)
    bool estimate_normals_ = false, estimate_radii_ = false;
    std::vector<HNode> nodes_;
    std::vector<NodeRecord> records_;
    // In core: the points in partition order (the cloud's attributes permuted, or estimated),
    // and as floats, 3 each, for the neighbour searches.
    UninitializedVector<Vec3d> positions_;
    UninitializedVector<Vec3f> normals_;
    UninitializedVector<Rgb8> colors_;
    UninitializedVector<float> radii_, xyz_;
    PointArrays arrays_;      // the points in partition order (in core: the arrays above)
    float cloud_extent_ = 0;
    std::unique_ptr<ArchiveWriter> writer_;
    // Out of core: the store whose mapped pages are dropped once resident memory passes
    // release_above_ (a chunk's leaves read their neighbours' pages too, and what is mapped stays
    // resident until dropped).
    OutOfCorePoints* store_ = nullptr;
    uint64_t release_above_ = 0;
};

// The input points of a leaf as splats (normals and radii estimated where missing).
std::vector<Splat> Builder::leaf_splats(const HNode& node) {
    if (estimate_normals_ || estimate_radii_) {
        EstimateInput in;
        in.positions = arrays_.positions;
        in.xyz = arrays_.xyz;
        in.halo = [this](const float lo[3], const float hi[3], size_t begin, size_t end, std::vector<uint32_t>& ids) {
            halo(lo, hi, begin, end, ids);
        };
        in.nearest = [this](const float q[3], size_t k, uint32_t* index, float* distance2) {
            return nearest_all(q, k, index, distance2);
        };
        in.cloud_extent = cloud_extent_;
        in.neighbours = settings_.neighbours;
        in.radius_neighbour = settings_.radius_neighbour;
        in.orient_up = settings_.orientation == NormalOrientation::Up ||
                       (settings_.orientation == NormalOrientation::Auto && z_up_);
        estimate_leaf(in, node.begin, node.end, estimate_normals_ ? arrays_.normals : nullptr,
                      estimate_radii_ ? arrays_.radii : nullptr);
    }
    std::vector<Splat> splats(node.end - node.begin);
    for (uint32_t i = node.begin; i < node.end; ++i) {
        Splat& s = splats[i - node.begin];
        for (int a = 0; a < 3; ++a) {
            s.p[a] = arrays_.positions[i][a];
            s.n[a] = arrays_.normals[i][a];
            s.color[a] = arrays_.colors ? float(arrays_.colors[i][a]) : 0.0f;
        }
        s.radius = std::max(arrays_.radii[i], float(radius_floor_));
        s.cover = 0;
        s.weight = float(M_PI) * s.radius * s.radius;
    }
    return splats;
}

// Encodes a node's splats, writes it, records it, and returns the splats as decoded (what the
// parent is built from), with their covers grown by the quantization.
std::vector<Splat> Builder::finish_node(size_t index, std::vector<Splat> splats, float children_error,
                                        const float* children_box_min, const float* children_box_max) {
    const HNode& node = nodes_[index];
    const size_t n = splats.size();
    // Radii below half the node's median are raised to it: a few tiny splats (duplicates, a
    // dense clump) would otherwise set a fine grid for the whole node.
    std::vector<float> radii, scratch;
    const float median = select_rank(n, n / 2, [&](size_t i) { return splats[i].radius; }, radii, scratch);
    radii.resize(n);
    const float floor = std::max(0.5f * median, float(radius_floor_));
    std::vector<double> positions(3 * n);
    std::vector<float> normals(3 * n);
    std::vector<uint8_t> colors(arrays_.colors ? 3 * n : 0);
    for (size_t i = 0; i < n; ++i) {
        Splat& s = splats[i];
        s.radius = std::max(s.radius, floor);
        radii[i] = s.radius;
        for (int a = 0; a < 3; ++a) {
            positions[3 * i + a] = s.p[a];
            normals[3 * i + a] = s.n[a];
            if (!colors.empty()) colors[3 * i + a] = uint8_t(std::clamp(std::lround(s.color[a]), 0L, 255L));
        }
    }
    PointSamplesView view;
    view.count = n;
    view.positions = positions.data();
    view.normals = normals.data();
    view.colors = colors.empty() ? nullptr : colors.data();
    view.radii = radii.data();
    std::vector<uint32_t> order;
    DecodedPoints decoded;
    NodeRecord& record = records_[index];
    PointEncodeSettings encode;
    encode.color_bits = settings_.color_bits;
    encode.error_fraction = settings_.error_fraction;
    std::vector<uint8_t> bytes = encode_point_node(view, encode, &order, &decoded, &record.stats);

    std::vector<Splat> out(n);
    double error = children_error, radius_sum = 0;
    for (int a = 0; a < 3; ++a) {
        record.box_min[a] = children_box_min ? children_box_min[a] : INFINITY;
        record.box_max[a] = children_box_max ? children_box_max[a] : -INFINITY;
    }
    float splat_min[3] = {INFINITY, INFINITY, INFINITY}, splat_max[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t i = 0; i < n; ++i) {
        const Splat& in = splats[order[i]];
        Splat& s = out[i];
        double moved2 = 0;
        for (int a = 0; a < 3; ++a) {
            s.p[a] = decoded.positions[3 * i + a];
            moved2 += (s.p[a] - in.p[a]) * (s.p[a] - in.p[a]);
            s.color[a] = colors.empty() ? 0.0f : float(decoded.colors[3 * i + a]);
        }
        oct_decode(decoded.normals[i], s.n);
        s.radius = decoded.radii[i];
        s.cover = round_up(double(in.cover) + std::sqrt(moved2));
        s.weight = in.weight;
        error = std::max(error, double(s.cover));
        radius_sum += s.radius;
        for (int a = 0; a < 3; ++a) {
            splat_min[a] = std::min(splat_min[a], decoded.positions[3 * i + a] - s.radius);
            splat_max[a] = std::max(splat_max[a], decoded.positions[3 * i + a] + s.radius);
        }
    }
    // Rounded outwards once per node: nextafter is monotone, so this is the box of the rounded
    // splat boxes (per splat, its calls were 2% of the conversion's instructions).
    for (int a = 0; a < 3; ++a) {
        record.box_min[a] = std::min(record.box_min[a], std::nextafter(splat_min[a], -INFINITY));
        record.box_max[a] = std::max(record.box_max[a], std::nextafter(splat_max[a], INFINITY));
    }
    record.error = round_up(error);
    record.count = uint32_t(n);
    record.mean_radius = float(radius_sum / double(n));
    record.bytes = bytes.size();
    record.error_to_radius = record.stats.position_error / record.stats.min_radius;

    ArchiveEntry entry;
    entry.key = node.key;
    entry.level = uint16_t(node.depth);
    entry.flags = node.left < 0 ? kPointLeafFlag : 0;
    entry.count = uint32_t(n);
    entry.error = record.error;
    writer_->add_node(entry, bytes.data(), bytes.size());
    if (progress_) progress_->add(1);
    return out;
}

std::vector<Splat> Builder::build_node(size_t index) {
    const HNode node = nodes_[index];
    if (node.left < 0) {
        std::vector<Splat> splats = finish_node(index, leaf_splats(node), 0.0f, nullptr, nullptr);
        // Dropping pages is always safe: the data stays in the shared files, and a page touched
        // again is mapped again from the page cache.
        if (store_ && current_rss_bytes() > release_above_) store_->release_pages();
        return splats;
    }
    std::vector<Splat> left, right;
    tbb::parallel_invoke([&] { left = build_node(size_t(node.left)); }, [&] { right = build_node(size_t(node.right)); });
    return merge_children(index, std::move(left), std::move(right));
}

// Out of core: above the chunks one child after the other, each chunk's subtree in parallel, its
// pages released when it is done, so that one chunk's points are resident at a time.
std::vector<Splat> Builder::build_top(size_t index, OutOfCorePoints& store) {
    if (store.is_chunk_root(index)) {
        std::vector<Splat> splats = build_node(index);
        store.release_pages();
        return splats;
    }
    const HNode node = nodes_[index];
    std::vector<Splat> left = build_top(size_t(node.left), store);
    std::vector<Splat> right = build_top(size_t(node.right), store);
    return merge_children(index, std::move(left), std::move(right));
}

// An inner node from its children's decoded splats.
std::vector<Splat> Builder::merge_children(size_t index, std::vector<Splat> left, std::vector<Splat> right) {
    const HNode node = nodes_[index];
    const NodeRecord& a = records_[size_t(node.left)];
    const NodeRecord& b = records_[size_t(node.right)];
    float box_min[3], box_max[3];
    for (int k = 0; k < 3; ++k) {
        box_min[k] = std::min(a.box_min[k], b.box_min[k]);
        box_max[k] = std::max(a.box_max[k], b.box_max[k]);
    }
    left.insert(left.end(), right.begin(), right.end());
    std::vector<Splat>().swap(right);
    simplify_splats(left, parent_points(left.size()));
    return finish_node(index, std::move(left), std::max(a.error, b.error), box_min, box_max);
}

// Sets the origin (the centre of the bounds), decides what to estimate, and sets the radius floor.
void Builder::prepare(const PointInputSummary& input, PointsBuildReport& report) {
    const size_t n = input.count;
    report.input_points = n;
    if (n >= (size_t(1) << 32)) fail("%zu points: more than this converter's 2^32", n);
    bounds_ = input.bounds;
    // The neighbour searches and splat radii work in single precision relative to the origin:
    // squared distances must stay normal floats. A cloud 1e30 wide overflowed them (infinite
    // radii, an assertion in the encoder); one 1e-30 wide underflowed them (every radius the
    // floor's). Real clouds, nanometres to planets, lie far within.
    const double extent = std::max({bounds_.max[0] - bounds_.min[0], bounds_.max[1] - bounds_.min[1],
                                    bounds_.max[2] - bounds_.min[2]});
    if (extent > kPointMaxExtent || (extent > 0 && extent < kPointMinExtent))
        fail("the %zu points span %g units, outside the %g to %g this converter supports (it measures distances "
             "in single precision): rescale the coordinates",
             n, extent, kPointMinExtent, kPointMaxExtent);
    for (int a = 0; a < 3; ++a) origin_[a] = 0.5 * (bounds_.min[a] + bounds_.max[a]);
    radius_floor_ = std::max(bounds_.diagonal(), double(input.largest_radius)) * 0x1p-20;
    if (!(radius_floor_ > 0))
        fail("all %zu points coincide and carry no radii: no splat size can be estimated (give radii in the input)", n);
    estimate_normals_ = !input.normals;
    estimate_radii_ = !input.radii;
    report.normals_estimated = estimate_normals_;
    report.radii_estimated = estimate_radii_;
    report.has_colors = input.colors;
}

// Moves the cloud to the origin (in double precision), builds the hierarchy's nodes and puts the
// points in their order (every leaf a range).
//
// Every large array here is written whole by a parallel loop and so not initialized before
// (base/default_init.h): at 100M points, zeroing them on one thread, page faults included, kept
// one core alone for about 7 s of the 22 s partition phase (perf), where the first touches now
// come from both. The cloud's arrays are released as soon as they are permuted.
//
// The order of the allocations sets the peak: the permutation is taken from the items only after
// the partition's scratch array is gone, and the leaves' floats (xyz_) are made from the permuted
// positions after the input's are released, rather than from the items beside both. On the 100M
// cloud that lowered the peak from 6451 to 5719 MiB (68 to 60 bytes a point, reading included;
// the dataset is the same). At that size, touching fresh memory is a large part of the partition
// phase (perf: the kernel's page clearing was a third of the CPU time of the first 30 s), and the
// peak is what must be fresh.
void Builder::partition_in_core(PointCloud& cloud) {
    const size_t n = cloud.size();
    UninitializedVector<uint32_t> perm;
    {
        Items items(n);
        tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
            for (size_t i = r.begin(); i < r.end(); ++i) {
                Vec3d& p = cloud.positions[i];
                for (int a = 0; a < 3; ++a) p[a] -= origin_[a];
                for (int a = 0; a < 3; ++a) items[i].p[a] = float(p[a]);
                items[i].index = uint32_t(i);
            }
        });
        nodes_ = partition_items(items, 0, uint32_t(n), 1, 0, partition_settings_of(settings_), progress_);
        perm.resize(n);
        tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
            for (size_t i = r.begin(); i < r.end(); ++i) perm[i] = items[i].index;
        });
    }
    auto gather = [&perm](auto& values, auto& out) {
        if (values.empty()) return;
        out.resize(values.size());
        tbb::parallel_for(tbb::blocked_range<size_t>(0, perm.size(), 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
            for (size_t i = r.begin(); i < r.end(); ++i) out[i] = values[perm[i]];
        });
        std::remove_reference_t<decltype(values)>().swap(values);
    };
    gather(cloud.positions, positions_);
    // What the leaves' neighbour searches read (only when something is estimated): the points as
    // floats in their final order, the same values the items held (float of the same doubles).
    if (estimate_normals_ || estimate_radii_) {
        xyz_.resize(3 * n);
        tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
            for (size_t i = r.begin(); i < r.end(); ++i)
                for (int a = 0; a < 3; ++a) xyz_[3 * i + a] = float(positions_[i][a]);
        });
    }
    if (!estimate_normals_) gather(cloud.normals, normals_);
    gather(cloud.colors, colors_);
    if (!estimate_radii_) gather(cloud.radii, radii_);
    // What is estimated is allocated only now (not moved by the gathers, not resident beside the
    // partition's items): the leaves' estimates write every point's, in parallel.
    if (estimate_normals_) normals_.resize(n);
    if (estimate_radii_) radii_.resize(n);
    arrays_.positions = positions_.data();
    arrays_.normals = normals_.data();
    arrays_.colors = colors_.empty() ? nullptr : colors_.data();
    arrays_.radii = radii_.data();
    arrays_.xyz = xyz_.data();
}

// The tight box of every node of the hierarchy (leaves from their points when `leaves`, else
// already set), through which a leaf finds the points around it (halo): only when something
// is estimated. This replaced a kd-tree over all points, whose queries were half the
// conversion's time (grid_knn.h).
void Builder::node_boxes(bool leaves) {
    if (!estimate_normals_ && !estimate_radii_) return;
    // Leaves from their points (in parallel), inner nodes from their children, which come after
    // them in the array.
    if (leaves)
        tbb::parallel_for(tbb::blocked_range<size_t>(0, nodes_.size(), 16), [&](const tbb::blocked_range<size_t>& r) {
            for (size_t i = r.begin(); i < r.end(); ++i) {
                HNode& node = nodes_[i];
                if (node.left >= 0) continue;
                for (int a = 0; a < 3; ++a) {
                    node.lo[a] = INFINITY;
                    node.hi[a] = -INFINITY;
                }
                for (uint32_t p = node.begin; p < node.end; ++p)
                    for (int a = 0; a < 3; ++a) {
                        node.lo[a] = std::min(node.lo[a], arrays_.xyz[3 * size_t(p) + a]);
                        node.hi[a] = std::max(node.hi[a], arrays_.xyz[3 * size_t(p) + a]);
                    }
            }
        });
    for (size_t i = nodes_.size(); i-- > 0;) {
        HNode& node = nodes_[i];
        if (node.left < 0) continue;
        const HNode &l = nodes_[size_t(node.left)], &r = nodes_[size_t(node.right)];
        for (int a = 0; a < 3; ++a) {
            node.lo[a] = std::min(l.lo[a], r.lo[a]);
            node.hi[a] = std::max(l.hi[a], r.hi[a]);
        }
    }
    const HNode& root = nodes_[0];
    cloud_extent_ = std::max({root.hi[0] - root.lo[0], root.hi[1] - root.lo[1], root.hi[2] - root.lo[2]});
}

// Appends the points in [lo, hi] of the leaves other than [begin, end) (estimate.h's HaloFn).
void Builder::halo(const float lo[3], const float hi[3], size_t begin, size_t end, std::vector<uint32_t>& ids) const {
    uint32_t stack[2 * kPointMaxDepth + 2];
    size_t depth = 0;
    stack[depth++] = 0;
    while (depth > 0) {
        const HNode& node = nodes_[stack[--depth]];
        bool apart = false;
        for (int a = 0; a < 3; ++a) apart |= node.hi[a] < lo[a] || node.lo[a] > hi[a];
        if (apart || (node.begin >= begin && node.end <= end)) continue;
        if (node.left >= 0) {
            stack[depth++] = uint32_t(node.right);
            stack[depth++] = uint32_t(node.left);
            continue;
        }
        for (uint32_t p = node.begin; p < node.end; ++p) {
            const float* q = &arrays_.xyz[3 * size_t(p)];
            if (q[0] >= lo[0] && q[0] <= hi[0] && q[1] >= lo[1] && q[1] <= hi[1] && q[2] >= lo[2] && q[2] <= hi[2])
                ids.push_back(p);
        }
    }
}

// The metadata: node records in index order, (depth, key).
// The k nearest points to q among all (estimate.h's NearestFn): best first over the hierarchy's
// node boxes, scanning the leaves met, until no box is nearer than the k-th found. The leaves
// are large (node_points), so this is for the few points a leaf's halo leaves unsettled.
size_t Builder::nearest_all(const float q[3], size_t k, uint32_t* index, float* distance2) const {
    auto box_distance2 = [q](const HNode& node) {
        float d2 = 0;
        for (int a = 0; a < 3; ++a) {
            const float d = std::max({node.lo[a] - q[a], q[a] - node.hi[a], 0.0f});
            d2 += d * d;
        }
        return d2;
    };
    struct Entry {
        float d2;
        uint32_t node;
        bool operator<(const Entry& o) const { return d2 > o.d2 || (d2 == o.d2 && node > o.node); }  // min-heap
    };
    std::vector<Entry> heap = {{box_distance2(nodes_[0]), 0}};
    size_t found = 0;
    float worst = INFINITY;
    while (!heap.empty()) {
        std::pop_heap(heap.begin(), heap.end());
        const Entry entry = heap.back();
        heap.pop_back();
        if (found == k && entry.d2 >= worst) break;
        const HNode& node = nodes_[entry.node];
        if (node.left >= 0) {
            for (int32_t child : {node.left, node.right}) {
                const float d2 = box_distance2(nodes_[size_t(child)]);
                if (found < k || d2 < worst) {
                    heap.push_back({d2, uint32_t(child)});
                    std::push_heap(heap.begin(), heap.end());
                }
            }
            continue;
        }
        for (uint32_t p = node.begin; p < node.end; ++p) {
            const float* x = &arrays_.xyz[3 * size_t(p)];
            const float dx = x[0] - q[0], dy = x[1] - q[1], dz = x[2] - q[2];
            const float d2 = dx * dx + dy * dy + dz * dz;
            if (found == k && !(d2 < worst)) continue;
            knn_insert(index, distance2, k, found, worst, p, d2);
        }
    }
    return found;
}

PointsMeta Builder::make_meta(const PointsBuildReport& report) const {
    PointsMeta meta;
    for (int a = 0; a < 3; ++a) {
        meta.origin[a] = origin_[a];
        meta.bounds_min[a] = bounds_.min[a];
        meta.bounds_max[a] = bounds_.max[a];
    }
    meta.input_points = report.input_points;
    meta.node_points = uint32_t(settings_.node_points);
    meta.flags = (estimate_normals_ ? 0 : kPointsMetaInputNormals) | (report.has_colors ? kPointsMetaInputColors : 0) |
                 (estimate_radii_ ? 0 : kPointsMetaInputRadii);
    meta.split = settings_.split;
    meta.color_bits = settings_.color_bits;
    meta.up_axis = settings_.up_axis ? settings_.up_axis : z_up_ ? 3 : 0;
    for (size_t i : index_order()) {
        const NodeRecord& r = records_[i];
        PointNodeInfo info;
        info.key = nodes_[i].key;
        std::copy(r.box_min, r.box_min + 3, info.box_min);
        std::copy(r.box_max, r.box_max + 3, info.box_max);
        info.mean_radius = r.mean_radius;
        meta.nodes.push_back(info);
    }
    return meta;
}

std::vector<size_t> Builder::index_order() const {
    std::vector<size_t> order(nodes_.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::sort(order.begin(), order.end(), [this](size_t a, size_t b) {
        return nodes_[a].depth != nodes_[b].depth ? nodes_[a].depth < nodes_[b].depth : nodes_[a].key < nodes_[b].key;
    });
    return order;
}

// Per-level and per-leaf figures, the codec's byte split.
void Builder::summarize(PointsBuildReport& report) const {
    report.min_leaf_points = SIZE_MAX;
    for (size_t i = 0; i < nodes_.size(); ++i) {
        const HNode& node = nodes_[i];
        const NodeRecord& r = records_[i];
        if (size_t(node.depth) >= report.levels.size()) report.levels.resize(size_t(node.depth) + 1);
        PointsLevelStats& level = report.levels[size_t(node.depth)];
        level.depth = node.depth;
        level.nodes += 1;
        level.points += r.count;
        level.bytes += r.bytes;
        level.max_error = std::max(level.max_error, double(r.error));
        level.mean_radius += r.mean_radius * r.count;
        report.stored_points += r.count;
        report.bytes_position += r.stats.bytes_position;
        report.bytes_normal += r.stats.bytes_normal;
        report.bytes_color += r.stats.bytes_color;
        report.bytes_radius += r.stats.bytes_radius;
        report.bytes_header += r.stats.bytes_header;
        report.worst_error_to_radius = std::max(report.worst_error_to_radius, r.error_to_radius);
        if (node.left < 0) {
            report.leaves += 1;
            report.depth = std::max(report.depth, node.depth);
            report.min_leaf_points = std::min<size_t>(report.min_leaf_points, r.count);
            report.max_leaf_points = std::max<size_t>(report.max_leaf_points, r.count);
        }
    }
    for (PointsLevelStats& level : report.levels)
        if (level.points) level.mean_radius /= double(level.points);
    report.nodes = nodes_.size();
    report.mean_leaf_points = double(report.input_points) / double(report.leaves);
}

PointsBuildReport Builder::run_in_core(PointCloud& cloud, const std::string& output_path) {
    PointsBuildReport report;
    const double start = now_seconds();
    PointInputSummary input;
    input.count = cloud.size();
    input.bounds = cloud.bounds();
    for (float r : cloud.radii) input.largest_radius = std::max(input.largest_radius, r);
    input.normals = cloud.has_normals();
    input.colors = cloud.has_colors();
    input.radii = cloud.has_radii();
    prepare(input, report);
    writer_ = std::make_unique<ArchiveWriter>(output_path, ArchiveKind::Points);

    if (progress_) progress_->phase("partitioning", cloud.size(), "pt");
    partition_in_core(cloud);
    report.seconds_partition = now_seconds() - start;

    double t0 = now_seconds();
    node_boxes(/*leaves=*/true);
    report.seconds_search_tree = now_seconds() - t0;

    t0 = now_seconds();
    if (progress_) progress_->phase("building nodes", nodes_.size(), "nodes");
    records_.resize(nodes_.size());
    build_node(0);
    report.seconds_nodes = now_seconds() - t0;
    return finish(report, start);
}

PointsBuildReport Builder::run_out_of_core(OutOfCorePoints& store, const std::string& output_path) {
    PointsBuildReport report;
    const double start = now_seconds();
    prepare(store.summary(), report);
    writer_ = std::make_unique<ArchiveWriter>(output_path, ArchiveKind::Points);

    store.partition(origin_);
    nodes_ = std::move(store.nodes());
    arrays_ = store.arrays();
    store_ = &store;
    release_above_ = settings_.memory_budget ? settings_.memory_budget / 4 * 3 : UINT64_MAX;
    report.out_of_core = true;
    report.chunks = store.chunks();
    report.split_passes = store.split_passes();
    report.seconds_partition = now_seconds() - start;

    double t0 = now_seconds();
    node_boxes(/*leaves=*/false);  // the store set the leaves' boxes
    report.seconds_search_tree = now_seconds() - t0;

    t0 = now_seconds();
    if (progress_) progress_->phase("building nodes", nodes_.size(), "nodes");
    records_.resize(nodes_.size());
    build_top(0, store);
    report.seconds_nodes = now_seconds() - t0;
    return finish(report, start);
}

PointsBuildReport Builder::finish(PointsBuildReport& report, double start) {
    const double t0 = now_seconds();
    if (progress_) progress_->phase("writing", 0, "");
    summarize(report);
    report.payload_bytes = writer_->payload_bytes();
    report.file_bytes = writer_->finish(encode_points_meta(make_meta(report)));
    report.seconds_write = now_seconds() - t0;
    report.seconds = now_seconds() - start;
    report.peak_rss = peak_rss_bytes();
    return report;
}

}  // namespace

namespace {

void check_settings(const PointsBuildSettings& settings) {
    if (settings.node_points < 16 || settings.node_points > (size_t(1) << 20))
        fail("node size %zu is out of range (16 .. 2^20 points)", settings.node_points);
    if (settings.color_bits.luma < 1 || settings.color_bits.luma > 8 || settings.color_bits.chroma < 1 ||
        settings.color_bits.chroma > 9)
        fail("colour precision %u/%u is out of range (luma 1..8, chroma 1..9 bits)", settings.color_bits.luma,
             settings.color_bits.chroma);
    if (!(settings.error_fraction > 0 && settings.error_fraction <= 1))
        fail("position error fraction %g is out of range (0, 1]", settings.error_fraction);
    if (settings.radius_neighbour < 1 || settings.radius_neighbour > 63)
        fail("radius neighbour %zu is out of range (1 .. 63)", settings.radius_neighbour);
}

// Out of core when asked, or when the in-core estimate exceeds the budget; then the budget
// must leave room for the process itself (libraries, thread stacks, the reader's buffers: about
// 25 MiB) and for a chunk.
bool use_out_of_core(uint64_t points, const PointsBuildSettings& settings) {
    if (settings.chunk_points) return true;
    if (!settings.memory_budget || points_memory_estimate(points) <= settings.memory_budget) return false;
    if (settings.memory_budget < kPointsMinimumBudget)
        fail("%llu points need about %llu MiB in core, more than the memory budget of %llu MiB, and out of core the "
             "point converter needs at least %llu MiB",
             (unsigned long long)points, (unsigned long long)(points_memory_estimate(points) >> 20),
             (unsigned long long)(settings.memory_budget >> 20), (unsigned long long)(kPointsMinimumBudget >> 20));
    return true;
}

// What the top splits' histograms and the distribution's buffers may take.
uint64_t out_of_core_buffer_bytes(const PointsBuildSettings& settings) {
    return settings.memory_budget ? std::max<uint64_t>(uint64_t(2) << 20, settings.memory_budget / 16) : uint64_t(64) << 20;
}

// The points a chunk may hold under the budget: what is left after the process's fixed needs
// (libraries, thread stacks, node records) and the buffers, at kOutOfCorePointBytes a point.
size_t out_of_core_chunk_points(const PointsBuildSettings& settings) {
    if (settings.chunk_points) return settings.chunk_points;
    const uint64_t fixed = (uint64_t(40) << 20) + out_of_core_buffer_bytes(settings);
    const uint64_t left = settings.memory_budget > fixed ? settings.memory_budget - fixed : 0;
    return std::max<size_t>(4 * settings.node_points, size_t(left / kOutOfCorePointBytes));
}

// The thread limit and the progress display of one conversion.
struct ConversionScope {
    std::unique_ptr<tbb::global_control> threads;
    std::unique_ptr<Progress> progress;
    explicit ConversionScope(const PointsBuildSettings& settings) {
        if (settings.threads)
            threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, settings.threads);
        if (settings.progress && Progress::enabled()) progress = std::make_unique<Progress>("convert", "preparing", 0, "");
    }
};

}  // namespace

PointsBuildReport build_points(PointCloud cloud, const std::string& output_path, const PointsBuildSettings& settings,
                               bool z_up) {
    check_output_file(output_path, "output");
    validate_point_cloud(cloud, "point cloud");
    check_settings(settings);
    ConversionScope scope(settings);
    Builder builder(settings, z_up, scope.progress.get());
    PointsBuildReport report;
    if (!use_out_of_core(cloud.size(), settings)) {
        report = builder.run_in_core(cloud, output_path);
    } else {
        OutOfCorePoints store(output_path, partition_settings_of(settings), out_of_core_chunk_points(settings),
                              out_of_core_buffer_bytes(settings), scope.progress.get());
        if (scope.progress) scope.progress->phase("storing", cloud.size(), "pt");
        store.add(cloud);
        if (scope.progress) scope.progress->add(cloud.size());
        cloud = PointCloud();  // the store holds it now
        report = builder.run_out_of_core(store, output_path);
    }
    report.memory_estimate = points_memory_estimate(report.input_points);
    if (scope.progress) scope.progress->finish();
    return report;
}

PointsBuildReport build_points_stream(PointFileReader& reader, const std::string& output_path,
                                      const PointsBuildSettings& settings) {
    check_output_file(output_path, "output");  // before the input is read, however long that takes
    check_settings(settings);
    ConversionScope scope(settings);
    Progress* progress = scope.progress.get();
    const double start = now_seconds();
    const bool z_up = reader.info().z_up;
    // Out of core from the start when the header's count says so; else in core while the
    // points read so far fit the budget (text files announce no count), moving to the store
    // when they stop fitting.
    std::unique_ptr<OutOfCorePoints> store;
    auto open_store = [&] {
        store = std::make_unique<OutOfCorePoints>(output_path, partition_settings_of(settings),
                                                  out_of_core_chunk_points(settings), out_of_core_buffer_bytes(settings), progress);
    };
    const uint64_t expected = reader.expected_points();
    if (settings.chunk_points || (expected && use_out_of_core(expected, settings))) open_store();
    if (progress) progress->phase("reading", expected, "pt");
    PointCloud cloud, batch;
    if (!store && expected) {
        cloud.positions.reserve(expected);
        if (reader.has_normals()) cloud.normals.reserve(expected);
        if (reader.has_colors()) cloud.colors.reserve(expected);
        if (reader.has_radii()) cloud.radii.reserve(expected);
    }
    constexpr size_t kBatch = size_t(1) << 16;  // 2.8 MiB of points with every attribute
    while (reader.next(batch, kBatch)) {
        if (progress) progress->add(batch.size());
        if (store) {
            store->add(batch);
            continue;
        }
        cloud.positions.insert(cloud.positions.end(), batch.positions.begin(), batch.positions.end());
        cloud.normals.insert(cloud.normals.end(), batch.normals.begin(), batch.normals.end());
        cloud.colors.insert(cloud.colors.end(), batch.colors.begin(), batch.colors.end());
        cloud.radii.insert(cloud.radii.end(), batch.radii.begin(), batch.radii.end());
        if (use_out_of_core(cloud.size(), settings)) {
            open_store();
            store->add(cloud);
            cloud = PointCloud();
        }
    }
    Builder builder(settings, z_up, progress);
    PointsBuildReport report = store ? builder.run_out_of_core(*store, output_path) : builder.run_in_core(cloud, output_path);
    report.memory_estimate = points_memory_estimate(report.input_points);
    report.dropped_input = reader.info().dropped;
    report.seconds_read = now_seconds() - start - report.seconds;
    report.seconds = now_seconds() - start;
    if (progress) progress->finish();
    return report;
}

PointsBuildReport build_points_file(const std::string& input_path, const std::string& output_path,
                                    const PointsBuildSettings& settings) {
    check_output_file(output_path, "output");
    PointFileReader reader(input_path);
    return build_points_stream(reader, output_path, settings);
}

}  // namespace catpaq
