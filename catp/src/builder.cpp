#include "catp/builder.h"

#include <algorithm>
#include <cassert>
#include <atomic>
#include <cmath>
#include <cstring>
#include <malloc.h>
#include <map>
#include <unordered_set>
#include <mutex>
#include <type_traits>
#include <unordered_map>

#include <tbb/concurrent_queue.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_arena.h>

#include "base/error.h"
#include "base/heap_warmup.h"
#include "base/progress.h"
#include "base/paged_array.h"
#include "base/sysinfo.h"
#include "base/temp_file.h"
#include "catp/format.h"
#include "catp/simplify.h"
#include "clip.h"
#include "common_codec/archive.h"
#include "common_codec/exact_predicates.h"
#include "common_codec/octahedral.h"
#include "common_codec/packed_vertex.h"
#include "build_input.h"
#include "fragment_build.h"
#include "leaf_routing.h"
#include "spill.h"

namespace catpaq {

namespace {

// The name the archive writer gives its node spill (common_codec/src/archive.cpp).
std::string archive_spill_name(const std::string& output) { return output + ".nodes.tmp." + std::to_string(getpid()); }

// Runs a build; an error that names the archive's spill (disk full while spilling nodes) names
// the user's output instead.
template <class Build>
CatpBuildReport naming_user_paths(const std::string& output, Build build) {
    try {
        return build();
    } catch (const Error& e) {
        std::string message = e.what(), spill = "'" + archive_spill_name(output) + "'";
        size_t at = message.find(spill);
        if (at == std::string::npos) throw;
        message.replace(at, spill.size(), "the scratch file next to '" + output + "'");
        throw Error(message);
    }
}


// ----------------------------------------------------------------------------------------------
// Placement of the model in the lattice.

struct Placement {
    double origin[3];
    double cell;  // world units per lattice unit (a power of two)
};

// A flat model (a wall, a floor, a relief scan: thin along one axis) is placed with its centre
// off the cube's middle plane across that axis, by 5461 lattice units (0b1010101010101: at least
// a third of a spacing from the planes of every level, spacings 2^19 down to 2). Centred, it lay
// on that plane, a face of the diamonds of every level; scanner noise made its surface cross the
// face everywhere, every crossing vertex was locked on the diamonds' outer faces, and the coarse
// levels could not simplify: a 220 x 220 grid with noise of 1e-6 of its side took 1.4 MB (187 KB
// without noise), level 0 held 24,773 triangles with the model's diagonal as its error bound,
// and verify found the two sides of those faces ending differently. Shifted: 208 KB, 3,301
// triangles at level 0, verify OK. Only thin axes move (thinner than kThinAxis of the longest
// side, but not exactly planar: a plane lying in the face is drawn as patches in it, as it always
// was). Shifting every model also changed where the lattice cuts the bunny and the scans, their
// sizes by 0.2-0.5% but the 2M scan's streaming by chance (the orbit view's fetched / drawn from
// 1.06 to 1.77), so other models keep the centred placement and their datasets, byte for byte.
constexpr int64_t kThinAxisShift = 5461;
constexpr double kThinAxis = 0.125;

Placement place_model(const Bounds& b, bool centred) {
    double extent = 0;
    for (int i = 0; i < 3; ++i) extent = std::max(extent, b.max[i] - b.min[i]);
    if (!(extent > 0) || !std::isfinite(extent))
        fail("the model has zero extent (all vertices coincide): nothing to build a hierarchy over");
    // A power-of-two cube with at least 3% margin on every side (across a thin axis far more,
    // even after the shift above), so no geometry touches the root cube's boundary and the
    // lattice mapping is an exact power-of-two scaling. (A cube fitted to the model would make
    // the leaves' steps up to twice finer for the same triangles per leaf, but it was measured
    // to break the hard case FlatTilted: the inexact scaling moves a plane that contained
    // lattice lines exactly to one that nearly contains them, and the clipper's triangle x line
    // constructions then disagree between neighbouring cells (cracks, and the finest level 30
    // times its bound). The precision is reached by the vertex layout's grid and the leaf level
    // instead.)
    double side = std::exp2(std::ceil(std::log2(extent * 1.0625)));
    Placement p;
    p.cell = side / double(kLatticeSize);
    for (int i = 0; i < 3; ++i) {
        double centre = 0.5 * (b.min[i] + b.max[i]);
        p.origin[i] = std::floor((centre - 0.5 * side) / p.cell) * p.cell;
        const double thickness = b.max[i] - b.min[i];
        if (!centred && thickness > 0 && thickness < kThinAxis * extent)
            p.origin[i] -= double(kThinAxisShift) * p.cell;
        if (b.min[i] < p.origin[i] || b.max[i] > p.origin[i] + side)
            fail("cannot place the model in a lattice cube (coordinates too large for double precision?)");
    }
    return p;
}

// ----------------------------------------------------------------------------------------------
// Edge lengths of lattice tetrahedra (bisection and the routing of triangles to leaves: leaf_routing.h).

int64_t len2(const LatticePoint& a, const LatticePoint& b) {
    int64_t s = 0;
    for (int i = 0; i < 3; ++i) s += int64_t(a[i] - b[i]) * (a[i] - b[i]);
    return s;
}

// ----------------------------------------------------------------------------------------------
// Choosing the leaf level (from the density) and the block level (from the memory budget).

struct LevelChoice {
    int leaf_level = 0;
    int block_octave = 0;                 // blocks are the cubes of this octave (level 3 x octave)
};

// The length of the longest run of equal keys in sorted `keys` (the sample points of the
// fullest tetrahedron or cube).
size_t longest_run(const std::vector<uint64_t>& keys) {
    size_t longest = 0;
    for (size_t i = 0, run = 0; i < keys.size(); ++i) {
        run = (i > 0 && keys[i] == keys[i - 1]) ? run + 1 : 1;
        longest = std::max(longest, run);
    }
    return longest;
}

// Sample vertices tracked down the hierarchy one bisection at a time (a point in a tetrahedron
// is in the child on its side of the splitting plane). Vertices sample the surface as well as
// triangle centroids do (a mesh has about two triangles per vertex), and they are known before
// the triangles are read.
struct TrackedSample {
    Vec3d p;
    Tetrahedron t;
};

std::vector<TrackedSample> track_from_root(const std::vector<Vec3d>& sample) {
    std::vector<TrackedSample> points;
    DiamondInfo root = diamond_info(root_diamond());
    for (const Vec3d& p : sample)
        for (int s = 0; s < 6; ++s) {
            Tetrahedron tet = diamond_tetrahedron(root, s);
            if (!separated(tet, &p, 1)) {
                points.push_back({p, tet});
                break;
            }
        }
    return points;
}

// Parallel over the points: the read phase is otherwise single-threaded, and tracking 50k
// points down 15 levels took 0.13 s of it.
template <class Fn>
void over_points(size_t n, Fn&& fn) {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 1024), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i != r.end(); ++i) fn(i);
    });
}

void descend_sample(TrackedSample& s) {
    Tetrahedron a, b;
    bisect(s.t, a, b);
    s.t = separated(a, &s.p, 1) ? b : a;
}

// The density's level: the first where the occupied tetrahedra hold about `leaf_target`
// triangles on average (at most 1.41 times it). Where density is even, the leaves are there
// (choose_refined_diamonds).
int choose_mean_level(const std::vector<Vec3d>& sample, uint64_t triangles, size_t leaf_target) {
    std::vector<TrackedSample> points = track_from_root(sample);
    double per_point = double(triangles) / double(std::max<size_t>(1, points.size()));
    std::vector<uint64_t> keys(points.size());
    for (int level = 0; level < kMaxLevel - 3; ++level) {
        over_points(points.size(), [&](size_t i) {
            Tetrahedron k = canonical_tetrahedron(points[i].t);
            uint64_t h = 1469598103934665603ull;
            for (auto& p : k)
                for (int v : p) h = (h ^ uint64_t(uint32_t(v))) * 1099511628211ull;
            keys[i] = h;
        });
        tbb::parallel_sort(keys.begin(), keys.end());
        size_t distinct = size_t(std::unique(keys.begin(), keys.end()) - keys.begin());
        const double mean = per_point * double(points.size()) / double(std::max<size_t>(1, distinct));
        if (mean <= double(leaf_target) * 1.4142) return level;
        over_points(points.size(), [&](size_t i) { descend_sample(points[i]); });
    }
    return kMaxLevel - 3;
}

// The leaves follow the local density (adaptive leaves): the refined diamonds, closed under
// parents, are those coarser than `floor` (the precision's level: every leaf's grid step reaches
// the precision) and those the sample says hold too much (`ids`). Leaf tetrahedra are then the
// slots whose creating parent is refined and whose own diamond is not: a cut of the diamond DAG,
// so the leaves tile the model conformingly as the client's cuts do, and every cut of the
// dataset stays crack-free by the same argument.
struct RefinedDiamonds {
    int floor = 0;
    std::unordered_set<uint64_t> ids;
    int deepest = 0;  // the deepest level `ids` refines to (its deepest diamond's level + 1)
    bool refined(uint64_t diamond, int level) const { return level < floor || ids.count(diamond) != 0; }
};

