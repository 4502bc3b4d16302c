// The point converter's out-of-core store (out_of_core.h).
#include "out_of_core.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "base/error.h"
#include "base/progress.h"
#include "base/temp_file.h"

namespace catpaq::points_detail {

namespace {

constexpr size_t kBlockPoints = size_t(1) << 16;  // points read from a scratch file at a time
constexpr size_t kBuckets = size_t(1) << 16;      // a histogram of 16 bits of a key

// The bucket of a histogram holding rank `rank` (0-based), and how many come before it.
uint32_t bucket_of_rank(const uint32_t* counts, uint64_t rank, uint64_t* before) {
    uint32_t bucket = 0;
    uint64_t sum = 0;
    while (sum + counts[bucket] <= rank) sum += counts[bucket++];
    *before = sum;
    return bucket;
}

template <class T>
void write_array(TempFile* file, uint64_t first, const T* data, size_t count) {
    if (file && count) file->write_at(first * sizeof(T), data, count * sizeof(T));
}

template <class T>
std::vector<T> read_array(const TempFile* file, uint64_t first, size_t count) {
    std::vector<T> out;
    if (!file) return out;
    out.resize(count);
    if (count) file->read_at(first * sizeof(T), out.data(), count * sizeof(T));
    return out;
}

}  // namespace

// A node of the top of the tree: decided (a split, children in top_) or not yet, or a chunk.
struct OutOfCorePoints::TopNode {
    uint64_t key = 1;
    int depth = 0;
    uint64_t count = 0;
    int32_t left = -1, right = -1;
    int axis = 0;
    bool by_rank = false;
    float plane = 0;         // a plane split: p[axis] < plane goes left
    uint64_t threshold = 0;  // a rank split: rank_order_key < threshold goes left
    bool chunk = false;
};

OutOfCorePoints::OutOfCorePoints(const std::string& near_path, const PartitionSettings& settings, size_t chunk_points,
                                 uint64_t histogram_bytes, Progress* progress)
    : near_path_(near_path),
      settings_(settings),
      chunk_points_(std::max(chunk_points, 4 * settings.node_points)),
      histogram_bytes_(histogram_bytes),
      progress_(progress) {}

OutOfCorePoints::~OutOfCorePoints() {
    for (const Mapped& m : mapped_) unmap_file(m.data, m.size);
}

void OutOfCorePoints::add(const PointCloud& batch) {
    const size_t n = batch.size();
    if (n == 0) return;
    if (!in_positions_) {
        summary_.normals = batch.has_normals();
        summary_.colors = batch.has_colors();
        summary_.radii = batch.has_radii();
        in_positions_ = std::make_unique<TempFile>(near_path_);
        if (summary_.normals) in_normals_ = std::make_unique<TempFile>(near_path_);
        if (summary_.colors) in_colors_ = std::make_unique<TempFile>(near_path_);
        if (summary_.radii) in_radii_ = std::make_unique<TempFile>(near_path_);
    }
    if (batch.has_normals() != summary_.normals || batch.has_colors() != summary_.colors ||
        batch.has_radii() != summary_.radii)
        fail("point batches disagree on their attributes (normals, colours, radii)");
    if (summary_.count + n >= (size_t(1) << 32)) fail("more than this converter's 2^32 points");
    const uint64_t first = summary_.count;
    write_array(in_positions_.get(), first, batch.positions.data(), n);
    write_array(in_normals_.get(), first, batch.normals.data(), batch.normals.size());
    write_array(in_colors_.get(), first, batch.colors.data(), batch.colors.size());
    write_array(in_radii_.get(), first, batch.radii.data(), batch.radii.size());
    for (const Vec3d& p : batch.positions) summary_.bounds.add(p);
    for (float r : batch.radii) summary_.largest_radius = std::max(summary_.largest_radius, r);
    summary_.count += n;
}

// Calls visit(p, index) for every input point in input order: p its position relative to the
// origin as the in-core partition's items hold it (the float of the double difference, written
// once to split_positions_ so that the passes read half the bytes).
// Each block's points are visited in parallel, visit(tally, p, index) counting into a tally of
// its thread's (make_tally() makes one); returns the tallies, for the caller to add up.
template <class Tally, class MakeTally, class Visit>
std::vector<Tally> OutOfCorePoints::for_each_input(MakeTally make_tally, Visit visit) {
    tbb::enumerable_thread_specific<Tally> tallies(make_tally);
    std::vector<float> block(3 * kBlockPoints);
    for (size_t first = 0; first < summary_.count; first += kBlockPoints) {
        const size_t m = std::min(kBlockPoints, summary_.count - first);
        split_positions_->read_at(first * 12, block.data(), m * 12);
        tbb::parallel_for(tbb::blocked_range<size_t>(0, m, 4096), [&](const tbb::blocked_range<size_t>& r) {
            Tally& tally = tallies.local();
            for (size_t i = r.begin(); i < r.end(); ++i) visit(tally, &block[3 * i], uint32_t(first + i));
        });
        if (progress_) progress_->add(m);
    }
    ++split_passes_;
    return std::vector<Tally>(tallies.begin(), tallies.end());
}

// The floats the passes read, from the doubles in input order.
void OutOfCorePoints::write_split_positions() {
    split_positions_ = std::make_unique<TempFile>(near_path_);
    std::vector<Vec3d> block(kBlockPoints);
    std::vector<float> out(3 * kBlockPoints);
    for (size_t first = 0; first < summary_.count; first += kBlockPoints) {
        const size_t m = std::min(kBlockPoints, summary_.count - first);
        in_positions_->read_at(first * sizeof(Vec3d), block.data(), m * sizeof(Vec3d));
        for (size_t i = 0; i < m; ++i)
            for (int a = 0; a < 3; ++a) out[3 * i + a] = float(block[i][a] - origin_[a]);
        split_positions_->write_at(first * 12, out.data(), m * 12);
    }
}

// The top node a point belongs to: down the decided splits.
uint32_t OutOfCorePoints::classify(const float p[3], uint32_t index) const {
    uint32_t t = 0;
    while (top_[t].left >= 0) {
        const TopNode& node = top_[t];
        PartitionItem item{{p[0], p[1], p[2]}, index};
        const bool left = node.by_rank ? rank_order_key(item, node.axis) < node.threshold : p[node.axis] < node.plane;
        t = uint32_t(left ? node.left : node.right);
    }
    return t;
}

namespace {

// The value of rank `rank` among 32-bit values, found `width` bits a pass from the top: each
// pass histograms the next bits of the values that share the bits found so far.
struct DigitSelect {
    uint64_t rank = 0;    // within the values that share the prefix
    uint32_t prefix = 0;  // the top `known` bits of the value
    int known = 0;
    bool done() const { return known == 32; }
    int step(int width) const { return std::min(width, 32 - known); }
    // The histogram bucket of v, or -1 if v does not share the prefix.
    int64_t bucket(uint32_t v, int width) const {
        if (known > 0 && (v >> (32 - known)) != prefix) return -1;
        const int bits = step(width);
        return int64_t((v >> (32 - known - bits)) & ((uint32_t(1) << bits) - 1));
    }
    void advance(const uint32_t* counts, int width) {
        uint64_t before = 0;
        const int bits = step(width);
        const uint32_t b = bucket_of_rank(counts, rank, &before);
        prefix = prefix << bits | b;  // prefix is 0 before the first digit
        rank -= before;
        known += bits;
    }
};

}  // namespace

// Decides the splits of a group of undecided top nodes by passes over the input: the same
// decisions partition.h's Partitioner takes from the same points (tight box, medians, counts
// below planes, and for splits by rank the input index that completes the threshold).
void OutOfCorePoints::decide_group(const std::vector<uint32_t>& group, int width) {
    const size_t g = group.size(), buckets = size_t(1) << width;
    std::vector<int32_t> slot_of(top_.size(), -1);
    for (size_t s = 0; s < g; ++s) slot_of[group[s]] = int32_t(s);
    auto slot_for = [&](const float p[3], uint32_t index) -> int32_t {
        const uint32_t t = classify(p, index);
        return t < slot_of.size() ? slot_of[t] : -1;
    };
    struct Slot {
        uint64_t n = 0;
        float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
        DigitSelect median[3];  // the order key of rank n/2, per axis
        // Planes whose counts below are wanted (at most the three axes' and the midpoint's).
        int count_axis[4] = {0, 0, 0, 0};
        float count_plane[4] = {0, 0, 0, 0};
        uint64_t below[4] = {0, 0, 0, 0};
        int counts = 0;
        int rank_axis = -1;  // a split by rank on this axis
        DigitSelect tie;     // its threshold's input index, among the points of the median's key
        uint64_t left_count = 0;
    };
    std::vector<Slot> slots(g);
    for (size_t s = 0; s < g; ++s)
        for (int a = 0; a < 3; ++a) slots[s].median[a].rank = top_[group[s]].count / 2;
    // What a pass counts, per thread (added up after it): histograms of the group's selections
    // (three per node), and in the first pass the nodes' counts and tight boxes.
    struct Tally {
        std::vector<uint32_t> hist;
        std::vector<uint64_t> n;
        std::vector<std::array<float, 6>> box;  // lo, hi
        std::vector<std::array<uint64_t, 4>> below;
    };
    auto make_tally = [&] {
        Tally t;
        t.hist.assign(g * 3 * buckets, 0);
        t.n.assign(g, 0);
        t.box.assign(g, {INFINITY, INFINITY, INFINITY, -INFINITY, -INFINITY, -INFINITY});
        t.below.assign(g, {0, 0, 0, 0});
        return t;
    };
    std::vector<uint32_t> hist(g * 3 * buckets);
    auto counts_of = [&](size_t s, int j) { return &hist[(s * 3 + size_t(j)) * buckets]; };
    auto add_histograms = [&](const std::vector<Tally>& tallies) {
        std::fill(hist.begin(), hist.end(), 0u);
        for (const Tally& t : tallies)
            for (size_t i = 0; i < hist.size(); ++i) hist[i] += t.hist[i];
    };

    // The medians' keys, `width` bits a pass; the first pass also finds the tight boxes.
    for (bool first = true; !slots[0].median[0].done(); first = false) {
        const std::vector<Tally> tallies = for_each_input<Tally>(make_tally, [&](Tally& t, const float p[3], uint32_t index) {
            const int32_t s = slot_for(p, index);
            if (s < 0) return;
            const Slot& slot = slots[size_t(s)];
            if (first) {
                ++t.n[size_t(s)];
                for (int a = 0; a < 3; ++a) {
                    t.box[size_t(s)][a] = std::min(t.box[size_t(s)][a], p[a]);
                    t.box[size_t(s)][3 + a] = std::max(t.box[size_t(s)][3 + a], p[a]);
                }
            }
            for (int a = 0; a < 3; ++a) {
                const int64_t b = slot.median[a].bucket(float_order_key(p[a]), width);
                if (b >= 0) ++t.hist[(size_t(s) * 3 + size_t(a)) * buckets + size_t(b)];
            }
        });
        add_histograms(tallies);
        if (first)
            for (const Tally& t : tallies)
                for (size_t s = 0; s < g; ++s) {
                    slots[s].n += t.n[s];
                    for (int a = 0; a < 3; ++a) {
                        slots[s].lo[a] = std::min(slots[s].lo[a], t.box[s][a]);
                        slots[s].hi[a] = std::max(slots[s].hi[a], t.box[s][3 + a]);
                    }
                }
        for (size_t s = 0; s < g; ++s) {
            if (first && slots[s].n != top_[group[s]].count)
                fail("out-of-core partition: a node's points changed between passes");
            for (int a = 0; a < 3; ++a) slots[s].median[a].advance(counts_of(s, a), width);
        }
    }

    // The planes each rule would try; their counts below decide between them.
    struct Plan {
        bool rank_only = false;  // deep nodes split by rank on x
        bool balanced = false;
        float planes[3] = {0, 0, 0};
        bool evaluated[3] = {false, false, false};
        bool exact_median[3] = {false, false, false};
        int count_index[4] = {-1, -1, -1, -1};  // per axis, and the midpoint's [3]
        int mid_axis = 0;
        float mid_plane = 0;
    };
    std::vector<Plan> plans(g);
    auto want_count = [](Slot& slot, int axis, float plane) {
        slot.count_axis[slot.counts] = axis;
        slot.count_plane[slot.counts] = plane;
        return slot.counts++;
    };
    for (size_t s = 0; s < g; ++s) {
        Slot& slot = slots[s];
        Plan& plan = plans[s];
        if (top_[group[s]].depth >= kMidpointMaxDepth) {
            plan.rank_only = true;
            continue;
        }
        plan.mid_axis = longest_axis(slot.lo, slot.hi);
        plan.mid_plane = 0.5f * (slot.lo[plan.mid_axis] + slot.hi[plan.mid_axis]);
        plan.count_index[3] = want_count(slot, plan.mid_axis, plan.mid_plane);
        if (settings_.split != PointSplitRule::Balanced) continue;
        plan.balanced = true;
        const float margin = balanced_margin(slot.lo, slot.hi, settings_.max_aspect);
        for (int a = 0; a < 3; ++a) {
            if (slot.hi[a] - slot.lo[a] < 2 * margin) continue;
            const float median = float_from_order_key(slot.median[a].prefix);
            const float plane = std::clamp(median, slot.lo[a] + margin, slot.hi[a] - margin);
            plan.evaluated[a] = true;
            plan.planes[a] = plane;
            plan.exact_median[a] = plane == median;
            if (!plan.exact_median[a]) plan.count_index[a] = want_count(slot, a, plane);
        }
    }
    for (const Tally& t : for_each_input<Tally>(make_tally, [&](Tally& t, const float p[3], uint32_t index) {
             const int32_t s = slot_for(p, index);
             if (s < 0) return;
             const Slot& slot = slots[size_t(s)];
             for (int c = 0; c < slot.counts; ++c) t.below[size_t(s)][c] += p[slot.count_axis[c]] < slot.count_plane[c];
         }))
        for (size_t s = 0; s < g; ++s)
            for (int c = 0; c < 4; ++c) slots[s].below[c] += t.below[s][c];

    // The decisions; splits by rank still need their threshold's input index.
    for (size_t s = 0; s < g; ++s) {
        Slot& slot = slots[s];
        const Plan& plan = plans[s];
        TopNode& node = top_[group[s]];
        auto by_plane = [&](int axis, float plane, uint64_t below) {
            if (below == 0 || below == slot.n) {
                slot.rank_axis = axis;
                return;
            }
            node.axis = axis;
            node.plane = plane;
            node.by_rank = false;
            slot.left_count = below;
        };
        if (plan.rank_only) {
            slot.rank_axis = 0;
        } else if (plan.balanced) {
            uint64_t imbalance[3] = {UINT64_MAX, UINT64_MAX, UINT64_MAX};
            for (int a = 0; a < 3; ++a)
                if (plan.evaluated[a])
                    imbalance[a] = plan.exact_median[a] ? 0 : split_imbalance(slot.below[plan.count_index[a]], slot.n);
            const int axis = balanced_axis(slot.lo, slot.hi, imbalance);
            if (axis < 0)
                by_plane(plan.mid_axis, plan.mid_plane, slot.below[plan.count_index[3]]);
            else if (imbalance[axis] == 0)
                slot.rank_axis = axis;
            else
                by_plane(axis, plan.planes[axis], slot.below[plan.count_index[axis]]);
        } else {
            by_plane(plan.mid_axis, plan.mid_plane, slot.below[plan.count_index[3]]);
        }
        // The threshold is the point of rank n/2 in (key, index): among the points whose key is
        // the median's, the one of rank n/2 - (points whose key is below the median's).
        if (slot.rank_axis >= 0) slot.tie.rank = slot.median[slot.rank_axis].rank;
    }
    auto ranked = [&](size_t s) { return slots[s].rank_axis >= 0; };
    bool any_rank = false;
    for (size_t s = 0; s < g; ++s) any_rank |= ranked(s);
    while (any_rank) {
        add_histograms(for_each_input<Tally>(make_tally, [&](Tally& t, const float p[3], uint32_t index) {
            const int32_t s = slot_for(p, index);
            if (s < 0 || !ranked(size_t(s))) return;
            const Slot& slot = slots[size_t(s)];
            const int a = slot.rank_axis;
            if (float_order_key(p[a]) != slot.median[a].prefix) return;
            const int64_t b = slot.tie.bucket(index, width);
            if (b >= 0) ++t.hist[size_t(s) * 3 * buckets + size_t(b)];
        }));
        bool done = true;
        for (size_t s = 0; s < g; ++s)
            if (ranked(s)) {
                slots[s].tie.advance(counts_of(s, 0), width);
                done &= slots[s].tie.done();
            }
        if (done) break;
    }
    // The children.
    for (size_t s = 0; s < g; ++s) {
        const Slot& slot = slots[s];
        const uint32_t t = group[s];
        if (slot.rank_axis >= 0) {
            TopNode& node = top_[t];
            node.axis = slot.rank_axis;
            node.by_rank = true;
            node.threshold = uint64_t(slot.median[slot.rank_axis].prefix) << 32 | slot.tie.prefix;
        }
        const uint64_t left_count = slot.rank_axis >= 0 ? slot.n / 2 : slot.left_count;
        for (int side = 0; side < 2; ++side) {
            TopNode child;
            child.key = 2 * top_[t].key + uint64_t(side);
            child.depth = top_[t].depth + 1;
            child.count = side == 0 ? left_count : top_[t].count - left_count;
            child.chunk = child.count <= chunk_points_;
            top_.push_back(child);
        }
        top_[t].left = int32_t(top_.size() - 2);
        top_[t].right = int32_t(top_.size() - 1);
    }
}

// Level by level, in groups whose histograms fit the allowance: 16-bit digits (two passes a
// 32-bit value) when a whole level fits so, else 11-bit digits (three passes) for larger groups.
void OutOfCorePoints::decide_top_splits() {
    TopNode root;
    root.count = summary_.count;
    root.chunk = root.count <= chunk_points_;
    top_.push_back(root);
    std::vector<uint32_t> pending;
    if (!root.chunk) pending.push_back(0);
    while (!pending.empty()) {
        for (const uint32_t t : pending)
            if (top_[t].depth >= kPointMaxDepth) fail("the point hierarchy would be deeper than %d levels", kPointMaxDepth);
        const uint64_t wide = 3 * (uint64_t(1) << 16) * sizeof(uint32_t), narrow = 3 * (uint64_t(1) << 11) * sizeof(uint32_t);
        // A histogram per thread of the passes and one for their sum.
        const uint64_t copies = uint64_t(tbb::this_task_arena::max_concurrency()) + 1;
        const int width = pending.size() * wide * copies <= histogram_bytes_ ? 16 : 11;
        const size_t group_size = size_t(std::max<uint64_t>(1, histogram_bytes_ / ((width == 16 ? wide : narrow) * copies)));
        for (size_t first = 0; first < pending.size(); first += group_size) {
            const size_t last = std::min(pending.size(), first + group_size);
            decide_group(std::vector<uint32_t>(pending.begin() + ptrdiff_t(first), pending.begin() + ptrdiff_t(last)), width);
        }
        std::vector<uint32_t> next;
        for (const uint32_t t : pending)
            for (const int32_t child : {top_[t].left, top_[t].right})
                if (!top_[size_t(child)].chunk) next.push_back(uint32_t(child));
        pending.swap(next);
    }
}

// Sends every point to its chunk's region of the chunk files (input order within a chunk).
void OutOfCorePoints::distribute() {
    // Chunks in tree order, each with its region.
    std::vector<int32_t> chunk_of(top_.size(), -1);
    std::vector<uint64_t> cursor;
    {
        std::vector<uint32_t> stack = {0};
        uint64_t begin = 0;
        chunk_begin_.assign(top_.size(), 0);
        while (!stack.empty()) {
            const uint32_t t = stack.back();
            stack.pop_back();
            if (top_[t].chunk) {
                chunk_of[t] = int32_t(cursor.size());
                chunk_begin_[t] = uint32_t(begin);
                cursor.push_back(begin);
                begin += top_[t].count;
                continue;
            }
            stack.push_back(uint32_t(top_[t].right));
            stack.push_back(uint32_t(top_[t].left));
        }
    }
    chunk_count_ = cursor.size();
    chunk_positions_ = std::make_unique<TempFile>(near_path_);
    chunk_indices_ = std::make_unique<TempFile>(near_path_);
    if (summary_.normals) chunk_normals_ = std::make_unique<TempFile>(near_path_);
    if (summary_.colors) chunk_colors_ = std::make_unique<TempFile>(near_path_);
    if (summary_.radii) chunk_radii_ = std::make_unique<TempFile>(near_path_);

    struct Buffer {
        std::vector<Vec3d> positions;
        std::vector<uint32_t> indices;
        std::vector<Vec3f> normals;
        std::vector<Rgb8> colors;
        std::vector<float> radii;
    };
    const size_t record = sizeof(Vec3d) + 4 + sizeof(Vec3f) + sizeof(Rgb8) + 4;
    const size_t buffer_points = std::clamp<size_t>(size_t(histogram_bytes_ / (chunk_count_ * record)), 64, kBlockPoints);
    std::vector<Buffer> buffers(chunk_count_);
    auto flush = [&](size_t c) {
        Buffer& b = buffers[c];
        const uint64_t first = cursor[c];
        write_array(chunk_positions_.get(), first, b.positions.data(), b.positions.size());
        write_array(chunk_indices_.get(), first, b.indices.data(), b.indices.size());
        write_array(chunk_normals_.get(), first, b.normals.data(), b.normals.size());
        write_array(chunk_colors_.get(), first, b.colors.data(), b.colors.size());
        write_array(chunk_radii_.get(), first, b.radii.data(), b.radii.size());
        cursor[c] += b.positions.size();
        b.positions.clear(), b.indices.clear(), b.normals.clear(), b.colors.clear(), b.radii.clear();
    };
    std::vector<uint32_t> chunk_ids(kBlockPoints);
    for (size_t first = 0; first < summary_.count; first += kBlockPoints) {
        const size_t m = std::min(kBlockPoints, summary_.count - first);
        const std::vector<Vec3d> positions = read_array<Vec3d>(in_positions_.get(), first, m);
        const std::vector<Vec3f> normals = read_array<Vec3f>(in_normals_.get(), first, m);
        const std::vector<Rgb8> colors = read_array<Rgb8>(in_colors_.get(), first, m);
        const std::vector<float> radii = read_array<float>(in_radii_.get(), first, m);
        // Where each point goes, in parallel; then appended in input order.
        tbb::parallel_for(tbb::blocked_range<size_t>(0, m, 4096), [&](const tbb::blocked_range<size_t>& r) {
            for (size_t i = r.begin(); i < r.end(); ++i) {
                float f[3];
                for (int a = 0; a < 3; ++a) f[a] = float(positions[i][a] - origin_[a]);
                chunk_ids[i] = uint32_t(chunk_of[classify(f, uint32_t(first + i))]);
            }
        });
        for (size_t i = 0; i < m; ++i) {
            Vec3d p;
            for (int a = 0; a < 3; ++a) p[a] = positions[i][a] - origin_[a];
            const uint32_t index = uint32_t(first + i);
            const size_t c = chunk_ids[i];
            Buffer& b = buffers[c];
            b.positions.push_back(p);
            b.indices.push_back(index);
            if (!normals.empty()) b.normals.push_back(normals[i]);
            if (!colors.empty()) b.colors.push_back(colors[i]);
            if (!radii.empty()) b.radii.push_back(radii[i]);
            if (b.positions.size() >= buffer_points) flush(c);
        }
        if (progress_) progress_->add(m);
    }
    for (size_t c = 0; c < chunk_count_; ++c) flush(c);
    in_positions_.reset(), in_normals_.reset(), in_colors_.reset(), in_radii_.reset();
}

// Partitions one chunk in core (partition.h) and writes its points, in their final order, to
// the partition-order files from `begin`; appends its nodes to `out`.
void OutOfCorePoints::partition_chunk(uint32_t t, uint32_t begin, std::vector<HNode>& out) {
    const TopNode& top = top_[t];
    const size_t n = size_t(top.count);
    const uint64_t first = chunk_begin_[t];
    const std::vector<uint32_t> indices = read_array<uint32_t>(chunk_indices_.get(), first, n);
    std::vector<HNode> sub;
    std::vector<uint32_t> local(n);
    {
        const std::vector<Vec3d> positions = read_array<Vec3d>(chunk_positions_.get(), first, n);
        Items items(n);
        for (size_t i = 0; i < n; ++i) {
            for (int a = 0; a < 3; ++a) items[i].p[a] = float(positions[i][a]);
            items[i].index = indices[i];
        }
        sub = partition_items(items, 0, uint32_t(n), top.key, top.depth, settings_, progress_);
        // The chunk holds its points in input order: an input index's rank among the chunk's
        // is where its data is.
        for (size_t i = 0; i < n; ++i)
            local[i] = uint32_t(std::lower_bound(indices.begin(), indices.end(), items[i].index) - indices.begin());
        std::vector<Vec3d> permuted(n);
        std::vector<float> xyz(3 * n);
        for (size_t i = 0; i < n; ++i) {
            permuted[i] = positions[local[i]];
            for (int a = 0; a < 3; ++a) xyz[3 * i + a] = float(permuted[i][a]);
        }
        write_array(positions_.get(), begin, permuted.data(), n);
        write_array(xyz_.get(), uint64_t(begin) * 3, xyz.data(), 3 * n);
        // Leaf boxes, for the halo searches.
        for (HNode& node : sub) {
            if (node.left >= 0) continue;
            for (int a = 0; a < 3; ++a) node.lo[a] = INFINITY, node.hi[a] = -INFINITY;
            for (uint32_t p = node.begin; p < node.end; ++p)
                for (int a = 0; a < 3; ++a) {
                    node.lo[a] = std::min(node.lo[a], xyz[3 * size_t(p) + a]);
                    node.hi[a] = std::max(node.hi[a], xyz[3 * size_t(p) + a]);
                }
        }
    }
    auto permute_to = [&](auto values, TempFile* file, auto fill) {
        using T = typename decltype(values)::value_type;
        std::vector<T> out_values(n, fill);
        if (!values.empty())
            for (size_t i = 0; i < n; ++i) out_values[i] = values[local[i]];
        write_array(file, begin, out_values.data(), n);
    };
    permute_to(read_array<Vec3f>(chunk_normals_.get(), first, n), normals_.get(), Vec3f{0, 0, 1});
    if (colors_) permute_to(read_array<Rgb8>(chunk_colors_.get(), first, n), colors_.get(), Rgb8{0, 0, 0});
    permute_to(read_array<float>(chunk_radii_.get(), first, n), radii_.get(), 0.0f);
    const int32_t base = int32_t(out.size());
    for (HNode node : sub) {
        node.begin += begin;
        node.end += begin;
        if (node.left >= 0) node.left += base, node.right += base;
        out.push_back(node);
    }
    chunk_root_.resize(out.size(), 0);
    chunk_root_[size_t(base)] = 1;
}

// The node array in the in-core partition's order: a node, its left subtree, its right one.
void OutOfCorePoints::emit(uint32_t t, std::vector<HNode>& out, uint32_t& next_begin) {
    const TopNode& top = top_[t];
    if (top.chunk) {
        partition_chunk(t, next_begin, out);
        next_begin += uint32_t(top.count);
        return;
    }
    const size_t at = out.size();
    HNode node;
    node.begin = next_begin;
    node.end = uint32_t(next_begin + top.count);
    node.key = top.key;
    node.depth = top.depth;
    out.push_back(node);
    chunk_root_.resize(out.size(), 0);
    out[at].left = int32_t(out.size());
    emit(uint32_t(top.left), out, next_begin);
    out[at].right = int32_t(out.size());
    emit(uint32_t(top.right), out, next_begin);
}

void OutOfCorePoints::partition(const double origin[3]) {
    std::copy(origin, origin + 3, origin_);
    if (progress_) progress_->phase("splitting", 0, "pt");
    if (summary_.count > chunk_points_) write_split_positions();
    decide_top_splits();
    split_positions_.reset();
    if (progress_) progress_->phase("distributing", summary_.count, "pt");
    distribute();
    positions_ = std::make_unique<TempFile>(near_path_);
    normals_ = std::make_unique<TempFile>(near_path_);
    if (summary_.colors) colors_ = std::make_unique<TempFile>(near_path_);
    radii_ = std::make_unique<TempFile>(near_path_);
    xyz_ = std::make_unique<TempFile>(near_path_);
    if (progress_) progress_->phase("partitioning", summary_.count, "pt");
    uint32_t next_begin = 0;
    nodes_.clear();
    emit(0, nodes_, next_begin);
    chunk_positions_.reset(), chunk_indices_.reset(), chunk_normals_.reset(), chunk_colors_.reset(), chunk_radii_.reset();
    map_arrays();
}

void OutOfCorePoints::map_arrays() {
    const uint64_t n = summary_.count;
    auto map = [&](TempFile* file, uint64_t bytes) -> void* {
        void* data = file->map(bytes);
        mapped_.push_back({data, bytes});
        return data;
    };
    arrays_.positions = static_cast<const Vec3d*>(map(positions_.get(), n * sizeof(Vec3d)));
    arrays_.normals = static_cast<Vec3f*>(map(normals_.get(), n * sizeof(Vec3f)));
    arrays_.colors = colors_ ? static_cast<const Rgb8*>(map(colors_.get(), n * sizeof(Rgb8))) : nullptr;
    arrays_.radii = static_cast<float*>(map(radii_.get(), n * sizeof(float)));
    arrays_.xyz = static_cast<const float*>(map(xyz_.get(), n * 3 * sizeof(float)));
}

void OutOfCorePoints::release_pages() {
    for (const Mapped& m : mapped_) release_mapped_pages(m.data, m.size);
}

}  // namespace catpaq::points_detail
