// Proximity merging of splats (splat.h): a greedy collapse over the k-nearest-neighbour graph
// with a lazily refreshed heap. A merge changes the survivor, so the edges that touch it become
// stale; rather than finding and updating them, every heap entry carries the count of merges
// done when it was pushed (its ends changed since are marked later), and a stale entry popped is
// re-priced and pushed again. Merged
// splats are found through a union-find (an edge to a merged splat leads to its survivor).
#include <algorithm>
#include <cassert>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>

#include "grid_knn.h"
#include "splat.h"
#include "std_order_heap.h"

namespace catpaq::points_detail {
namespace {

constexpr size_t kNeighbours = 4;
constexpr float kOpposedNormalCost = 4.0f;
// Splats per occupied cell of the neighbour search's grid (grid_knn.h), for k = 4 (1.5 to 4
// measured within noise of each other).
constexpr double kSplatsPerCell = 2;

double distance(const double* a, const double* b) {
    double dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
    return std::sqrt(dx * dx + dy * dy + dz * dz);
}

// Radius of the smallest ball holding both splats' balls.
double merged_radius(const Splat& a, const Splat& b) {
    double d = distance(a.p, b.p);
    return std::max({double(a.radius), double(b.radius), 0.5 * (d + a.radius + b.radius)});
}

float merge_cost(const Splat& a, const Splat& b) {
    float cost = float(merged_radius(a, b));
    float dot = a.n[0] * b.n[0] + a.n[1] * b.n[1] + a.n[2] * b.n[2];
    return dot < 0 ? cost * kOpposedNormalCost : cost;
}

struct Edge {
    float cost;
    uint32_t a, b;
    uint32_t stamp;  // the merges done when it was priced: stale if either end merged since
    bool operator<(const Edge& o) const {  // for a min-heap by cost (ties: by index, deterministic)
        if (cost != o.cost) return cost > o.cost;
        if (a != o.a) return a > o.a;
        return b > o.b;
    }
};

static_assert(sizeof(Edge) == 16);

// Edge::operator< for the heap, without its branches: (cost, a) as one key (a positive float's
// bits order as it does), b on ties.
struct CostlierEdge {
    static uint64_t key(const Edge& e) {
        uint32_t bits;
        std::memcpy(&bits, &e.cost, 4);
        return uint64_t(bits) << 32 | e.a;
    }
    bool operator()(const Edge& x, const Edge& y) const {
        const uint64_t kx = key(x), ky = key(y);
        return kx > ky || (kx == ky && x.b > y.b);
    }
};

// Sorts edges cheapest first, ties by a then b: the order of std::sort with Edge::operator<
// reversed, by an LSD radix sort on (cost's bits, a) (costs are positive floats, whose bits
// order as they do), then runs of equal (cost, a) by b. Written out because the comparison
// sort was the simplifier's largest part after the neighbour search (6% of the conversion's
// instructions, more of its time: its branches mispredict).
void sort_edges(std::vector<Edge>& edges, std::vector<Edge>& scratch) {
    const size_t n = edges.size();
    auto key = [](const Edge& e) {
        uint32_t bits;
        std::memcpy(&bits, &e.cost, 4);
        return (uint64_t(bits) << 32) | e.a;
    };
    auto by_key = [&](const Edge& x, const Edge& y) {
        const uint64_t kx = key(x), ky = key(y);
        return kx != ky ? kx < ky : x.b < y.b;
    };
    if (n < 256) {
        std::sort(edges.begin(), edges.end(), by_key);
        return;
    }
    std::vector<std::array<uint32_t, 256>> counts(8);
    for (auto& c : counts) c.fill(0);
    for (const Edge& e : edges) {
        const uint64_t k = key(e);
        for (int pass = 0; pass < 8; ++pass) ++counts[size_t(pass)][(k >> (8 * pass)) & 255];
    }
    scratch.resize(n);
    for (int pass = 0; pass < 8; ++pass) {
        std::array<uint32_t, 256>& c = counts[size_t(pass)];
        if (c[(key(edges[0]) >> (8 * pass)) & 255] == n) continue;  // one byte value: already in order
        uint32_t sum = 0;
        for (uint32_t& v : c) {
            const uint32_t count = v;
            v = sum;
            sum += count;
        }
        for (const Edge& e : edges) scratch[c[(key(e) >> (8 * pass)) & 255]++] = e;
        edges.swap(scratch);
    }
    for (size_t i = 0; i + 1 < n;) {
        size_t j = i + 1;
        while (j < n && key(edges[j]) == key(edges[i])) ++j;
        if (j - i > 1) std::sort(edges.begin() + ptrdiff_t(i), edges.begin() + ptrdiff_t(j), by_key);
        i = j;
    }
}

// Sorts distinct 64-bit keys ascending: an LSD radix sort in 11-bit digits of the high 32 bits
// only (a digit all keys share skipped), then runs of equal high halves (rare) sorted whole. For
// the edges of splats numbered below 2^16, whose (cost, a, b) pack into one key: the cost's bits
// order nearly all of them, and its three digits halve the passes of a sort over all six (the
// scatter was 2.5% of the 1M scan's conversion time).
void sort_keys(std::vector<uint64_t>& keys, std::vector<uint64_t>& scratch) {
    constexpr int kDigitBits = 11, kDigits = 3, kFirstBit = 32;  // bits 32-64
    constexpr size_t kBuckets = size_t(1) << kDigitBits;
    const size_t n = keys.size();
    if (n < 256) {
        std::sort(keys.begin(), keys.end());
        return;
    }
    std::vector<uint32_t> counts(kDigits * kBuckets, 0);
    for (const uint64_t k : keys)
        for (int d = 0; d < kDigits; ++d)
            ++counts[size_t(d) * kBuckets + ((k >> (kFirstBit + kDigitBits * d)) & (kBuckets - 1))];
    scratch.resize(n);
    for (int d = 0; d < kDigits; ++d) {
        uint32_t* c = &counts[size_t(d) * kBuckets];
        const int shift = kFirstBit + kDigitBits * d;
        if (c[(keys[0] >> shift) & (kBuckets - 1)] == n) continue;  // one digit value: in order already
        uint32_t sum = 0;
        for (size_t v = 0; v < kBuckets; ++v) {
            const uint32_t count = c[v];
            c[v] = sum;
            sum += count;
        }
        for (const uint64_t k : keys) scratch[c[(k >> shift) & (kBuckets - 1)]++] = k;
        keys.swap(scratch);
    }
    for (size_t i = 0; i + 1 < n;) {
        if ((keys[i] ^ keys[i + 1]) >> kFirstBit) {
            ++i;
            continue;
        }
        size_t j = i + 2;
        while (j < n && !((keys[j] ^ keys[i]) >> kFirstBit)) ++j;
        std::sort(keys.begin() + ptrdiff_t(i), keys.begin() + ptrdiff_t(j));
        i = j;
    }
}

// The re-priced edges of a node of at most 2^16 splats, cheapest first: a radix heap (Ahuja,
// Mehlhorn, Orlin and Tarjan 1990) on the packed key (cost bits, a, b), a total order on the
// edges. An edge in bucket k differs from the heap's floor (`last_`, its cheapest key when it
// was last settled) first at bit k - 1 (bucket 0: equal to it), so a push is an append and only
// the lowest bucket is ever looked into; an edge moves down a bucket at most once per bit, and
// most never move: about two thirds of the edges pushed are never taken (the node reaches its
// size first). The binary heap it replaced sifted each of them (a quarter of the loop's time).
//
// A radix heap wants keys no smaller than its floor. Re-pricing after a merge almost always
// raises an edge's cost (the merged ball holds both balls), but a key may fall below the floor:
// a cost that fell (the survivor's normal turned, kOpposedNormalCost), or one between the last
// edge taken and a floor that a look at the top raised. Those go to `below_`, a binary heap taken
// from first (its keys are below everything in the buckets): 1.1% of the pushes on the 1M scan.
class RadixEdgeQueue {
public:
    static uint64_t key(const Edge& e) {
        uint32_t bits;
        std::memcpy(&bits, &e.cost, 4);
        return uint64_t(bits) << 32 | uint64_t(e.a) << 16 | e.b;
    }