// Where the density asks for leaves coarser or finer than the mean level: above it, a diamond
// none of whose tetrahedra holds half the target stays a leaf (a sparse region, or a corner of
// the surface: a hundredfold density contrast made the sparse part of a mesh three times larger
// and slower to build when every leaf sat at the level of the dense part); at and below it, a
// diamond with a tetrahedron estimated at more than kLargestLeafRatio times the target is
// refined. The coarsening's working memory grows with the largest diamonds, and the budget
// reserves a fixed amount per thread for them: a 300k-triangle scan with a 2M-triangle sphere
// inside, its leaves chosen by the mean alone, held 46k triangles in a leaf and peaked at
// 235 MiB at a 102 MiB budget. At 8 times (the bound when one leaf level served the whole model,
// then reached only by its largest leaf) the dense sphere of a 1M uneven mesh filled most of its
// leaves up to it and, with 2 threads at 122 MiB, peaked at 123.6 MiB; at 6 times, 110.2 MiB
// (memory_budget_bench; at 4 times 80.5, but the 10M scan's file grew 2.2%). Scan-like meshes of
// even density have a few tetrahedra of 4.4-6.3 times the target at the mean level: the 1M
// scan's file is the same, the 10M scan's has 11 more diamonds (3073) and 0.05% more bytes. A
// diamond without a sample stays a leaf. The estimate is the sample's count times the triangles
// per sample.
constexpr double kLargestLeafRatio = 6.0;
constexpr double kSparseLeafRatio = 0.5;

RefinedDiamonds choose_refined_diamonds(const std::vector<Vec3d>& sample, uint64_t triangles, size_t leaf_target,
                                        int mean_level) {
    RefinedDiamonds refined;
    std::vector<TrackedSample> points = track_from_root(sample);
    const double per_point = double(triangles) / double(std::max<size_t>(1, points.size()));
    const double target = double(leaf_target);
    struct Where {
        uint64_t diamond;
        int slot;
        bool operator<(const Where& o) const { return diamond != o.diamond ? diamond < o.diamond : slot < o.slot; }
        bool operator==(const Where& o) const { return diamond == o.diamond && slot == o.slot; }
    };
    std::vector<Where> where;
    for (int level = 0; level < kMaxLevel - 3 && !points.empty(); ++level) {
        where.resize(points.size());
        over_points(points.size(), [&](size_t i) {
            DiamondId id;
            int slot = 0;
            tetrahedron_diamond(points[i].t, id, slot);
            where[i] = {id.bits, slot};
        });
        std::vector<Where> sorted = where;
        tbb::parallel_sort(sorted.begin(), sorted.end());
        // Per diamond, its fullest tetrahedron's count: refine or not.
        std::vector<uint64_t> refine;  // sorted
        for (size_t i = 0; i < sorted.size();) {
            size_t fullest = 0, j = i;
            while (j < sorted.size() && sorted[j].diamond == sorted[i].diamond) {
                size_t k = j;
                while (k < sorted.size() && sorted[k] == sorted[j]) ++k;
                fullest = std::max(fullest, k - j);
                j = k;
            }
            const double estimate = per_point * double(fullest);
            if (level < mean_level ? estimate >= target * kSparseLeafRatio : estimate > target * kLargestLeafRatio)
                refine.push_back(sorted[i].diamond);
            i = j;
        }
        if (refine.empty()) break;
        refined.ids.insert(refine.begin(), refine.end());
        refined.deepest = level + 1;
        size_t kept = 0;
        for (size_t i = 0; i < points.size(); ++i)
            if (std::binary_search(refine.begin(), refine.end(), where[i].diamond)) points[kept++] = points[i];
        points.resize(kept);
        over_points(points.size(), [&](size_t i) { descend_sample(points[i]); });
    }
    // Closed under parents: a diamond is refined only where all of its parents are.
    std::vector<uint64_t> work(refined.ids.begin(), refined.ids.end());
    while (!work.empty()) {
        const DiamondId id{work.back()};
        work.pop_back();
        if (id == root_diamond()) continue;
        for (DiamondId p : diamond_parents(id))
            if (refined.ids.insert(p.bits).second) work.push_back(p.bits);
    }
    return refined;
}

// The block octave: the coarsest (at most the leaf level's) whose fullest cube is estimated to
// hold at most `block_target` triangles.
LevelChoice choose_block_octave(const std::vector<Vec3d>& sample, uint64_t triangles, int leaf_level,
                                uint64_t block_target) {
    LevelChoice choice;
    choice.leaf_level = leaf_level;
    double per_point = double(triangles) / double(std::max<size_t>(1, sample.size()));
    std::vector<uint64_t> keys(sample.size());
    for (int octave = 0; octave <= leaf_level / 3; ++octave) {
        int32_t side = kLatticeSize >> octave;
        for (size_t i = 0; i < sample.size(); ++i) {
            BlockCube c;
            for (int k = 0; k < 3; ++k) c.index[k] = std::clamp(int32_t(sample[i][k] / side), 0, (kLatticeSize / side) - 1);
            keys[i] = c.key();
        }
        std::sort(keys.begin(), keys.end());
        const size_t largest = longest_run(keys);
        // Triangles crossing block borders are counted in every block they touch: 25% margin.
        choice.block_octave = octave;
        if (uint64_t(1.25 * per_point * double(largest)) + 1 <= block_target) break;
    }
    return choice;
}

// The longest edge of the tetrahedra of `level` (their diamonds' spines), in lattice units: the
// side of the level's cubes times sqrt 3 (cube diamonds), sqrt 2 (face) or 1 (edge).
double level_longest_edge(int level) {
    static constexpr double kSpine[3] = {1.7320508075688772, 1.4142135623730951, 1.0};
    return std::ldexp(kSpine[level % 3], kLatticeBits - level / 3);
}

// The vertex layout, its grid and the leaf level for a precision (lattice units): the leaves'
// quantization step (longest edge / grid) must be at most the precision. Tried from the density's
// leaf level down, each level with the layouts `kinds` in order; the smallest grid that reaches
// it is taken (a finer grid only costs bits), but at least kMinGrid steps: the grid is the same
// at every level, and the coarser levels' own simplification error needs the 24-bit layout's
// 463 steps (with 100, on the hard cases, level 0 was four times as far from the input).
struct PrecisionChoice {
    VertexLayout layout;
    int leaf_level = 0;
    bool reached = true;  // false: a forced leaf level the layouts cannot reach the precision at
};
constexpr int32_t kMinGrid = kBaryGrid;

PrecisionChoice choose_precision(double precision, int density_level, bool level_forced,
                                 const std::vector<VertexLayoutKind>& kinds) {
    PrecisionChoice choice;
    const int last = level_forced ? density_level : kMaxLevel - 3;
    for (int level = density_level; level <= last; ++level)
        for (VertexLayoutKind kind : kinds) {
            const double steps = std::ceil(level_longest_edge(level) / precision);
            if (steps > double(VertexLayout::max_grid(kind))) continue;
            choice.layout = VertexLayout{kind, std::max(kMinGrid, int32_t(steps))};
            choice.leaf_level = level;
            return choice;
        }
    if (!level_forced)
        fail("a precision of %g lattice cells is finer than the deepest leaves can hold", precision);
    choice.layout = VertexLayout{kinds.back(), VertexLayout::max_grid(kinds.back())};
    choice.leaf_level = density_level;
    choice.reached = false;
    return choice;
}

// ----------------------------------------------------------------------------------------------

Tetrahedron slot_tetrahedron(const SlotKey& key) { return diamond_tetrahedron(diamond_info(DiamondId{key.diamond}), key.slot); }

double tetrahedron_longest_edge(const Tetrahedron& t) {
    int64_t best = 0;
    for (int i = 0; i < 4; ++i)
        for (int j = i + 1; j < 4; ++j) best = std::max(best, len2(t[i], t[j]));
    return std::sqrt(double(best));
}

// The sum of edge lengths (lattice units) in fixed point with 2^-24 resolution, so that it does
// not depend on the order of the additions: inputs read in other chunks, or by other threads,
// give the same mean edge, hence the same grid and the same dataset.
struct EdgeLengthSum {
    unsigned __int128 sum = 0;  // lengths below 2^22, times 2^24, over fewer than 2^64 edges
    uint64_t count = 0;
    void add(const Vec3d& a, const Vec3d& b) {
        const double d2 = (a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]);
        sum += uint64_t(std::ldexp(std::sqrt(d2), 24));
        ++count;
    }
    void add(const EdgeLengthSum& o) {
        sum += o.sum;
        count += o.count;
    }
    double mean() const { return count ? std::ldexp(double(sum / count), -24) : 0.0; }
};

// Per-vertex data as the converter keeps it (40 bytes).
struct VertexRecord {
    Vec3d position;  // model units until to_lattice(), then lattice units on the snapping grid
    Vec3f normal;
    Rgb8 color;
};

// Gives freed heap memory back to the system between phases. glibc keeps freed blocks in its
// per-thread arenas; without this the resident size only grows, and a later phase's peak adds
// to an earlier phase's leftovers (measured: 89 MiB instead of 64 on a 1M-triangle build).
// Not while a HeapWarmup is in place: trimming would hand its warm pages back.
void return_free_memory(const HeapWarmup* warm) {
    if (!warm) malloc_trim(0);
}

// A warm heap (see base/heap_warmup.h) when the budget is ample: at least 100 bytes per input
// triangle (a mesh has about two triangles per vertex), twice the peak of a 10M-triangle scan's
// build. The heap is then not trimmed between phases, which costs some memory. It warms 32 bytes
// per triangle, less than the heap holds at its peak. 10M scan at 1 GiB, three alternating pairs
// against no warm-up: wall time x0.96 (system time 1.8 -> 1.1 s), page faults that trap
// 118k -> 32k, peak 497 -> 542 MiB (24 bytes: 528 MiB, fewer faults saved; 40 bytes: 608 MiB
// for little more).
std::unique_ptr<HeapWarmup> make_heap_warmup(uint64_t budget, uint64_t vertices) {
    const uint64_t triangles = 2 * vertices;
    if (budget < triangles * 100) return nullptr;
    return std::make_unique<HeapWarmup>(size_t(triangles * 32));
}

