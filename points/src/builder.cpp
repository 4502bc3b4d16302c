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

#include "base/error.h"
#include "base/output_path.h"
#include "base/progress.h"
#include "base/sysinfo.h"
#include "common_codec/archive.h"
#include "common_codec/octahedral.h"
#include "estimate.h"
#include "kdtree.h"
#include "splat.h"

namespace catpaq {

using namespace points_detail;

namespace {

constexpr size_t kParallelPoints = 1 << 16;  // ranges this large are partitioned in parallel
constexpr int kMidpointMaxDepth = 48;        // deeper, the midpoint rule gives way to the median

// One node of the hierarchy: a range of the (permuted) points, and children in the same array.
struct HNode {
    uint32_t begin = 0, end = 0;
    int32_t left = -1, right = -1;
    uint64_t key = 1;
    int depth = 0;
    float lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};  // tight box of the points (set for the halo search)
};

// A point as the partition moves it: its position (float, relative to the origin: enough to
// place split planes) next to its index, so that every pass over a node reads memory in order
// (through an index array into the doubles, the first levels of a 10M cloud took 28 s of cache
// misses).
struct PartitionItem {
    float p[3];
    uint32_t index;
};
using Items = std::vector<PartitionItem>;

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

class Builder {
public:
    Builder(PointCloud& cloud, const PointsBuildSettings& settings, bool z_up, Progress* progress)
        : cloud_(cloud), settings_(settings), z_up_(z_up), progress_(progress) {}

    PointsBuildReport run(const std::string& output_path);

private:
    void prepare(PointsBuildReport& report);
    void partition_all();
    void build_search_tree();
    void halo(const float lo[3], const float hi[3], size_t begin, size_t end, std::vector<uint32_t>& ids) const;
    size_t nearest_all(const float q[3], size_t k, uint32_t* index, float* distance2) const;
    PointsMeta make_meta(const PointsBuildReport& report) const;
    std::vector<size_t> index_order() const;
    void summarize(PointsBuildReport& report) const;
    void place_at_origin();
    std::vector<HNode> partition(Items& items, uint32_t begin, uint32_t end, uint64_t key, int depth);
    uint32_t choose_split(Items& items, uint32_t begin, uint32_t end, int depth) const;
    uint32_t split_midpoint(Items& items, uint32_t begin, uint32_t end, const float lo[3], const float hi[3]) const;
    uint32_t split_balanced(Items& items, uint32_t begin, uint32_t end, const float lo[3], const float hi[3]) const;
    uint32_t split_median(Items& items, uint32_t begin, uint32_t end, int axis) const;
    void apply_permutation(const std::vector<uint32_t>& perm);

    std::vector<Splat> build_node(size_t index);
    size_t parent_points(size_t children_points) const { return parent_points_for(children_points, settings_.node_points); }
    std::vector<Splat> leaf_splats(const HNode& node);
    std::vector<Splat> finish_node(size_t index, std::vector<Splat> splats, float children_error,
                                   const float* children_box_min, const float* children_box_max);