    bool empty() const { return size_ == 0 && below_.empty(); }

    void clear() {
        for (auto& b : buckets_) b.clear();
        below_.clear();
        size_ = 0;
        last_ = 0;
        min_ = UINT64_MAX;
        min_known_ = true;
    }

    void push(const Edge& e) {
        const uint64_t k = key(e);
        if (k < last_) {
            below_.push(e);
            return;
        }
        buckets_[bucket(k)].push_back(e);
        ++size_;
        if (k < min_) min_ = k;  // (an unknown minimum stays unknown: it is found when asked)
    }

    // The cheapest edge. Not empty.
    const Edge& top() {
        if (!below_.empty()) return below_.top();
        settle();
        return buckets_[0].back();
    }

    Edge pop() {
        if (!below_.empty()) return below_.pop();
        settle();
        const Edge e = buckets_[0].back();
        buckets_[0].pop_back();
        --size_;
        if (buckets_[0].empty()) min_known_ = false;
        return e;
    }

private:
    size_t bucket(uint64_t k) const { return k == last_ ? 0 : size_t(64 - std::countl_zero(k ^ last_)); }

    // Brings the cheapest edges (all of that key) into bucket 0: the lowest bucket holds the
    // cheapest, whose key becomes `last_`; the bucket's other edges move to lower buckets.
    void settle() {
        if (!buckets_[0].empty()) return;
        size_t lowest = 1;
        while (buckets_[lowest].empty()) ++lowest;
        std::vector<Edge>& from = buckets_[lowest];
        if (!min_known_) {
            min_ = UINT64_MAX;
            for (const Edge& e : from) min_ = std::min(min_, key(e));
        }
        last_ = min_;
        min_known_ = true;
        for (const Edge& e : from) buckets_[bucket(key(e))].push_back(e);
        from.clear();
    }