unsigned worker_threads(unsigned requested) {
    return requested ? requested : unsigned(std::max(1, tbb::info::default_concurrency()));
}

// How the memory budget is shared. The phases run one after another, so each may use most of
// it; the shares leave room for the process itself, TBB's workers and the simplifier's working
// set (a few MiB per worker thread). While reading: vertices 2/5, normal sums 1/5, triangle bins
// 2/5. While clipping leaves: a block 2/5, leaf fragments 1/5, and either the bins (2/5) or,
// when the vertices fit beside compact bins in 2/5, both (see CatpBuild::choose_bins). While
// coarsening: the finer level's fragments (at most 2/5) and the coarser level's (2/5).
constexpr uint64_t kMaxBlockTriangles = uint64_t(1) << 18;

struct BudgetShares {
    uint64_t vertex_cache, normal_cache, triangle_buffers, fragments_in_memory, coarse_fragments_in_memory,
        block_triangles;
    explicit BudgetShares(uint64_t budget)
        : vertex_cache(budget * 2 / 5),
          normal_cache(budget / 5),
          triangle_buffers(budget * 2 / 5),
          fragments_in_memory(budget / 5),
          // Coarsening holds two levels' fragments and nothing else big.
          coarse_fragments_in_memory(budget * 2 / 5),
          // A loaded block costs its 128-byte records plus, while clipping, hits and fragments:
          // about 320 bytes per triangle, measured on scan-like meshes. Blocks are also kept
          // small when memory is plentiful: a small block's memory is reused by the next one
          // instead of being faulted in afresh (1M scan: 3.9 s with one block, 3.2 s with 16).
          block_triangles(std::clamp<uint64_t>(budget * 2 / 5 / 320, 1, kMaxBlockTriangles)) {}
};

// Working memory of coarsening one diamond per gathered triangle: the simplifier's block, the
// two error grids, the welded arrays and the clipped slots (measured with heaptrack on the 1M
// scan, one thread: 21 MiB for its largest diamond, 46k gathered triangles).
constexpr uint64_t kCoarsenBytesPerTriangle = 480;

constexpr size_t kChunk = 1 << 16;  // vertices or triangles per read
constexpr size_t kSampleTarget = 50000;

// The stages of one build, in order. Each method is one phase; members carry what the later
// phases need.
class CatpBuild {
public:
    CatpBuild(BuildInput& input, const std::string& output_path, const CatpBuildSettings& settings)
        : in_(input), output_(output_path), settings_(settings) {}

    CatpBuildReport run();

private:
    void read_vertices();
    void compute_normals();
    void to_lattice();
    bool choose_bins(uint64_t triangle_estimate) const;
    template <typename Record>
    void bin_triangles(TriangleBins<Record>& bins);
    template <typename Record>
    size_t load_block(TriangleBins<Record>& bins, size_t b, std::vector<TriangleRecord>& records);
    template <typename Record>
    void build_leaves(TriangleBins<Record>& bins);
    void write_leaf_nodes();
    void coarsen_level(int level);
    void choose_layout_and_leaves();
    void finish_archive();

    // A node whose fragments are final, with what its bound needs; written at once, or (one that
    // draws nothing) once its level is done (finish_empty_nodes).
    struct PreparedNode {
        ArchiveEntry entry;
        std::vector<uint8_t> bytes;
        std::vector<uint32_t> slot_bytes;
        QuantizationLoss loss;
        LostGeometryReach reach;
        double step = 0, unquantized = 0, children_stored = 0;
        size_t triangles = 0, vertices = 0;
        bool leaf = false;
        double* stored = nullptr;  // where the caller keeps the node's stored bound
    };
    void write_node(DiamondId id, const DiamondInfo& info, const std::array<const WorkFragment*, 8>& slots,
                    double unquantized_error, double children_stored, bool leaf, double* stored);
    void commit_node(PreparedNode& node, double lost);
    void finish_empty_nodes();
    double quantization_step(const DiamondInfo& info, const std::array<const WorkFragment*, 8>& slots) const;


    BuildInput& in_;
    std::string output_;
    CatpBuildSettings settings_;
    CatpBuildReport report_;
    uint64_t budget_ = 0;
    std::unique_ptr<BudgetShares> shares_;
    std::unique_ptr<Progress> progress_;
    std::unique_ptr<HeapWarmup> warm_heap_;  // see make_heap_warmup

    Bounds bounds_;
    Placement place_{};
    std::unique_ptr<PagedArray<VertexRecord>> vertices_;
    std::vector<Vec3d> sample_;  // model units
    LevelChoice levels_;  // leaf_level: the deepest leaf level (the density's, then the precision's)
    int mean_level_ = 0;  // the density's level where it is even (choose_mean_level)
    RefinedDiamonds refined_;
    VertexLayout layout_;
    double mean_edge_ = 0;   // lattice units
    double precision_ = 0;   // lattice units, as asked for
    uint64_t triangles_ = 0;
    EdgeLengthSum edge_lengths_;  // of the binned triangles
    std::vector<TriangleCorners> block_corners_;  // the block being loaded, by corner indices
    std::unique_ptr<ArchiveWriter> archive_;
    std::vector<CatpLevelStats> stats_;
    std::mutex stats_mutex_;
    // The slot table of the meta (catp/format.h), by (level, key): the archive's index order.
    // Every node's index entry (no offset or checksum) and its slots' sizes, in index order
    // (level, key): the slot table in the metadata.
    std::map<std::pair<uint16_t, uint64_t>, std::pair<ArchiveEntry, std::vector<uint32_t>>> slot_bytes_;
    // The level being coarsened: its fragments, and each diamond's errors (lattice units).
    // `unquantized`: of its unquantized geometry from the original, 0 at the leaves, above them
    // the largest child's plus the diamond's own measured simplification error. `stored`: the
    // bound written, the unquantized error plus what quantization costs (the grid step, or the
    // distance from the thin geometry it loses to what is drawn, whichever is larger), and at
    // least every child's stored bound, so stored bounds are monotone.
    struct DiamondError {
        double unquantized = 0, stored = 0;
    };
    std::unique_ptr<FragmentSpill> fragments_;  // the leaves', then each coarser level's
    std::unique_ptr<FragmentSpill> leaves_;     // while coarsening: the leaves (not gathered
    size_t leaf_next_ = 0;                      // from leaf_next_ on)
    std::unordered_map<uint64_t, DiamondError> diamond_error_;  // the level just made
    std::unordered_map<uint64_t, DiamondError> leaf_error_;     // every leaf's
    // The nodes of the level being written that draw nothing, and the largest stored bound of
    // those that draw something (lattice units; -1: none yet).
    std::vector<PreparedNode> empty_nodes_;
    double drawn_max_stored_ = -1;
    uint64_t bytes_spilled_ = 0;
    const Rgb8 default_color_{180, 180, 180};
};

// Pass over the vertices: keeps them (paged), their bounds and a regular sample. Two stages
// overlap on the cores, each serial and in input order: parsing a chunk of the input, and
// storing the previous chunk's vertices (one thread doing both was the build's only serial
// stretch, the first 3% of a 2M-triangle build's time). Chunks are recycled: fresh memory costs
// page faults.
void CatpBuild::read_vertices() {
    uint64_t count = in_.vertex_count();
    if (count == 0) fail("the mesh has no vertices");
    if (count > uint64_t(UINT32_MAX)) fail("the mesh has %llu vertices; at most 2^32 - 1 are supported", (unsigned long long)count);
    vertices_ = std::make_unique<PagedArray<VertexRecord>>(count, shares_->vertex_cache, output_);
    uint64_t stride = std::max<uint64_t>(1, count / kSampleTarget);
    struct Chunk {
        std::vector<Vec3d> positions;
        std::vector<Vec3f> normals;
        std::vector<Rgb8> colors;
        size_t n = 0;
    };
    constexpr size_t kLiveChunks = 2;  // one parsed while the other is stored
    std::vector<Chunk> chunks(kLiveChunks);
    tbb::concurrent_queue<Chunk*> free_chunks;
    for (Chunk& c : chunks) free_chunks.push(&c);
    uint64_t v = 0;
    auto parse = [&](tbb::flow_control& flow) -> Chunk* {
        Chunk* chunk = nullptr;
        if (!free_chunks.try_pop(chunk)) fail("internal error: no free chunk in the vertex pipeline");
        chunk->positions.clear();
        chunk->normals.clear();
        chunk->colors.clear();
        chunk->n = in_.read_vertices(kChunk, chunk->positions, &chunk->normals, &chunk->colors);
        if (chunk->n == 0) {
            free_chunks.push(chunk);
            flow.stop();
            return nullptr;
        }
        return chunk;
    };
    auto store = [&](Chunk* chunk) {
        const size_t n = chunk->n;
        progress_->add(n);
        for (size_t i = 0; i < n; ++i, ++v) {
            if (v >= count) fail("'%s': more vertices than declared", in_.name().c_str());
            VertexRecord& r = vertices_->at_for_write(v);
            r.position = chunk->positions[i];
            r.normal = chunk->normals.empty() ? Vec3f{0, 0, 1} : chunk->normals[i];
            r.color = chunk->colors.empty() ? default_color_ : chunk->colors[i];
            bounds_.add(chunk->positions[i]);
            if (v % stride == 0) sample_.push_back(chunk->positions[i]);
        }
        free_chunks.push(chunk);
    };
    tbb::parallel_pipeline(kLiveChunks, tbb::make_filter<void, Chunk*>(tbb::filter_mode::serial_in_order, parse) &
                                            tbb::make_filter<Chunk*, void>(tbb::filter_mode::serial_in_order, store));
    if (v != count) fail("'%s': %llu vertices read, %llu declared", in_.name().c_str(), (unsigned long long)v, (unsigned long long)count);
}