    PointCloud& cloud_;
    const PointsBuildSettings& settings_;
    bool z_up_;
    Progress* progress_;
    double origin_[3] = {0, 0, 0};
    Bounds bounds_;
    double radius_floor_ = 0;  // no splat is smaller (a tiny fraction of the model's size)
    bool estimate_normals_ = false, estimate_radii_ = false;
    std::vector<HNode> nodes_;
    std::vector<NodeRecord> records_;
    std::vector<float> xyz_;  // the points as floats, 3 each, for the neighbour searches
    float cloud_extent_ = 0;
    std::unique_ptr<ArchiveWriter> writer_;
};

// Moves the points to the origin at the centre of their bounds (in double precision).
void Builder::place_at_origin() {
    bounds_ = cloud_.bounds();
    for (int a = 0; a < 3; ++a) origin_[a] = 0.5 * (bounds_.min[a] + bounds_.max[a]);
    for (Vec3d& p : cloud_.positions)
        for (int a = 0; a < 3; ++a) p[a] -= origin_[a];
}

uint32_t Builder::split_median(Items& items, uint32_t begin, uint32_t end, int axis) const {
    const uint32_t middle = begin + (end - begin) / 2;
    std::nth_element(items.begin() + begin, items.begin() + middle, items.begin() + end,
                     [axis](const PartitionItem& a, const PartitionItem& b) { return a.p[axis] < b.p[axis]; });
    return middle;
}

// Seed 002: the middle of the longest side of the tight box.
uint32_t Builder::split_midpoint(Items& items, uint32_t begin, uint32_t end, const float lo[3], const float hi[3]) const {
    int axis = 0;
    for (int a = 1; a < 3; ++a)
        if (hi[a] - lo[a] > hi[axis] - lo[axis]) axis = a;
    const float plane = 0.5f * (lo[axis] + hi[axis]);
    auto middle = std::partition(items.begin() + begin, items.begin() + end,
                                 [axis, plane](const PartitionItem& i) { return i.p[axis] < plane; });
    uint32_t at = uint32_t(middle - items.begin());
    // A tight box has points on both of its faces, so both sides are non-empty unless the box
    // is too thin for floats to hold a plane between them.
    if (at == begin || at == end) return split_median(items, begin, end, axis);
    return at;
}

// Floats order as these keys do (negatives reversed below the positives; -0 just below +0).
inline uint32_t float_order_key(float v) {
    uint32_t bits;
    std::memcpy(&bits, &v, 4);
    return (bits & 0x80000000u) ? ~bits : (bits | 0x80000000u);
}

// The value of rank `rank` among n floats get(0) .. get(n - 1): the value std::nth_element
// puts at `rank` (ties aside: equal values, and -0 and +0, which compare equal), by a radix
// select: a histogram of the order keys' top bits above the smallest key picks the bucket
// holding the rank, whose values are selected the same way until few are left for
// nth_element. Written out because nth_element on a node's coordinates and radii mispredicts
// most of its branches (3% of the conversion's time); these passes have nearly none.
template <class Get>
float select_rank(size_t n, size_t rank, Get get, std::vector<float>& values, std::vector<float>& next) {
    constexpr size_t kSmall = 512;  // below, nth_element
    constexpr uint32_t kBits = 11;  // a histogram of 2048 buckets
    values.resize(n);
    for (size_t i = 0; i < n; ++i) values[i] = get(i);
    uint32_t counts[size_t(1) << kBits];
    while (values.size() > kSmall) {
        uint32_t low = UINT32_MAX, high = 0;
        for (float v : values) {
            low = std::min(low, float_order_key(v));
            high = std::max(high, float_order_key(v));
        }
        if (low == high) return values[0];
        const uint32_t width = uint32_t(std::bit_width(high - low)), shift = width > kBits ? width - kBits : 0;
        std::fill(counts, counts + (size_t(1) << kBits), 0u);
        for (float v : values) ++counts[(float_order_key(v) - low) >> shift];
        uint32_t bucket = 0;
        size_t before = 0;
        while (before + counts[bucket] <= rank) before += counts[bucket++];
        next.clear();
        for (float v : values)
            if ((float_order_key(v) - low) >> shift == bucket) next.push_back(v);
        values.swap(next);
        rank -= before;
    }
    std::nth_element(values.begin(), values.begin() + ptrdiff_t(rank), values.end());
    return values[rank];
}

// The value of rank n / 2 of the items' coordinates on `axis` (what std::nth_element puts at
// n / 2 of a copy of them). Large ranges select by a histogram of the top 16 bits of the
// coordinates' order-preserving keys and a selection within the bucket holding that rank: on
// 10M points, the copies and nth_elements of the balanced split were a tenth of the CPU time.
float median_coordinate(const Items& items, uint32_t begin, uint32_t end, int axis) {
    const size_t n = end - begin, rank = n / 2;
    std::vector<float> values;
    if (n < kParallelPoints) {
        std::vector<float> next;
        return select_rank(n, rank, [&](size_t i) { return items[begin + i].p[axis]; }, values, next);
    }
    auto key = float_order_key;
    std::vector<uint32_t> counts(size_t(1) << 16, 0);
    for (uint32_t i = begin; i < end; ++i) ++counts[key(items[i].p[axis]) >> 16];
    uint32_t bucket = 0;
    size_t before = 0;
    while (before + counts[bucket] <= rank) before += counts[bucket++];
    values.reserve(counts[bucket]);
    for (uint32_t i = begin; i < end; ++i)
        if (key(items[i].p[axis]) >> 16 == bucket) values.push_back(items[i].p[axis]);
    std::nth_element(values.begin(), values.begin() + ptrdiff_t(rank - before), values.end());
    return values[rank - before];
}

// Seed 000: among the planes whose children are not thinner (across the plane) than the
// longest side / max_aspect, the most balanced one; on each axis that is the median clamped to
// the acceptable range, and the axis whose plane splits the counts most evenly wins.
uint32_t Builder::split_balanced(Items& items, uint32_t begin, uint32_t end, const float lo[3], const float hi[3]) const {
    const float longest = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
    const float margin = longest / float(std::max(settings_.max_aspect, 2.0));
    const uint32_t n = end - begin;
    int best_axis = -1;
    float best_plane = 0;
    uint64_t best_imbalance = UINT64_MAX;
    // Each axis's median plane and how unevenly it splits; the three are independent, and on
    // large nodes (the first levels, which run before the tree fans out over the cores) they are
    // found in parallel.
    float planes[3] = {0, 0, 0};
    uint64_t imbalances[3] = {UINT64_MAX, UINT64_MAX, UINT64_MAX};
    auto evaluate = [&](int axis) {
        if (hi[axis] - lo[axis] < 2 * margin) return;
        const float median = median_coordinate(items, begin, end, axis);
        const float plane = std::clamp(median, lo[axis] + margin, hi[axis] - margin);
        uint64_t below = 0;
        for (uint32_t i = begin; i < end; ++i) below += items[i].p[axis] < plane;
        uint64_t imbalance = below > n / 2 ? below - n / 2 : n / 2 - below;
        if (plane == median) imbalance = 0;  // the median itself: split by rank below
        planes[axis] = plane;
        imbalances[axis] = imbalance;
    };
    if (n > kParallelPoints) {
        tbb::parallel_for(0, 3, evaluate);
    } else {
        for (int axis = 0; axis < 3; ++axis) evaluate(axis);
    }
    for (int axis = 0; axis < 3; ++axis) {
        if (imbalances[axis] == UINT64_MAX) continue;
        const float plane = planes[axis];
        const uint64_t imbalance = imbalances[axis];
        if (imbalance < best_imbalance ||
            (imbalance == best_imbalance && hi[axis] - lo[axis] > hi[best_axis] - lo[best_axis])) {
            best_axis = axis;
            best_plane = plane;
            best_imbalance = imbalance;
        }
    }
    if (best_axis < 0) return split_midpoint(items, begin, end, lo, hi);
    if (best_imbalance == 0) return split_median(items, begin, end, best_axis);
    auto middle = std::partition(items.begin() + begin, items.begin() + end,
                                 [best_axis, best_plane](const PartitionItem& i) { return i.p[best_axis] < best_plane; });
    uint32_t at = uint32_t(middle - items.begin());
    if (at == begin || at == end) return split_median(items, begin, end, best_axis);
    return at;
}

// The tight box of items[begin, end) (in parallel for large ranges).
void item_bounds(const Items& items, uint32_t begin, uint32_t end, float lo[3], float hi[3]) {
    struct Box {
        float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
        void add(const Box& o) {
            for (int a = 0; a < 3; ++a) {
                lo[a] = std::min(lo[a], o.lo[a]);
                hi[a] = std::max(hi[a], o.hi[a]);
            }
        }
    };
    auto range_box = [&items](size_t first, size_t last) {
        Box box;
        for (size_t i = first; i < last; ++i)
            for (int a = 0; a < 3; ++a) {
                box.lo[a] = std::min(box.lo[a], items[i].p[a]);
                box.hi[a] = std::max(box.hi[a], items[i].p[a]);
            }
        return box;
    };
    Box box;
    if (end - begin > kParallelPoints) {
        box = tbb::parallel_reduce(
            tbb::blocked_range<size_t>(begin, end, 1 << 15), Box(),
            [&](const tbb::blocked_range<size_t>& r, Box b) {
                b.add(range_box(r.begin(), r.end()));
                return b;
            },
            [](Box a, const Box& b) {
                a.add(b);
                return a;
            });
    } else {
        box = range_box(begin, end);
    }
    std::copy(box.lo, box.lo + 3, lo);
    std::copy(box.hi, box.hi + 3, hi);
}

uint32_t Builder::choose_split(Items& items, uint32_t begin, uint32_t end, int depth) const {
    float lo[3], hi[3];
    item_bounds(items, begin, end, lo, hi);
    // Deep trees come from points that coincide or nearly do: split them by rank.
    if (depth >= kMidpointMaxDepth) return split_median(items, begin, end, 0);
    if (settings_.split == PointSplitRule::Balanced) return split_balanced(items, begin, end, lo, hi);
    return split_midpoint(items, begin, end, lo, hi);
}

// Partitions items[begin, end) into the subtree of node `key`; returns the subtree's nodes, its
// root first, children indices relative to the returned array.
std::vector<HNode> Builder::partition(Items& items, uint32_t begin, uint32_t end, uint64_t key, int depth) {
    HNode node;
    node.begin = begin;
    node.end = end;
    node.key = key;
    node.depth = depth;
    if (end - begin <= settings_.node_points) {
        if (progress_) progress_->add(end - begin);
        return {node};
    }
    if (depth >= kPointMaxDepth) fail("the point hierarchy would be deeper than %d levels", kPointMaxDepth);
    const uint32_t middle = choose_split(items, begin, end, depth);
    std::vector<HNode> left, right;
    if (end - begin > kParallelPoints) {
        tbb::parallel_invoke([&] { left = partition(items, begin, middle, 2 * key, depth + 1); },
                             [&] { right = partition(items, middle, end, 2 * key + 1, depth + 1); });
    } else {
        left = partition(items, begin, middle, 2 * key, depth + 1);
        right = partition(items, middle, end, 2 * key + 1, depth + 1);
    }
    std::vector<HNode> out;
    out.reserve(1 + left.size() + right.size());
    node.left = 1;
    node.right = int32_t(1 + left.size());
    out.push_back(node);
    for (HNode& child : left) {
        if (child.left >= 0) child.left += 1, child.right += 1;
        out.push_back(child);
    }
    for (HNode& child : right) {
        if (child.left >= 0) child.left += node.right, child.right += node.right;
        out.push_back(child);
    }
    return out;
}

void Builder::apply_permutation(const std::vector<uint32_t>& perm) {
    auto gather = [&perm](auto& values) {
        if (values.empty()) return;
        std::remove_reference_t<decltype(values)> out(values.size());
        tbb::parallel_for(tbb::blocked_range<size_t>(0, perm.size(), 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
            for (size_t i = r.begin(); i < r.end(); ++i) out[i] = values[perm[i]];
        });
        values.swap(out);
    };
    gather(cloud_.positions);
    gather(cloud_.normals);
    gather(cloud_.colors);
    gather(cloud_.radii);
}

// The input points of a leaf as splats (normals and radii estimated where missing).
std::vector<Splat> Builder::leaf_splats(const HNode& node) {
    if (estimate_normals_ || estimate_radii_) {
        EstimateInput in;
        in.positions = cloud_.positions.data();
        in.xyz = xyz_.data();
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
        estimate_leaf(in, node.begin, node.end, estimate_normals_ ? cloud_.normals.data() : nullptr,
                      estimate_radii_ ? cloud_.radii.data() : nullptr);
    }
    std::vector<Splat> splats(node.end - node.begin);
    for (uint32_t i = node.begin; i < node.end; ++i) {
        Splat& s = splats[i - node.begin];
        for (int a = 0; a < 3; ++a) {
            s.p[a] = cloud_.positions[i][a];
            s.n[a] = cloud_.normals[i][a];
            s.color[a] = cloud_.colors.empty() ? 0.0f : float(cloud_.colors[i][a]);
        }
        s.radius = std::max(cloud_.radii[i], float(radius_floor_));
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
    std::vector<uint8_t> colors(cloud_.colors.empty() ? 0 : 3 * n);
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
    if (node.left < 0) return finish_node(index, leaf_splats(node), 0.0f, nullptr, nullptr);
    std::vector<Splat> left, right;
    tbb::parallel_invoke([&] { left = build_node(size_t(node.left)); }, [&] { right = build_node(size_t(node.right)); });
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

// Moves the points to their origin, decides what to estimate, and sets the radius floor.
void Builder::prepare(PointsBuildReport& report) {
    const size_t n = cloud_.size();
    report.input_points = n;
    if (n >= (size_t(1) << 32)) fail("%zu points: more than this converter's 2^32", n);
    place_at_origin();
    float largest_radius = 0;
    for (float r : cloud_.radii) largest_radius = std::max(largest_radius, r);
    radius_floor_ = std::max(bounds_.diagonal(), double(largest_radius)) * 0x1p-20;
    if (!(radius_floor_ > 0))
        fail("all %zu points coincide and carry no radii: no splat size can be estimated (give radii in the input)", n);
    estimate_normals_ = !cloud_.has_normals();
    estimate_radii_ = !cloud_.has_radii();
    report.normals_estimated = estimate_normals_;
    report.radii_estimated = estimate_radii_;
    report.has_colors = cloud_.has_colors();
    if (estimate_normals_) cloud_.normals.assign(n, Vec3f{0, 0, 1});
    if (estimate_radii_) cloud_.radii.assign(n, 0.0f);
}

// Builds the hierarchy's nodes and puts the points in their order (every leaf a range).
void Builder::partition_all() {
    const size_t n = cloud_.size();
    std::vector<uint32_t> perm(n);
    {
        Items items(n);
        tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
            for (size_t i = r.begin(); i < r.end(); ++i) {
                for (int a = 0; a < 3; ++a) items[i].p[a] = float(cloud_.positions[i][a]);
                items[i].index = uint32_t(i);
            }
        });
        nodes_ = partition(items, 0, uint32_t(n), 1, 0);
        for (size_t i = 0; i < n; ++i) perm[i] = items[i].index;
    }
    apply_permutation(perm);
    records_.resize(nodes_.size());
}

// What the leaves' neighbour searches read (only when something is estimated): the points as
// floats, and the tight box of every node of the hierarchy, through which a leaf finds the
// points around it (halo). This replaced a kd-tree over all points, whose queries were half the
// conversion's time (grid_knn.h).
void Builder::build_search_tree() {
    if (!estimate_normals_ && !estimate_radii_) return;
    const size_t n = cloud_.size();
    xyz_.resize(3 * n);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1 << 14), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i < r.end(); ++i)
            for (int a = 0; a < 3; ++a) xyz_[3 * i + a] = float(cloud_.positions[i][a]);
    });
    // Leaves from their points (in parallel), inner nodes from their children, which come after
    // them in the array.
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
                    node.lo[a] = std::min(node.lo[a], xyz_[3 * size_t(p) + a]);
                    node.hi[a] = std::max(node.hi[a], xyz_[3 * size_t(p) + a]);
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
            const float* q = &xyz_[3 * size_t(p)];
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
            const float* x = &xyz_[3 * size_t(p)];
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