    std::array<std::vector<Edge>, 65> buckets_;
    StdOrderHeap<Edge, CostlierEdge> below_;
    size_t size_ = 0;                // in the buckets
    uint64_t last_ = 0, min_ = UINT64_MAX;  // min_: the buckets' cheapest key, when min_known_
    bool min_known_ = true;
};

// The graph's edges come sorted once (cheapest first, a plain sort); only edges re-priced after
// a merge go through the heap. Each step takes the cheaper of the two fronts, so the merges are
// those of one heap holding everything, with far fewer heap operations.
struct Simplifier {
    std::vector<Splat>* splats_ = nullptr;
    // modified[i]: the count of merges done when splat i last changed (0: never). An edge is
    // stale when either end changed after its stamp, as the generations of both ends it carried
    // before said; one stamp makes an edge 16 bytes rather than 20 (the heap and the sorted
    // edges move less; the simplifier's loop was 10% of the 1M scan's conversion time).
    std::vector<uint32_t> parent, modified;
    uint32_t clock = 0;
    std::vector<Edge> sorted;  // cheapest first; sorted[next] is the next one not taken
    size_t next = 0;
    // Re-priced edges: a radix heap where the keys pack (splats numbered below 2^16), else a
    // binary heap.
    bool packed = true;
    RadixEdgeQueue radix;
    StdOrderHeap<Edge, CostlierEdge> heap;
    std::vector<Edge> scratch;  // sort_edges's
    std::vector<uint64_t> keys, key_scratch;  // sort_keys's
    std::vector<uint32_t> live, lists;        // connect_alive's
    std::vector<float> xyz;
    LocalKnn knn;
    size_t alive = 0;

    // Kept per thread and reset for each node (as estimate_leaf's scratch): the buffers above,
    // the grid's (its cell array up to 16 cells a splat) included, were allocated and zeroed
    // anew for each of the 1M scan's inner nodes.
    void reset(std::vector<Splat>& s) {
        splats_ = &s;
        parent.resize(s.size());
        for (size_t i = 0; i < s.size(); ++i) parent[i] = uint32_t(i);
        modified.assign(s.size(), 0);
        clock = 0;
        alive = s.size();
        packed = s.size() <= (size_t(1) << 16);
    }