// Area-weighted vertex normals, as compute_vertex_normals does it (double sums in triangle order,
// so the result is the same bit for bit), with the sums paged like the vertices.
void CatpBuild::compute_normals() {
    uint64_t count = vertices_->size();
    PagedArray<Vec3d> sums(count, shares_->normal_cache, output_);
    std::vector<uint32_t> indices;
    in_.rewind_triangles();
    for (;;) {
        indices.clear();
        size_t n = in_.read_triangles(kChunk, indices);
        if (n == 0) break;
        for (size_t t = 0; t < n; ++t) {
            const uint32_t* f = &indices[3 * t];
            Vec3d a = vertices_->at(f[0]).position, b = vertices_->at(f[1]).position, c = vertices_->at(f[2]).position;
            double ux = b[0] - a[0], uy = b[1] - a[1], uz = b[2] - a[2];
            double vx = c[0] - a[0], vy = c[1] - a[1], vz = c[2] - a[2];
            Vec3d normal{uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx};
            for (int k = 0; k < 3; ++k) {
                Vec3d& s = sums.at_for_write(f[k]);
                for (int i = 0; i < 3; ++i) s[i] += normal[i];
            }
        }
        progress_->add(n);
    }
    for (uint64_t v = 0; v < count; ++v) {
        Vec3d s = sums.at(v);
        double length = std::sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
        vertices_->at_for_write(v).normal = length > 0 && std::isfinite(length)
                                                ? Vec3f{float(s[0] / length), float(s[1] / length), float(s[2] / length)}
                                                : Vec3f{0.0f, 0.0f, 1.0f};
    }
    bytes_spilled_ += sums.bytes_spilled();
}

// Vertex positions from model units to lattice units on the snapping grid, once per vertex
// (before, every triangle converted its three corners: 30M conversions for 10M triangles).
// In parallel when every vertex is in memory (the read phase is otherwise serial).
void CatpBuild::to_lattice() {
    auto convert = [&](Vec3d& p) {
        for (int i = 0; i < 3; ++i) p[i] = snap_to_grid((p[i] - place_.origin[i]) / place_.cell);
    };
    PagedArray<VertexRecord>& vertices = *vertices_;
    if (vertices.resident()) {
        tbb::parallel_for(tbb::blocked_range<uint64_t>(0, vertices.size(), 1 << 14), [&](const tbb::blocked_range<uint64_t>& r) {
            for (uint64_t v = r.begin(); v != r.end(); ++v) convert(vertices.resident_at(v).position);
        });
        return;
    }
    for (uint64_t v = 0; v < vertices.size(); ++v) convert(vertices.at_for_write(v).position);
}

// True to bin triangles as corner indices (TriangleCorners), keeping the vertices in memory until
// the leaves are built: when every vertex is in memory and vertices plus compact bins fit in 2/5
// of the budget (the share the bins have otherwise). Else triangles are binned as TriangleRecords
// and the vertices are freed first. Both give the same leaves.
bool CatpBuild::choose_bins(uint64_t triangle_estimate) const {
    if (!vertices_->resident()) return false;
    uint64_t vertex_bytes = vertices_->size() * sizeof(VertexRecord);
    // Triangles crossing block borders are binned once per block: 25% margin.
    uint64_t bin_bytes = triangle_estimate * sizeof(TriangleCorners) * 5 / 4;
    if (triangle_estimate * 5 / 4 >= UINT32_MAX) return false;  // TriangleCorners::sequence
    return vertex_bytes + bin_bytes <= budget_ * 2 / 5;
}

namespace {

// Empties a fragment whose arrays are to be filled again.
void clear_keeping_capacity(WorkFragment& f) {
    f.positions.clear();
    f.normals.clear();
    f.colors.clear();
    f.indices.clear();
}

// A binned triangle's corners, in lattice units.
void corner_positions(const TriangleRecord& r, const PagedArray<VertexRecord>&, Vec3d out[3]) {
    for (int k = 0; k < 3; ++k) out[k] = r.positions[k];
}
void corner_positions(const TriangleCorners& r, const PagedArray<VertexRecord>& vertices, Vec3d out[3]) {
    for (int k = 0; k < 3; ++k) out[k] = vertices.resident_at(r.vertices[k]).position;
}

// A triangle as binned, from its corner indices (the reading stage: PagedArray::at is not
// thread-safe, and the corners of consecutive triangles share pages).
void make_record(const uint32_t* f, PagedArray<VertexRecord>& vertices, TriangleRecord& r) {
    std::memset(static_cast<void*>(&r), 0, sizeof r);  // padding too: records are written to disk
    for (int k = 0; k < 3; ++k) {
        const VertexRecord& v = vertices.at(f[k]);
        r.positions[k] = v.position;
        r.normals[k] = v.normal;
        r.colors[k] = v.color;
    }
}
void make_record(const uint32_t* f, PagedArray<VertexRecord>&, TriangleCorners& r) {
    r.vertices = {f[0], f[1], f[2]};
}

}  // namespace

// Pass over the triangles: sorts each into every block cube it may overlap, as a record of its
// corners' data or as corner indices.
template <typename Record>
void CatpBuild::bin_triangles(TriangleBins<Record>& bins) {
    struct Batch {
        std::vector<uint32_t> indices;
        std::vector<Record> records;
        std::vector<std::pair<uint32_t, uint64_t>> hits;  // record, block cube
        size_t triangles = 0;
        uint64_t first_record = 0;  // the input's records before this batch's
        EdgeLengthSum edge_lengths;
    };
    // Three stages overlap on the cores: reading (serial: the input and the paged vertices are
    // sequential), finding each triangle's block cubes (any order), and appending to the bins
    // (serial, in input order, so a block keeps the input order). Batches are recycled: fresh
    // memory costs page faults.
    constexpr size_t kLiveBatches = 3, kBatchTriangles = 1 << 14;  // at most about 2.5 MiB each
    std::vector<Batch> batches(kLiveBatches);
    tbb::concurrent_queue<Batch*> free_batches;
    for (Batch& b : batches) free_batches.push(&b);
    const int32_t side = kLatticeSize >> levels_.block_octave;
    uint64_t records_read = 0;
    // The mean edge from the first 65536 triangles and every 16th after them: as exact as the
    // precision needs, and three square roots per triangle cost 1.3% of a build. Counted by
    // record, in input order, so any chunking of the input gives the same sample.
    constexpr uint64_t kAllEdgesUpTo = 1 << 16, kEdgeSampleStride = 16;
    in_.rewind_triangles();
    auto read = [&](tbb::flow_control& flow) -> Batch* {
        Batch* batch = nullptr;
        if (!free_batches.try_pop(batch)) fail("internal error: no free batch in the binning pipeline");
        batch->indices.clear();
        batch->records.clear();
        batch->triangles = in_.read_triangles(kBatchTriangles, batch->indices);
        if (batch->triangles == 0) {
            free_batches.push(batch);
            flow.stop();
            return nullptr;
        }
        triangles_ += batch->triangles;
        for (size_t t = 0; t < batch->triangles; ++t) {
            const uint32_t* f = &batch->indices[3 * t];
            if (f[0] == f[1] || f[1] == f[2] || f[0] == f[2]) continue;  // no area, nothing to clip
            Record& r = batch->records.emplace_back();
            make_record(f, *vertices_, r);
            r.sequence = decltype(r.sequence)(records_read + batch->records.size() - 1);
        }
        if (std::is_same_v<Record, TriangleCorners> && records_read + batch->records.size() > UINT32_MAX)
            fail("internal error: compact bins hold fewer than 2^32 triangles");
        batch->first_record = records_read;
        records_read += batch->records.size();
        return batch;
    };
    auto find_blocks = [&](Batch* batch) -> Batch* {
        batch->hits.clear();
        batch->edge_lengths = EdgeLengthSum{};
        BlockCube cube;
        for (size_t i = 0; i < batch->records.size(); ++i) {
            Vec3d corners[3];
            corner_positions(batch->records[i], *vertices_, corners);
            const uint64_t record = batch->first_record + i;
            if (record < kAllEdgesUpTo || record % kEdgeSampleStride == 0)
                for (int k = 0; k < 3; ++k) batch->edge_lengths.add(corners[k], corners[(k + 1) % 3]);
            int32_t lo[3], hi[3];
            cube_range(corners, 3, side, lo, hi);
            for (cube.index[2] = lo[2]; cube.index[2] <= hi[2]; ++cube.index[2])
                for (cube.index[1] = lo[1]; cube.index[1] <= hi[1]; ++cube.index[1])
                    for (cube.index[0] = lo[0]; cube.index[0] <= hi[0]; ++cube.index[0])
                        batch->hits.push_back({uint32_t(i), cube.key()});
        }
        return batch;
    };
    auto append = [&](Batch* batch) {
        edge_lengths_.add(batch->edge_lengths);
        for (auto [record, block] : batch->hits) bins.add(block, batch->records[record]);
        progress_->add(batch->triangles);
        free_batches.push(batch);
    };
    tbb::parallel_pipeline(kLiveBatches,
                           tbb::make_filter<void, Batch*>(tbb::filter_mode::serial_in_order, read) &
                               tbb::make_filter<Batch*, Batch*>(tbb::filter_mode::parallel, find_blocks) &
                               tbb::make_filter<Batch*, void>(tbb::filter_mode::serial_in_order, append));
    in_.finish();
}