PointsBuildReport Builder::run(const std::string& output_path) {
    PointsBuildReport report;
    const double start = now_seconds();
    prepare(report);
    writer_ = std::make_unique<ArchiveWriter>(output_path, ArchiveKind::Points);

    if (progress_) progress_->phase("partitioning", cloud_.size(), "pt");
    partition_all();
    report.seconds_partition = now_seconds() - start;

    double t0 = now_seconds();
    build_search_tree();
    report.seconds_search_tree = now_seconds() - t0;

    t0 = now_seconds();
    if (progress_) progress_->phase("building nodes", nodes_.size(), "nodes");
    build_node(0);
    report.seconds_nodes = now_seconds() - t0;

    t0 = now_seconds();
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

PointsBuildReport build_points(PointCloud cloud, const std::string& output_path, const PointsBuildSettings& settings,
                               bool z_up) {
    check_output_file(output_path, "output");
    validate_point_cloud(cloud, "point cloud");
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
    const uint64_t estimate = points_memory_estimate(cloud.size());
    if (settings.memory_budget && estimate > settings.memory_budget)
        fail("%zu points need about %llu MiB in core, more than the memory budget of %llu MiB (the point converter "
             "works in core; a larger --memory, or fewer points)",
             cloud.size(), (unsigned long long)(estimate >> 20), (unsigned long long)(settings.memory_budget >> 20));
    std::unique_ptr<tbb::global_control> threads;
    if (settings.threads)
        threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, settings.threads);
    std::unique_ptr<Progress> progress;
    if (settings.progress && Progress::enabled())
        progress = std::make_unique<Progress>("convert", "preparing", 0, "");
    Builder builder(cloud, settings, z_up, progress.get());
    PointsBuildReport report = builder.run(output_path);
    report.memory_estimate = estimate;
    if (progress) progress->finish();
    return report;
}

PointsBuildReport build_points_file(const std::string& input_path, const std::string& output_path,
                                    const PointsBuildSettings& settings) {
    check_output_file(output_path, "output");  // before the input is read, however long that takes
    PointReadInfo info;
    PointCloud cloud = read_point_cloud(input_path, &info);
    PointsBuildReport report = build_points(std::move(cloud), output_path, settings, info.z_up);
    report.dropped_input = info.dropped;
    return report;
}

}  // namespace catpaq