    uint32_t find(uint32_t i) {
        while (parent[i] != i) {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        return i;
    }

    void push(uint32_t a, uint32_t b) {
        const std::vector<Splat>& splats = *splats_;
        const Edge e{merge_cost(splats[a], splats[b]), a, b, clock};
        if (packed) radix.push(e);
        else heap.push(e);
    }

    // Builds the proximity graph of the splats still alive.
    void connect_alive() {
        std::vector<Splat>& splats = *splats_;
        live.clear();
        for (uint32_t i = 0; i < splats.size(); ++i)
            if (parent[i] == i) live.push_back(i);
        xyz.resize(3 * live.size());
        for (size_t i = 0; i < live.size(); ++i)
            for (int a = 0; a < 3; ++a) xyz[3 * i + a] = float(splats[live[i]].p[a]);
        knn.build(xyz.data(), nullptr, live.size(), kSplatsPerCell);
        radix.clear();
        heap.clear();
        sorted.clear();
        next = 0;
        // Each point's nearest (itself first, then kNeighbours); an edge both ends list is kept
        // once, from its smaller end.
        const size_t stride = kNeighbours + 1;
        lists.assign(live.size() * stride, UINT32_MAX);
        knn.all_nearest(stride, [](uint32_t) { return true; },
                        [&](uint32_t i, const float*, size_t found, const uint32_t* index, const float*) {
                            std::copy(index, index + found, &lists[size_t(i) * stride]);
                        });
        auto lists_contain = [&](size_t i, uint32_t j) {
            for (size_t k = 0; k < stride; ++k)
                if (lists[i * stride + k] == j) return true;
            return false;
        };
        // Splats numbered below 2^16 (nodes of up to 32768 points): each edge as one key,
        // (cost bits, a, b), which sort as the edges do (a positive float's bits order as it
        // does) in 8 bytes rather than 20 and with no ties left; the edges are then rebuilt
        // from the keys. (Moving the edges themselves, the radix sort's scatter took 2.4% of
        // the conversion's time.)
        keys.clear();
        for (size_t i = 0; i < live.size(); ++i)
            for (size_t k = 0; k < stride; ++k) {
                uint32_t j = lists[i * stride + k];
                if (j == UINT32_MAX || j == i || (j < i && lists_contain(j, uint32_t(i)))) continue;
                uint32_t a = std::min(live[i], live[j]), b = std::max(live[i], live[j]);
                const float cost = merge_cost(splats[a], splats[b]);
                if (packed) {
                    uint32_t bits;
                    std::memcpy(&bits, &cost, 4);
                    keys.push_back(uint64_t(bits) << 32 | uint64_t(a) << 16 | b);
                } else {
                    sorted.push_back({cost, a, b, clock});
                }
            }
        if (packed) {
            sort_keys(keys, key_scratch);
            sorted.resize(keys.size());
            for (size_t e = 0; e < keys.size(); ++e) {
                const uint32_t bits = uint32_t(keys[e] >> 32), a = uint32_t(keys[e] >> 16) & 0xffff, b = uint32_t(keys[e]) & 0xffff;
                float cost;
                std::memcpy(&cost, &bits, 4);
                sorted[e] = {cost, a, b, clock};
            }
        } else {
            sort_edges(sorted, scratch);
        }
    }

    // The cheapest edge of either front, or false when both are empty.
    template <class Queue>
    bool take(Queue& queue, Edge& e) {
        if (next < sorted.size() && (queue.empty() || !(sorted[next] < queue.top()))) {
            e = sorted[next++];
            return true;
        }
        if (queue.empty()) return false;
        e = queue.pop();
        return true;
    }
    bool take(Edge& e) { return packed ? take(radix, e) : take(heap, e); }

    void run(size_t target) {
        std::vector<Splat>& splats = *splats_;
        connect_alive();
        while (alive > target) {
            Edge e;
            if (!take(e)) {  // the graph fell apart into pieces merged whole: connect what is left
                connect_alive();
                assert(!sorted.empty());
                continue;
            }
            uint32_t a = find(e.a), b = find(e.b);
            if (a == b) continue;
            if (a != e.a || b != e.b || modified[a] > e.stamp || modified[b] > e.stamp) {
                push(std::min(a, b), std::max(a, b));
                continue;
            }
            splats[a] = merge_splats(splats[a], splats[b]);
            parent[b] = a;
            modified[a] = ++clock;
            --alive;
        }
        size_t out = 0;
        for (size_t i = 0; i < splats.size(); ++i)
            if (parent[i] == i) splats[out++] = splats[i];
        splats.resize(out);
    }
};

}  // namespace

Splat merge_splats(const Splat& a, const Splat& b) {
    const double d = distance(a.p, b.p);
    Splat m;
    double radius;
    if (d + b.radius <= a.radius) {  // a's ball holds b's
        std::copy(a.p, a.p + 3, m.p);
        radius = a.radius;
    } else if (d + a.radius <= b.radius) {
        std::copy(b.p, b.p + 3, m.p);
        radius = b.radius;
    } else {
        radius = 0.5 * (d + a.radius + b.radius);
        double t = (radius - a.radius) / d;  // d > 0 here: equal centres fall in a case above
        for (int k = 0; k < 3; ++k) m.p[k] = a.p[k] + (b.p[k] - a.p[k]) * t;
    }
    // Rounded up so that the float radius still holds both balls.
    float r = float(radius);
    if (double(r) < radius) r = std::nextafter(r, INFINITY);
    m.radius = r;
    double cover = std::max(distance(m.p, a.p) + a.cover, distance(m.p, b.p) + b.cover);
    float c = float(cover);
    if (double(c) < cover) c = std::nextafter(c, INFINITY);
    m.cover = c;
    const float wa = a.weight, wb = b.weight, w = wa + wb;
    const float ta = w > 0 ? wa / w : 0.5f, tb = 1.0f - ta;
    float n[3], length2 = 0;
    for (int k = 0; k < 3; ++k) {
        n[k] = ta * a.n[k] + tb * b.n[k];
        length2 += n[k] * n[k];
    }
    if (length2 > 1e-12f) {
        float inv = 1.0f / std::sqrt(length2);
        for (int k = 0; k < 3; ++k) m.n[k] = n[k] * inv;
    } else {  // opposed normals of equal weight: keep one
        std::copy(a.n, a.n + 3, m.n);
    }
    for (int k = 0; k < 3; ++k) m.color[k] = ta * a.color[k] + tb * b.color[k];
    m.weight = w;
    return m;
}

void simplify_splats(std::vector<Splat>& splats, size_t target) {
    assert(target >= 1);
    if (splats.size() <= target) return;
    static thread_local Simplifier simplifier;
    simplifier.reset(splats);
    simplifier.run(target);
}

}  // namespace catpaq::points_detail