// Loads block b's triangles as records (resolving corner indices, in parallel, from the
// vertices in memory) into the first elements of `records`; returns how many.
template <>
size_t CatpBuild::load_block(TriangleBins<TriangleRecord>& bins, size_t b, std::vector<TriangleRecord>& records) {
    bins.load(b, records);
    return records.size();
}
template <>
size_t CatpBuild::load_block(TriangleBins<TriangleCorners>& bins, size_t b, std::vector<TriangleRecord>& records) {
    std::vector<TriangleCorners>& corners = block_corners_;  // reused: fresh memory costs page faults
    bins.load(b, corners);
    // Never shrunk: growing a vector zero-fills the new records before they are overwritten,
    // and after every smaller block that cost 1.4% of the leaf phase (perf, 10M scan).
    if (records.size() < corners.size()) records.resize(corners.size());
    const PagedArray<VertexRecord>& vertices = *vertices_;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, corners.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i != r.end(); ++i) {
            for (int k = 0; k < 3; ++k) {
                const VertexRecord& v = vertices.resident_at(corners[i].vertices[k]);
                records[i].positions[k] = v.position;
                records[i].normals[k] = v.normal;
                records[i].colors[k] = v.color;
            }
            records[i].sequence = corners[i].sequence;
        }
    });
    return corners.size();
}

// Clips each block's triangles by its leaf tetrahedra; the leaf fragments go to the spill. A
// leaf coarser than the blocks (a sparse region's, where memory asked for small blocks) gathers
// its triangles from every block they were binned in, and is clipped after the blocks.
template <typename Record>
void CatpBuild::build_leaves(TriangleBins<Record>& bins) {
    fragments_ = std::make_unique<FragmentSpill>(output_, shares_->fragments_in_memory);
    // Blocks in key order, so the work (and the scratch file) is laid out the same every run.
    std::vector<size_t> order(bins.block_count());
    for (size_t b = 0; b < order.size(); ++b) order[b] = b;
    std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return bins.block_key(a) < bins.block_key(b); });
    std::vector<TriangleRecord> records;
    if constexpr (std::is_same_v<Record, TriangleCorners>) {
        // Sized once for the largest block: grown block by block, it copied its old records
        // (which are overwritten anyway) and zero-filled the new ones (2% of the 1M scan's
        // build). (Binned records are loaded into a cleared array instead: nothing to copy.)
        uint64_t largest = 0;
        for (size_t b = 0; b < order.size(); ++b) largest = std::max(largest, bins.block_records(b));
        records.resize(size_t(largest));
        block_corners_.reserve(size_t(largest));
    }
    // The routing's hits by chunk of records, so that they come out in record order whatever
    // thread routed which chunk. Kept from block to block: fresh memory costs page faults.
    constexpr size_t kRouteChunk = 4096;
    std::vector<std::vector<LeafHit>> chunk_hits;
    LeafGroups groups;
    tbb::enumerable_thread_specific<SourceVertexMap> source_maps;  // reused: see SourceVertexMap::clear
    // Leaves coarser than the blocks: their triangles, by leaf number, until every block is done.
    TriangleBins<TriangleRecord> spanning(output_, shares_->fragments_in_memory / 2);
    std::vector<SlotKey> spanning_keys;
    std::map<std::pair<uint64_t, int>, uint32_t> spanning_number;
    std::vector<std::vector<std::pair<SlotKey, uint32_t>>> chunk_spanning;
    const RefinedDiamonds& refined = refined_;
    for (size_t b : order) {
        const size_t count = load_block(bins, b, records);
        BlockCube block = BlockCube::from_key(levels_.block_octave, bins.block_key(b));
        const int block_level = 3 * block.octave;
        const int deepest = levels_.leaf_level;
        // The cube a level's tetrahedra are looked for in: the block, or for a level coarser
        // than the blocks, the block's ancestor of that level's octave (its leaves may reach
        // into other blocks: they are gathered across blocks, below).
        auto cube_of = [&](int level) {
            if (level >= block_level) return block;
            BlockCube cube = block;
            cube.octave = level / 3;
            for (int a = 0; a < 3; ++a) cube.index[a] = block.index[a] >> (block.octave - cube.octave);
            return cube;
        };
        const size_t chunks = (count + kRouteChunk - 1) / kRouteChunk;
        if (chunk_hits.size() < chunks) chunk_hits.resize(chunks);
        if (chunk_spanning.size() < chunks) chunk_spanning.resize(chunks);
        for (std::vector<LeafHit>& h : chunk_hits) h.clear();
        for (auto& h : chunk_spanning) h.clear();
        tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
            std::vector<LeafHit>& out = chunk_hits[c];
            const size_t end = std::min(count, (c + 1) * kRouteChunk);
            for (size_t i = c * kRouteChunk; i != end; ++i) {
                const Vec3d* corners = records[i].positions.data();
                auto emit = [&](SlotKey k, int level, bool whole) {
                    if (level < block_level) chunk_spanning[c].push_back({k, uint32_t(i)});
                    else out.push_back({k, uint32_t(i), whole});
                };
                // A tetrahedron of level L is a leaf when its creating parent is refined and its
                // own diamond is not (refined_ is closed under parents, and every diamond above
                // the floor is refined). Down the levels from the floor: while the triangle lies
                // strictly inside one tetrahedron, that one (the fast path's tables); once it
                // crosses a face, every candidate of each level.
                int level = refined.floor;
                SlotKey key;
                bool placed = false;
                for (; level <= deepest && single_leaf(corners, level, cube_of(level), key); ++level)
                    if (!refined.refined(key.diamond, level)) {
                        emit(key, level, true);
                        placed = true;
                        break;
                    }
                for (bool deeper = !placed; deeper && level <= deepest; ++level) {
                    deeper = false;
                    search_leaf_slots(corners, level, cube_of(level), [&](SlotKey k) {
                        if (level > refined.floor &&
                            !refined.refined(slot_parent(diamond_info(DiamondId{k.diamond}), k.slot).bits, level - 1))
                            return;  // not a tetrahedron of the leaves' tiling
                        if (refined.refined(k.diamond, level)) deeper = true;
                        else emit(k, level, false);
                    });
                }
            }
        });
        for (size_t c = 0; c < chunks; ++c)
            for (auto [key, i] : chunk_spanning[c]) {
                auto [it, fresh] = spanning_number.emplace(std::pair{key.diamond, key.slot}, uint32_t(spanning_keys.size()));
                if (fresh) spanning_keys.push_back(key);
                spanning.add(it->second, records[i]);
            }
        groups.build(chunk_hits);
        tbb::parallel_for(size_t(0), groups.size(), [&](size_t g) {
            const SlotKey key = groups.key(g);
            std::vector<ClipPlane> planes = tetrahedron_clip_planes(slot_tetrahedron(key), 0xf);
            WorkFragment fragment;
            FragmentWelder welder(fragment);
            // A mesh has about half as many vertices as triangles; clipping adds a few of each.
            const size_t triangles = size_t(groups.end(g) - groups.begin(g));
            welder.reserve(triangles * 5 / 8 + 64, triangles * 9 / 8 + 16);
            if constexpr (std::is_same_v<Record, TriangleCorners>) {
                // The corners' input vertex indices are known: each input vertex is welded by
                // position once, its other triangles find it by index (a vertex is shared by
                // about six triangles).
                SourceVertexMap& welded = source_maps.local();
                welded.clear(triangles * 5 / 8 + 64);
                for (const LeafGroups::Entry* e = groups.begin(g); e != groups.end(g); ++e) {
                    const TriangleRecord& r = records[e->triangle];
                    const uint32_t* source = block_corners_[e->triangle].vertices.data();
                    if (e->whole)
                        welder.add_whole(source, welded, r.positions, r.normals, r.colors);
                    else
                        welder.add_clipped(source, welded, r.positions, r.normals, r.colors, planes);
                }
            } else {
                for (const LeafGroups::Entry* e = groups.begin(g); e != groups.end(g); ++e) {
                    const TriangleRecord& r = records[e->triangle];
                    if (e->whole)
                        welder.add_whole(r.positions, r.normals, r.colors);
                    else
                        welder.add_clipped(r.positions, r.normals, r.colors, planes);
                }
            }
            if (!fragment.indices.empty()) fragments_->put(key, std::move(fragment));
        });
        progress_->add(count);
    }
    // The leaves coarser than the blocks: their triangles in input order, each once (a triangle
    // crossing blocks was binned, and reached its leaf, in each).
    std::mutex load_mutex;  // TriangleBins::load is not thread-safe
    tbb::parallel_for(size_t(0), spanning.block_count(), [&](size_t n) {
        std::vector<TriangleRecord> gathered;
        {
            std::lock_guard lock(load_mutex);
            spanning.load(n, gathered);
        }
        std::sort(gathered.begin(), gathered.end(),
                  [](const TriangleRecord& a, const TriangleRecord& b) { return a.sequence < b.sequence; });
        gathered.erase(std::unique(gathered.begin(), gathered.end(),
                                   [](const TriangleRecord& a, const TriangleRecord& b) { return a.sequence == b.sequence; }),
                       gathered.end());
        const SlotKey key = spanning_keys[spanning.block_key(n)];
        const Tetrahedron t = slot_tetrahedron(key);
        std::vector<ClipPlane> planes = tetrahedron_clip_planes(t, 0xf);
        WorkFragment fragment;
        FragmentWelder welder(fragment);
        welder.reserve(gathered.size() * 5 / 8 + 64, gathered.size() * 9 / 8 + 16);
        for (const TriangleRecord& r : gathered) {
            if (strictly_inside(t, r.positions.data(), 3))
                welder.add_whole(r.positions, r.normals, r.colors);
            else
                welder.add_clipped(r.positions, r.normals, r.colors, planes);
        }
        if (!fragment.indices.empty()) fragments_->put(key, std::move(fragment));
    });
    report_.leaves_across_blocks = spanning.block_count();
    bytes_spilled_ += spanning.bytes_spilled();
    bytes_spilled_ += bins.bytes_spilled();
    return_free_memory(warm_heap_.get());
}

double CatpBuild::quantization_step(const DiamondInfo& info, const std::array<const WorkFragment*, 8>& slots) const {
    double longest = 0;
    for (int s = 0; s < 8; ++s)
        if (slots[s] && !slots[s]->indices.empty())
            longest = std::max(longest, tetrahedron_longest_edge(diamond_tetrahedron(info, s)));
    return longest / layout_.grid;
}

// Writes the node of a diamond whose fragments are final and sets *stored to its stored error
// bound (lattice units): see DiamondError. A node that draws nothing waits for its level's other
// nodes (finish_empty_nodes), and *stored is set then.
void CatpBuild::write_node(DiamondId id, const DiamondInfo& info, const std::array<const WorkFragment*, 8>& slots,
                           double unquantized_error, double children_stored, bool leaf, double* stored) {
    DiamondFragments node;
    PreparedNode prepared;
    std::vector<QuantizedSlot> quantized;
    quantized.reserve(8);
    for (int s = 0; s < 8; ++s) {
        if (!slots[s] || slots[s]->indices.empty()) continue;
        Tetrahedron t = canonical_tetrahedron(diamond_tetrahedron(info, s));
        QuantizedSlot& q = quantized.emplace_back();
        q.in = slots[s];
        q.out = &node.slots[s];
        q.corners = t;
        quantize_fragment(*slots[s], t, layout_, node.slots[s], &q.trace);
        if (node.slots[s].indices.empty()) continue;
        node.slot_mask |= uint8_t(1 << s);
        prepared.triangles += node.slots[s].triangle_count();
        prepared.vertices += node.slots[s].vertices.size();
    }
    // Thin geometry the grid cannot hold is drawn nowhere: the bound must cover its distance to
    // what is drawn.
    prepared.step = quantization_step(info, slots);
    const double step = prepared.step;
    // At the leaves, pieces along a face up to four mean input edges long, and a quarter of the
    // tetrahedron, are clipping slivers whose triangle goes on, drawn, in the neighbour: not
    // needles (which span the tetrahedron, and may be the input's typical triangle: the Slivers
    // hard case). Coarser levels excuse nothing: there every neighbour may lose the same thin
    // geometry (Slivers' coarse levels draw nothing at all).
    const double excuse = leaf ? std::min(4 * mean_edge_, step * layout_.grid / 4) : 0.0;
    prepared.loss = quantization_loss(quantized, step / 4, step, excuse, leaf);
    prepared.bytes = encode_diamond_node(node, &prepared.slot_bytes);
    prepared.entry.key = id.bits;
    prepared.entry.level = uint16_t(info.level);
    prepared.entry.flags = uint16_t(node.slot_mask) | (leaf ? kCatpLeafFlag : 0);
    prepared.entry.count = uint32_t(prepared.triangles);
    prepared.unquantized = unquantized_error;
    prepared.children_stored = children_stored;
    prepared.leaf = leaf;
    prepared.stored = stored;
    if (prepared.loss.nothing_drawn) {
        prepared.reach = lost_geometry_reach(info, slots);
        std::lock_guard lock(stats_mutex_);
        empty_nodes_.push_back(std::move(prepared));
        return;
    }
    commit_node(prepared, prepared.loss.error);
}

// Writes a prepared node whose lost geometry lies within `lost` (lattice units) of what is drawn.
void CatpBuild::commit_node(PreparedNode& node, double lost) {
    const double stored = std::max(node.unquantized + std::max(node.step, lost), node.children_stored);
    ArchiveEntry& entry = node.entry;
    entry.error = float(stored * place_.cell);
    archive_->add_node(entry, node.bytes.data(), node.bytes.size());
    *node.stored = stored;
    std::lock_guard lock(stats_mutex_);
    entry.size = uint32_t(node.bytes.size());
    slot_bytes_[{entry.level, entry.key}] = {entry, std::move(node.slot_bytes)};
    if (!node.loss.nothing_drawn) drawn_max_stored_ = std::max(drawn_max_stored_, stored);
    if (node.leaf) {
        const double area = place_.cell * place_.cell;
        report_.lost_triangles += node.loss.triangles;
        report_.lost_area += node.loss.area * area;
        report_.lost_error = std::max(report_.lost_error, lost * place_.cell);
        report_.lost_beyond_step |= lost > 2 * node.step;
    }
    CatpLevelStats& s = stats_[entry.level];
    s.diamonds++;
    s.fragments += size_t(__builtin_popcount(entry.flags & 0xff));
    s.triangles += node.triangles;
    s.vertices += node.vertices;
    s.bytes += node.bytes.size();
    s.max_error = std::max(s.max_error, double(entry.error));
    s.empty_diamonds += node.loss.nothing_drawn;
}

// Writes the nodes of the level just made that draw nothing. Where all their geometry reaches
// their diamonds' outer faces (lost_geometry_reach), the surface goes on into neighbours of the
// same level, which draw it within their bounds: a point of it is within the diameters of the
// empty nodes it may cross (all of them, at most) plus the level's largest bound of a node that
// draws something. Else (a piece alone inside, or a level that draws nothing at all, as the
// Slivers hard case's coarse levels) nothing local bounds it, and the model's diagonal does.
// (The diagonal for every empty node made the whole chain of its ancestors carry it, by
// monotonicity: a 1M uneven-density mesh had 101 such diamonds down to level 15, and a client
// drew 289 nodes for a 64 x 48 view of it.)
void CatpBuild::finish_empty_nodes() {
    const double diagonal = bounds_.diagonal() / place_.cell;
    // In key order: threads queued them in any order, and the sum must not depend on it.
    std::sort(empty_nodes_.begin(), empty_nodes_.end(),
              [](const PreparedNode& a, const PreparedNode& b) { return a.entry.key < b.entry.key; });
    double chain = 0;
    for (const PreparedNode& node : empty_nodes_) chain += node.reach.diameter;
    for (PreparedNode& node : empty_nodes_) {
        const bool local = node.reach.anchored && drawn_max_stored_ >= 0;
        commit_node(node, local ? std::min(diagonal, chain + drawn_max_stored_) : diagonal);
    }
    empty_nodes_.clear();
    drawn_max_stored_ = -1;
}

// Ranges [begin, end) of 0..count over which group_of(index) is constant (sorted input).
template <typename GroupOf>
std::vector<std::pair<size_t, size_t>> group_runs(size_t count, GroupOf group_of) {
    std::vector<std::pair<size_t, size_t>> runs;
    for (size_t i = 0; i < count;) {
        size_t j = i + 1;
        while (j < count && group_of(j) == group_of(i)) ++j;
        runs.push_back({i, j});
        i = j;
    }
    return runs;
}

// Leaves sit at several levels: they are written deepest level first, so that a leaf's bound
// covers its leaf children's (a leaf may have a child present, one its other parent made), and
// a level's empty nodes are settled with that level.
void CatpBuild::write_leaf_nodes() {
    std::vector<SpilledFragment>& refs = fragments_->fragments();
    auto level_of = [](const SpilledFragment& f) { return diamond_level(DiamondId{f.key.diamond}); };
    std::sort(refs.begin(), refs.end(), [&](const SpilledFragment& a, const SpilledFragment& b) {
        const int la = level_of(a), lb = level_of(b);
        return la != lb ? la > lb : a.key < b.key;
    });
    auto runs = group_runs(refs.size(), [&](size_t i) { return refs[i].key.diamond; });
    for (auto& run : runs) leaf_error_.emplace(refs[run.first].key.diamond, DiamondError{});
    progress_->set_total(runs.size());
    for (size_t first = 0; first < runs.size();) {
        const int level = level_of(refs[runs[first].first]);
        size_t last = first;
        while (last < runs.size() && level_of(refs[runs[last].first]) == level) ++last;
        tbb::parallel_for(first, last, [&](size_t i) {
            DiamondId id{refs[runs[i].first].key.diamond};
            DiamondInfo info = diamond_info(id);
            std::array<WorkFragment, 8> loaded;
            std::array<const WorkFragment*, 8> slots{};
            for (size_t k = runs[i].first; k < runs[i].second; ++k)
                slots[refs[k].key.slot] = &fragments_->get(refs[k], loaded[refs[k].key.slot]);
            double children = 0;  // leaves of deeper levels, written already
            for (DiamondId child : diamond_children(id)) {
                auto it = leaf_error_.find(child.bits);
                if (it != leaf_error_.end()) children = std::max(children, it->second.stored);
            }
            // Each diamond's own entry, written by this thread only (or by finish_empty_nodes).
            write_node(id, info, slots, 0.0, children, true, &leaf_error_.find(id.bits)->second.stored);
            progress_->add(1);
        });
        finish_empty_nodes();
        first = last;
    }
    // The deepest leaves there are (those the density allowed may hold no geometry).
    if (!refs.empty()) {
        levels_.leaf_level = report_.leaf_level = level_of(refs.front());
        report_.coarsest_leaf_level = level_of(refs.back());
    }
    // Kept while coarsening: each level gathers the leaves one level finer than itself.
    leaves_ = std::move(fragments_);
}

// One coarsening step: every diamond of `level` is made from the fragments of the finer level
// whose tetrahedra its refinement created (welded, simplified to about half, clipped into its
// own tetrahedra); its node is written and its fragments replace the finer level's.
void CatpBuild::coarsen_level(int level) {
    // The fragments one level finer: those the level below made, and the leaves there (sorted
    // deepest first by write_leaf_nodes: the next ones to gather are at leaf_next_).
    struct Input {
        SpilledFragment ref;
        FragmentSpill* spill;
    };
    std::vector<Input> inputs;
    if (fragments_)
        for (const SpilledFragment& f : fragments_->fragments()) inputs.push_back({f, fragments_.get()});
    std::vector<SpilledFragment>& leaves = leaves_->fragments();
    while (leaf_next_ < leaves.size() && diamond_level(DiamondId{leaves[leaf_next_].key.diamond}) == level + 1)
        inputs.push_back({leaves[leaf_next_++], leaves_.get()});
    uint64_t finer_triangles = 0;  // every fragment of the finer level is gathered by one diamond
    for (const Input& in : inputs) finer_triangles += in.ref.triangles;
    progress_->phase(strprintf("coarsening level %d of %d", level, levels_.leaf_level), finer_triangles, "tri");
    std::vector<uint64_t> parent_of(inputs.size());
    {
        std::vector<std::pair<uint64_t, size_t>> order(inputs.size());
        tbb::parallel_for(size_t(0), inputs.size(), [&](size_t i) {
            DiamondInfo child = diamond_info(DiamondId{inputs[i].ref.key.diamond});
            order[i] = {slot_parent(child, inputs[i].ref.key.slot).bits, i};
        });
        // Children in key order within a parent: welding order, hence the output, is fixed.
        std::sort(order.begin(), order.end(), [&](const auto& a, const auto& b) {
            return a.first != b.first ? a.first < b.first : inputs[a.second].ref.key < inputs[b.second].ref.key;
        });
        std::vector<Input> sorted(inputs.size());
        for (size_t i = 0; i < order.size(); ++i) {
            sorted[i] = inputs[order[i].second];
            parent_of[i] = order[i].first;
        }
        inputs = std::move(sorted);
    }
    auto runs = group_runs(inputs.size(), [&](size_t i) { return parent_of[i]; });
    auto next = std::make_unique<FragmentSpill>(output_, shares_->coarse_fragments_in_memory);
    std::vector<DiamondError> produced_error(runs.size());
    // Each thread's gathered and child fragments, cleared from diamond to diamond but kept for
    // the level: fresh arrays for every diamond made malloc search its bins of free chunks for
    // them (3.5% of the 10M scan's build, most of it cache misses on chunk headers). A thread
    // waiting inside coarsen_diamond may take up another diamond meanwhile: that one finds the
    // set in use and works in arrays of its own.
    struct Scratch {
        WorkFragment gathered, child;
        bool in_use = false;
    };
    tbb::enumerable_thread_specific<Scratch> scratches;
    auto coarsen_run = [&](size_t i) {
        DiamondId id{parent_of[runs[i].first]};
        DiamondInfo info = diamond_info(id);
        // Every child with geometry counts, also those whose gathered slots came from other
        // parents: that keeps the stored errors monotone along every parent-child edge.
        DiamondError children;
        for (DiamondId child : diamond_children(id)) {
            auto it = diamond_error_.find(child.bits);
            if (it == diamond_error_.end()) {
                it = leaf_error_.find(child.bits);
                if (it == leaf_error_.end()) continue;
            }
            children.unquantized = std::max(children.unquantized, it->second.unquantized);
            children.stored = std::max(children.stored, it->second.stored);
        }
        Scratch& mine = scratches.local();
        Scratch own;
        Scratch& scratch = mine.in_use ? own : mine;
        scratch.in_use = true;
        struct Release {
            Scratch& s;
            ~Release() { s.in_use = false; }
        } release{scratch};
        WorkFragment &gathered = scratch.gathered, &child = scratch.child;
        clear_keeping_capacity(gathered);
        {
            FragmentWelder welder(gathered);
            size_t vertices = 0, triangles = 0;
            for (size_t k = runs[i].first; k < runs[i].second; ++k) {
                vertices += inputs[k].ref.vertices;
                triangles += inputs[k].ref.triangles;
            }
            welder.reserve(vertices, triangles);
            for (size_t k = runs[i].first; k < runs[i].second; ++k) {
                welder.append(inputs[k].spill->get(inputs[k].ref, child));
                inputs[k].spill->release(inputs[k].ref);
            }
        }
        size_t gathered_triangles = gathered.indices.size() / 3;
        std::array<WorkFragment, 8> produced;
        double simplify_error = coarsen_diamond(info, gathered, produced);
        std::array<const WorkFragment*, 8> slots;
        for (int s = 0; s < 8; ++s) slots[s] = &produced[s];
        // Monotone: a diamond's error bounds its children's plus its own simplification.
        DiamondError& error = produced_error[i];
        error.unquantized = children.unquantized + simplify_error;
        write_node(id, info, slots, error.unquantized, children.stored, false, &error.stored);
        for (int s = 0; s < 8; ++s)
            if (!produced[s].indices.empty()) next->put(SlotKey{id.bits, s}, std::move(produced[s]));
        progress_->add(gathered_triangles);
    };
    // Diamonds too large for three quarters of one thread's allowance (kMemoryPerThread; the
    // quarter is the margin of the per-triangle estimate) go one at a time, after
    // the others, each still using every thread inside (coarsen_diamond's parallel steps), and
    // each after handing the heap's free memory back: where density varies, a level's largest
    // diamonds gather far more than its mean one, and on top of what glibc kept of the smaller
    // diamonds' memory they went past the budget (a 300k scan with a 2M-triangle sphere inside,
    // at 102 MiB: 106-110 MiB; trimmed first, 94-95 MiB). Scan-like meshes of even density
    // have none (the 10M scan's largest diamond gathers 65k triangles).
    std::vector<size_t> small, large;
    for (size_t i = 0; i < runs.size(); ++i) {
        uint64_t triangles = 0;
        for (size_t k = runs[i].first; k < runs[i].second; ++k) triangles += inputs[k].ref.triangles;
        (triangles * kCoarsenBytesPerTriangle > kMemoryPerThread * 3 / 4 ? large : small).push_back(i);
    }
    // Isolated: a thread that waits inside coarsen_diamond's parallel steps runs only that
    // diamond's tasks, never another diamond of the loop, so at most one diamond per thread is
    // in flight. Without it a waiting thread could take up a third diamond beside the two
    // running, past the threads' allowances. 1M uneven-density mesh, 2 threads at the smallest
    // budget (106 MiB), peaks of 8-16 runs: 92.7-107.4 MiB before; isolated, 93.0-103.2; with
    // the three-quarter rule above as well, 86.6-92.2 (the rule alone: 88.1-93.7). Build time
    // unchanged (1M scan, 5 alternated pairs: user time 12.79 against 12.94 s).
    tbb::parallel_for(size_t(0), small.size(), [&](size_t k) {
        tbb::this_task_arena::isolate([&] { coarsen_run(small[k]); });
    });
    for (size_t i : large) {
        return_free_memory(warm_heap_.get());
        coarsen_run(i);
    }
    finish_empty_nodes();
    if (fragments_) bytes_spilled_ += fragments_->bytes_spilled();
    fragments_ = std::move(next);
    // No return_free_memory() here: the next level reuses what this one freed, and trimming
    // every level made it fault all of it in again (250k page faults instead of 97k on the 10M
    // scan, 9% of the build's time; the peak was the same).
    diamond_error_.clear();
    for (size_t i = 0; i < runs.size(); ++i) diamond_error_[parent_of[runs[i].first]] = produced_error[i];
}

// The vertex layout, its grid and the final leaf level, from the precision asked for (after the
// binning pass measured the mean edge). Going deeper than the density's level keeps the blocks
// valid: they only need to be coarser than the leaves.
void CatpBuild::choose_layout_and_leaves() {
    if (edge_lengths_.count == 0) fail("the mesh has no triangles");
    mean_edge_ = edge_lengths_.mean();
    const Precision& asked = settings_.precision;
    precision_ = asked.model_units > 0 ? asked.model_units / place_.cell : asked.mean_edges * mean_edge_;
    if (!(precision_ > 0) || !std::isfinite(precision_))
        fail("the precision must be positive (asked: %g model units, or %g mean edges of %g)", asked.model_units,
             asked.mean_edges, mean_edge_ * place_.cell);
    std::vector<VertexLayoutKind> kinds;
    switch (settings_.layout) {
        case LayoutChoice::Rgb24: kinds = {VertexLayoutKind::Rgb24}; break;
        case LayoutChoice::Rgb18: kinds = {VertexLayoutKind::Rgb18}; break;
        case LayoutChoice::Position48: kinds = {VertexLayoutKind::Position48}; break;
        case LayoutChoice::Auto:
            kinds = in_.has_colors() ? std::vector{VertexLayoutKind::Rgb24, VertexLayoutKind::Rgb18}
                                     : std::vector{VertexLayoutKind::Position48};
            break;
    }
    const bool forced = settings_.leaf_level >= 0;
    PrecisionChoice choice = choose_precision(precision_, mean_level_, forced, kinds);
    layout_ = choice.layout;
    report_.density_leaf_level = mean_level_;
    // The precision's floor: no leaf is coarser than the coarsest level whose step, on the grid
    // chosen, reaches the precision (the choice's own level, or coarser when the grid has room).
    int floor = choice.leaf_level;
    if (!forced)
        while (floor > 0 && level_longest_edge(floor - 1) / layout_.grid <= precision_) --floor;
    refined_.floor = floor;
    levels_.leaf_level = std::max(floor, refined_.deepest);  // the deepest a leaf can be
    report_.leaf_level = levels_.leaf_level;
    report_.layout = layout_;
    report_.mean_edge = mean_edge_ * place_.cell;
    // The coarsest leaves' step: the largest.
    report_.leaf_step = level_longest_edge(floor) / layout_.grid * place_.cell;
    // What is guaranteed: the precision asked for, or (a forced leaf level that cannot reach
    // it) the leaves' step.
    report_.precision = std::max(precision_ * place_.cell, choice.reached ? 0.0 : report_.leaf_step);
    if (!choice.reached)
        report_.warnings.push_back(strprintf(
            "the precision asked for (%g) cannot be reached at the forced leaf level %d: the finest level is within %g",
            precision_ * place_.cell, choice.leaf_level, report_.leaf_step));
    stats_.resize(size_t(levels_.leaf_level) + 1);
    for (int l = 0; l <= levels_.leaf_level; ++l) stats_[size_t(l)].level = l;
}

void CatpBuild::finish_archive() {
    CatpMeta meta;
    for (int i = 0; i < 3; ++i) {
        meta.origin[i] = place_.origin[i];
        meta.bounds_min[i] = bounds_.min[i];
        meta.bounds_max[i] = bounds_.max[i];
    }
    meta.cell = place_.cell;
    meta.leaf_level = uint32_t(levels_.leaf_level);
    meta.flags = (in_.has_colors() ? 1u : 0u) | (in_.has_normals() ? 2u : 0u);
    meta.input_vertices = in_.vertex_count();
    meta.input_triangles = triangles_;
    meta.default_rgb = uint32_t(default_color_[0]) | (uint32_t(default_color_[1]) << 8) | (uint32_t(default_color_[2]) << 16);
    meta.layout = layout_;
    meta.up = settings_.up;
    meta.precision = report_.precision;
    meta.mean_edge = report_.mean_edge;
    std::vector<ArchiveEntry> entries;
    for (const auto& [node, slots] : slot_bytes_) {
        entries.push_back(slots.first);
        meta.slot_bytes.insert(meta.slot_bytes.end(), slots.second.begin(), slots.second.end());
    }
    report_.file_bytes = archive_->finish(encode_catp_meta(meta, entries));
}

CatpBuildReport CatpBuild::run() {
    double start = now_seconds();
    std::unique_ptr<tbb::global_control> threads;
    if (settings_.threads > 0)
        threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, settings_.threads);
    budget_ = settings_.memory_budget ? settings_.memory_budget : default_memory_budget();
    uint64_t minimum = minimum_memory_budget(settings_.threads);
    if (budget_ < minimum)
        fail("a memory budget of %.1f MiB is too small: with %u worker threads the converter needs at least %llu MiB",
             double(budget_) / (1 << 20), worker_threads(settings_.threads), (unsigned long long)(minimum >> 20));
    shares_ = std::make_unique<BudgetShares>(budget_ - (minimum - kMinimumDataMemory));
    report_.memory_budget = budget_;
    report_.input_vertices = in_.vertex_count();
    report_.dropped_input = in_.dropped();
    warm_heap_ = make_heap_warmup(budget_, in_.vertex_count());
    bool needs_normals = !in_.has_normals();
    // One phase per pass, each counting its own units exactly (a phase's total is known when it
    // begins), so no bar runs past its end.
    progress_ = std::make_unique<Progress>("convert", "reading vertices", in_.vertex_count(), "vert");
    if (!settings_.progress) progress_->silence();

    // Wall time per phase: each lap() ends one.
    double mark = start;
    auto lap = [&mark](double& seconds) {
        double now = now_seconds();
        seconds = now - mark;
        mark = now;
    };

    // ---- Read: vertices, placement, normals, levels.
    read_vertices();
    uint64_t estimate = in_.triangle_estimate();
    if (estimate == 0) fail("the mesh has no triangles");
    report_.diagonal = bounds_.diagonal();
    place_ = place_model(bounds_, settings_.centred_placement);
    if (needs_normals) {
        progress_->phase("computing normals", estimate, "tri");
        compute_normals();
    }
    for (Vec3d& p : sample_)
        for (int i = 0; i < 3; ++i) p[i] = (p[i] - place_.origin[i]) / place_.cell;
    const bool forced = settings_.leaf_level >= 0;
    if (settings_.leaf_level > kMaxLevel - 3)
        fail("leaf level %d is deeper than the lattice allows (%d)", settings_.leaf_level, kMaxLevel - 3);
    mean_level_ = forced ? settings_.leaf_level : choose_mean_level(sample_, estimate, settings_.leaf_triangles);
    if (forced) {
        refined_.floor = settings_.leaf_level;  // every leaf there, as asked
        refined_.deepest = settings_.leaf_level;
    } else {
        refined_ = choose_refined_diamonds(sample_, estimate, settings_.leaf_triangles, mean_level_);
    }
    // Blocks no finer than the deepest leaves the density asks for (coarser leaves gather their
    // triangles across blocks: build_leaves).
    levels_ = choose_block_octave(sample_, estimate, std::max(refined_.deepest, mean_level_), shares_->block_triangles);
    report_.block_level = 3 * levels_.block_octave;
    archive_ = std::make_unique<ArchiveWriter>(output_, ArchiveKind::Catp);

    to_lattice();
    lap(report_.seconds_read);

    // ---- Triangles into blocks, then leaves clipped block by block.
    auto bin_and_clip = [&](auto& bins, bool records_carry_vertices) {
        progress_->phase("binning triangles", estimate, "tri");
        bin_triangles(bins);
        lap(report_.seconds_bin);
        if (triangles_ == 0) fail("the mesh has no triangles");
        choose_layout_and_leaves();
        if (records_carry_vertices) {
            vertices_.reset();  // free the cache before the blocks are loaded
            return_free_memory(warm_heap_.get());
        }
        report_.input_triangles = triangles_;
        report_.blocks = bins.block_count();
        uint64_t binned = 0;  // triangles crossing block borders count once per block
        for (size_t b = 0; b < bins.block_count(); ++b) binned += bins.block_records(b);
        progress_->phase("clipping leaves", binned, "tri");
        build_leaves(bins);
    };
    report_.compact_bins = choose_bins(estimate);
    if (report_.compact_bins) {
        // Never flushed: choose_bins made sure they fit.
        TriangleBins<TriangleCorners> bins(output_, UINT64_MAX);
        bin_and_clip(bins, false);
    } else {
        TriangleBins<TriangleRecord> bins(output_, shares_->triangle_buffers);
        bin_and_clip(bins, true);
    }
    vertices_.reset();
    if (fragments_->fragments().empty())
        fail("none of the %llu triangles has an area: nothing to build", (unsigned long long)triangles_);
    lap(report_.seconds_clip);
    progress_->phase("encoding leaf nodes", 0, "nodes");
    write_leaf_nodes();
    lap(report_.seconds_leaf_nodes);

    // ---- Coarser levels, bottom-up.
    for (int level = levels_.leaf_level - 1; level >= 0; --level) coarsen_level(level);
    if (fragments_) bytes_spilled_ += fragments_->bytes_spilled();
    fragments_.reset();
    bytes_spilled_ += leaves_->bytes_spilled();
    leaves_.reset();
    lap(report_.seconds_coarsen);

    progress_->phase("writing " + output_, 0, "bytes");
    finish_archive();
    progress_->finish();
    lap(report_.seconds_write);
    stats_.resize(size_t(levels_.leaf_level) + 1);
    for (auto& s : stats_) {
        if (s.diamonds) report_.nodes += s.diamonds;
        report_.levels.push_back(s);
    }
    report_.bytes_spilled = bytes_spilled_;
    report_.seconds = now_seconds() - start;
    report_.peak_rss = peak_rss_bytes();
    return report_;
}

}  // namespace


bool parse_layout_choice(const std::string& text, LayoutChoice& out) {
    static const std::pair<const char*, LayoutChoice> kNames[] = {{"auto", LayoutChoice::Auto},
                                                                   {"rgb24", LayoutChoice::Rgb24},
                                                                   {"rgb18", LayoutChoice::Rgb18},
                                                                   {"position48", LayoutChoice::Position48}};
    for (auto& [name, choice] : kNames)
        if (text == name) {
            out = choice;
            return true;
        }
    return false;
}

uint64_t minimum_memory_budget(unsigned threads) {
    // At least two threads' allowance, also for one thread: a level's largest diamond, coarsened
    // alone (coarsen_level), may need up to twice one (its leaves are capped at kLargestLeafRatio
    // times the target, and it gathers several of them). A 300k scan with a 2M-triangle sphere
    // inside, one thread at 62 MiB: 65-66 MiB.
    return kMinimumDataMemory + kMemoryPerThread * std::max(2u, worker_threads(threads));
}

uint64_t default_memory_budget() {
    uint64_t physical = physical_memory_bytes();
    return std::max<uint64_t>(minimum_memory_budget(), physical ? physical / 2 : (uint64_t(4) << 30));
}

CatpBuildReport build_catp(const Mesh& mesh, const std::string& output_path, const CatpBuildSettings& settings) {
    if (mesh.triangle_count() == 0) fail("the mesh has no triangles");
    auto input = mesh_build_input(mesh);
    return naming_user_paths(output_path, [&] { return CatpBuild(*input, output_path, settings).run(); });
}

CatpBuildReport build_catp_file(const std::string& input_path, const std::string& output_path,
                                const CatpBuildSettings& settings) {
    auto input = file_build_input(input_path);
    return naming_user_paths(output_path, [&] { return CatpBuild(*input, output_path, settings).run(); });
}

}  // namespace catpaq
