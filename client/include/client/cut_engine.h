#pragma once
// The view-dependent cut of a multiresolution DAG (client/hierarchy.h), one piece of code for
// every format.
//
// State: the refined set R, closed under parents, kept from frame to frame. The *active* nodes
// (drawn) are the nodes not in R with at least one parent in R, and the roots while unrefined;
// each draws the parts created by its refined parents. The *frontier* is the nodes of R without a
// refined child: the ones that can be coarsened next. Active and frontier nodes form the cut;
// the caches pin it (pinned()).
//
// Each frame, update():
//  1. recounts the cut (residency and exact draw counts may have changed since last frame);
//  2. coarsens frontier nodes whose projected error fell below tolerance * hysteresis and whose
//     data is resident (they are drawn again), cascading to parents that become frontier;
//  3. if a budget is exceeded (budgets lowered), coarsens the lowest-error frontier nodes until it
//     fits;
//  4. refines active nodes in order of decreasing projected error (a priority queue), while their
//     projected error exceeds the tolerance: a node P is refined together with the ancestors it
//     needs (closure under parents), only if what every child that would become drawn draws for
//     P is resident (Residency::ready(child, P): for a node fetched by parts, the parts P
//     creates; else the whole child) — otherwise P stays coarse and the missing data is
//     requested (never waits); with
//     skip_factor, a missing child close enough to the tolerance is refined with P instead, its
//     own children then needed in its place — and only if
//     the budgets still hold; when they do not, frontier nodes whose projected error is below
//     P's * hysteresis are coarsened to make room (all or nothing), so under a budget the cut
//     converges to the best one by projected error without thrashing. Virtual nodes (no data)
//     are refined only as ancestors a refinement needs, and coarsened as soon as they have no
//     refined child;
//  5. requests, each a fetch unit (CutRequest: a node, or the parts of it one parent creates):
//     what drawn nodes draw that is not resident first, then children needed by refinements
//     (priority: the projected error of the node that needs them), then nodes wanted for a
//     coarsening; ties coarse levels first. Nodes outside the frustum have projected error 0:
//     never refined for their own sake, and they request nothing. At most max_new_requests new
//     requests per frame; requests made earlier and no longer wanted are reported as cancelled.
//
// Projected error of a node: k * asin(error / d) pixels, d a lower bound of the distance from the
// eye to the node's geometry: the nearest of its view boxes in the frustum
// (HierarchyNode::view_boxes: for CATP the diamond's tetrahedra that hold geometry, its own or
// its descendants'), or the box of its decoded data when the residency knows it and it is
// farther (Residency::data_bounds), and up close, where the eye is nearer the box than the box is
// wide, the distance to the node's triangles themselves (Residency::data_distance); k = viewport
// height / (2 tan(fov / 2)) pixels per radian at the centre of the view. A surface point at
// distance >= d and a point within `error` of it are at most asin(error / d) apart as seen from
// the eye (for d > error; else anything up to pi, the whole view): an upper bound of the
// on-screen deviation that stays finite when the eye comes close (the former error * k / d
// reached 18,000 px with the eye inside a node's box). For error << d it is error * k / d.
// View boxes nest along parent edges and errors are monotone, so a node that needs refinement
// has a parent that needs it at least as much: refining from the roots reaches it. (The nodes'
// full bounds, which also hold what descendants add through their other parents, made close
// views refine diamonds for their neighbours' sake: 14-17% of the dataset on the report's close
// views, fetch_bench.)
#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "client/hierarchy.h"

namespace catpaq {

// k * asin(error / distance) pixels, or k * pi when error >= distance (see above).
double projected_error_px(double error, double distance, double k);

struct ViewParams {
    std::array<double, 3> eye{0, 0, 0};
    // Frustum planes in world coordinates, (a, b, c, d) with the inside where
    // a x + b y + c z + d >= 0. Ignored when use_frustum is false.
    std::array<std::array<double, 4>, 6> planes{};
    bool use_frustum = true;
    // Pixels per world unit at distance 1: pixels_per_unit if > 0, else
    // viewport_height / (2 tan(fov_y_radians / 2)).
    double pixels_per_unit = 0;
    double viewport_height = 0;
    double fov_y_radians = 0;
    double near = 1e-3;         // the near clip distance (world units): the near frustum plane
    double tolerance_px = 1.5;  // refine while the projected error exceeds this
    double hysteresis = 0.7;    // coarsen only below tolerance * hysteresis
    // Visibility hysteresis: a node leaving the frustum keeps its projected error for coarsening
    // decisions until its box, grown by frustum_margin times its distance from the eye (about
    // that many radians), is outside too — so nodes at the frustum's edge do not flip.
    double frustum_margin = 0.1;
    // Skipping levels: a refinement that needs a child that is not resident, and whose projected
    // error is within (1, skip_factor] times the tolerance, refines that child at once too
    // instead of waiting for it: the child would be refined again as soon as it is drawn, so its
    // data is never fetched (only what the view finally draws, and children coarser than
    // skip_factor times the tolerance as a preview). 0: never skip (every level is fetched).
    // A node whose fetches fail (Residency::failed) is never skipped through: its subtree takes
    // every level, so the rest of the view still refines around it. Ignored for a hierarchy whose
    // nodes decode against their parents (Hierarchy::decodes_against_parents: AQP's levels).
    double skip_factor = 0;

    double k() const;
    // Planes of an OpenGL view-projection matrix (clip = M * world, column-major, clip volume
    // -w <= x, y, z <= w), normalized.
    static std::array<std::array<double, 4>, 6> planes_from_view_projection(const std::array<double, 16>& m);
    // A perspective camera: eye looking at target, vertical fov, viewport size, clip distances.
    static ViewParams look_at(const std::array<double, 3>& eye, const std::array<double, 3>& target,
                              const std::array<double, 3>& up, double fov_y_radians, int width, int height,
                              double near, double far);
    // False if the box is certainly outside the frustum (conservative plane test); `grow`
    // enlarges the box by that much on every side first.
    bool may_see(const Aabb& box, double grow = 0) const;
};

// What a node costs while it is in the cut: GPU bytes while drawn, CPU (decoded) bytes while in
// the cut (drawn or frontier).
struct NodeBytes {
    uint64_t gpu = 0;
    uint64_t cpu = 0;
};

// Which parents are refined, for DrawCounter.
struct RefinedView {
    const uint8_t* flags = nullptr;
    bool operator()(uint32_t node) const { return node == kNoNode || flags[node] != 0; }
};

// Per-format: the exact number of primitives a node draws while unrefined, given which of its
// parents are refined (CATP: the triangles of the slots whose slot_parent is refined). May be an
// estimate for a node that is not resident; the engine only makes a node drawn once resident.
class DrawCounter {
public:
    virtual ~DrawCounter() = default;
    virtual uint64_t count(uint32_t node, const RefinedView& refined) const = 0;
};

// The generic counter over the hierarchy's parts: sums the parts whose parent is refined (or
// unconditional). Starts from the parts' index estimates; set_counts() gives exact ones.
class PartDrawCounter : public DrawCounter {
public:
    explicit PartDrawCounter(const Hierarchy& hierarchy);
    uint64_t count(uint32_t node, const RefinedView& refined) const override;
    // Exact primitives of each part of `node`, in the order of HierarchyNode::parts.
    void set_counts(uint32_t node, const uint32_t* counts, size_t n);
    // Exact primitives of one part (index in HierarchyNode::parts).
    void set_part_count(uint32_t node, size_t part, uint32_t count) { counts_[offsets_[node] + part] = count; }
    uint32_t part_count(uint32_t node, size_t part) const { return counts_[offsets_[node] + part]; }

private:
    std::vector<uint32_t> offsets_;
    std::vector<uint32_t> parents_;  // creating parent of each part (kNoNode: unconditional)
    std::vector<uint32_t> counts_;
};

// What the engine asks about data: loaded and decoded (resident), and what it costs.
class Residency {
public:
    virtual ~Residency() = default;
    // Virtual nodes (no data) are treated as resident whatever this says. For a node fetched by
    // parts (HierarchyNode::fetch_parts): every part resident.
    virtual bool resident(uint32_t node) const = 0;
    // What `node` draws while `parent` is refined is resident: the parts `parent` creates
    // (kNoNode: a root's parts). The engine asks only this; for nodes fetched whole it is
    // resident(node).
    virtual bool ready(uint32_t node, uint32_t parent) const {
        (void)parent;
        return resident(node);
    }
    // Exact when resident, an estimate otherwise.
    virtual NodeBytes bytes(uint32_t node) const = 0;
    // The box of a resident node's own data (world), or nullptr: where the node's geometry
    // really is, for the projected error (see above). Must lie within the hierarchy's box.
    virtual const Aabb* data_bounds(uint32_t node) const {
        (void)node;
        return nullptr;
    }
    // True for a node whose every fetch failed so far: a refinement that skips levels does not
    // wait on it, it takes every level (see ViewParams::skip_factor).
    virtual bool failed(uint32_t node) const {
        (void)node;
        return false;
    }
    // A lower bound of the distance from `eye` to a resident node's own geometry, or 0 if
    // unknown. Asked only of nodes whose data box is closer to the eye than it is wide: there
    // the box says little (the eye may be inside it, far from any triangle).
    virtual double data_distance(uint32_t node, const std::array<double, 3>& eye) const {
        (void)node;
        (void)eye;
        return 0;
    }
    // Optional change feed, so the engine recounts only what changed instead of the whole cut
    // each frame: appends the nodes whose residency, bytes or draw counts changed since `cursor`
    // and advances it. Returns false (cursor still advanced) when it cannot tell; the engine
    // then recounts everything, which is always correct.
    virtual bool changes_since(uint64_t& cursor, std::vector<uint32_t>& out) const {
        (void)cursor;
        (void)out;
        return false;
    }
};

// A bounded change feed for Residency implementations (a ring of the last `capacity` changes).
class ChangeLog {
public:
    explicit ChangeLog(size_t capacity = 8192) : ring_(capacity) {}
    void add(uint32_t node) { ring_[size_t(seq_++ % ring_.size())] = node; }
    bool since(uint64_t& cursor, std::vector<uint32_t>& out) const;

private:
    std::vector<uint32_t> ring_;
    uint64_t seq_ = 0;
};

// Which parts of each node are resident, with their bytes and data boxes: the bookkeeping of
// nodes fetched by parts (HierarchyNode::fetch_parts), shared by ResidencyTable and NodeStore.
// A node fetched whole is all its parts at once. Bytes and box of a node: the sums and union
// over its resident parts (a node fetched by parts that is drawn has the parts it draws).
class PartResidency {
public:
    explicit PartResidency(const Hierarchy& hierarchy);
    // Every part (the whole node) resident, or evicted.
    void set_node(uint32_t node, NodeBytes bytes, const Aabb& data);
    void clear_node(uint32_t node);
    // One part (index in HierarchyNode::parts) of a node fetched by parts.
    void set_part(uint32_t node, size_t part, NodeBytes bytes, const Aabb& data);
    void clear_part(uint32_t node, size_t part);

    bool any(uint32_t node) const { return mask_[node] != 0 || whole_[node]; }
    bool all(uint32_t node) const { return whole_[node] != 0; }
    bool part(uint32_t node, size_t part) const { return (mask_[node] >> part) & 1u; }
    // The parts `parent` creates are resident (true when it creates none).
    bool ready(uint32_t node, uint32_t parent) const;
    NodeBytes bytes(uint32_t node) const { return bytes_[node]; }
    const Aabb& data(uint32_t node) const { return data_[node]; }
    size_t resident_count() const { return count_; }

private:
    void total(uint32_t node);
    const Hierarchy& hierarchy_;
    std::vector<uint32_t> mask_, full_;  // resident parts, all parts (bit per part)
    std::vector<uint8_t> whole_;         // every part resident (also for a node without parts)
    std::vector<uint32_t> part_off_;
    std::vector<NodeBytes> part_bytes_;
    std::vector<Aabb> part_data_;
    std::vector<NodeBytes> bytes_;
    std::vector<Aabb> data_;
    size_t count_ = 0;  // nodes with every part resident
};

// A plain table: set_resident() on arrival, set_evicted() when a cache drops the node (exact
// draw counts given to a PartDrawCounter should come with set_resident()); for nodes fetched by
// parts, set_part_resident() and set_part_evicted().
// Non-resident estimate: `bytes_per_primitive` times the node's primitives, for GPU and CPU.
class ResidencyTable : public Residency {
public:
    explicit ResidencyTable(const Hierarchy& hierarchy, double bytes_per_primitive = 16.0);
    bool resident(uint32_t node) const override { return parts_.all(node); }
    bool ready(uint32_t node, uint32_t parent) const override { return parts_.ready(node, parent); }
    NodeBytes bytes(uint32_t node) const override;
    bool changes_since(uint64_t& cursor, std::vector<uint32_t>& out) const override { return log_.since(cursor, out); }
    const Aabb* data_bounds(uint32_t node) const override {
        return parts_.any(node) && !parts_.data(node).empty() ? &parts_.data(node) : nullptr;
    }
    double data_distance(uint32_t node, const std::array<double, 3>& eye) const override {
        return parts_.any(node) && distance_ ? distance_(node, eye) : 0.0;
    }
    // Measures data_distance (the owner knows the nodes' geometry).
    void set_distance_function(std::function<double(uint32_t, const std::array<double, 3>&)> f) {
        distance_ = std::move(f);
    }
    // `data`: the box of the node's decoded geometry, if known (empty: unknown).
    void set_resident(uint32_t node, NodeBytes bytes, const Aabb& data = Aabb{});
    void set_evicted(uint32_t node);
    // `part`: index in HierarchyNode::parts.
    void set_part_resident(uint32_t node, size_t part, NodeBytes bytes, const Aabb& data = Aabb{});
    void set_part_evicted(uint32_t node, size_t part);
    bool part_resident(uint32_t node, size_t part) const { return parts_.part(node, part); }
    bool any_resident(uint32_t node) const { return parts_.any(node); }
    bool failed(uint32_t node) const override { return failed_[node] != 0; }
    void set_failed(uint32_t node, bool failed) { failed_[node] = failed; }
    size_t resident_count() const { return parts_.resident_count(); }

private:
    const Hierarchy& hierarchy_;
    double bytes_per_primitive_;
    PartResidency parts_;
    std::vector<uint8_t> failed_;
    std::function<double(uint32_t, const std::array<double, 3>&)> distance_;
    ChangeLog log_;
};

struct CutBudgets {
    static constexpr uint64_t kUnlimited = std::numeric_limits<uint64_t>::max();
    uint64_t max_primitives = kUnlimited;  // primitives drawn
    uint64_t max_gpu_bytes = kUnlimited;   // sum over drawn nodes
    uint64_t max_cpu_bytes = kUnlimited;   // sum over the cut (drawn and frontier nodes)
    // New requests per frame: as many as may be outstanding, so that a cold start lists a level's
    // nodes in one frame and the fetcher can coalesce neighbours (AQP's small nodes: cold starts
    // of the 2M scan's views took 3-6x less time than at 16; at 1024 rather than 256, cold starts
    // of a 1M-triangle scan's five report views as AQP took 1.2-7x fewer requests for the same
    // bytes, while CATP's took the same requests and bytes). The fetcher still serves them
    // nearest first.
    uint32_t max_new_requests = 1024;
    uint32_t max_outstanding_requests = 1024;
    uint32_t max_refinements = std::numeric_limits<uint32_t>::max();  // per frame, closure included
};

enum class RequestReason : uint8_t { Drawn = 0, Refine = 1, Coarsen = 2 };

// A wanted fetch: a node, or for a node fetched by parts (HierarchyNode::fetch_parts) the parts
// of it that `parent` creates (kNoNode: a root's parts, or the whole node).
struct CutRequest {
    uint32_t node = kNoNode;
    uint64_t key = 0;
    uint16_t level = 0;
    RequestReason reason = RequestReason::Refine;
    double priority = 0;  // projected error (pixels) of the node that needs it
    uint32_t parent = kNoNode;
};

// Budgets, as bits of CutFrameStats::budgets_binding.
enum BudgetBit : uint8_t { kPrimitiveBudget = 1, kGpuBudget = 2, kCpuBudget = 4 };

struct CutFrameStats {
    uint64_t frame = 0;
    uint64_t primitives = 0, gpu_bytes = 0, cpu_bytes = 0;
    double certified_error_px = 0;  // max projected error over drawn nodes with data
    size_t drawn_nodes = 0, refined_nodes = 0, frontier_nodes = 0;
    size_t holes = 0;  // drawn nodes in the view with data that are not resident (draw nothing yet)
    uint32_t refinements = 0, coarsenings = 0;
    uint32_t budget_blocked = 0;  // refinements refused by a budget
    uint8_t budgets_binding = 0;  // which budgets refused them (BudgetBit)
    uint32_t waiting = 0;         // refinements waiting for data
    uint32_t capped = 0;          // refinements left for later frames (max_refinements)
    // Drawn finest-level nodes whose projected error exceeds the tolerance: nothing finer exists.
    uint32_t leaves_over_tolerance = 0;
    uint32_t new_requests = 0;
    bool over_budget = false;  // a budget is exceeded and coarsening could not fix it (yet)
    double seconds = 0;
};

struct CutFrame {
    CutFrameStats stats;
    std::vector<uint32_t> drawn;          // the active nodes
    std::vector<CutRequest> requests;     // every wanted fetch (earlier ones re-prioritised), best first
    std::vector<CutRequest> cancelled;    // earlier requests no longer wanted
};

class CutEngine {
public:
    // `hierarchy` and `counter` must outlive the engine.
    CutEngine(const Hierarchy& hierarchy, const DrawCounter& counter, CutBudgets budgets = {});

    const CutFrame& update(const ViewParams& view, const Residency& residency);

    void set_budgets(const CutBudgets& budgets) { budgets_ = budgets; }
    const CutBudgets& budgets() const { return budgets_; }
    const CutFrame& last_frame() const { return frame_; }

    bool refined(uint32_t node) const { return refined_[node] != 0; }
    bool drawn(uint32_t node) const;
    std::vector<uint32_t> refined_nodes() const;
    const std::vector<uint32_t>& drawn_nodes() const { return active_.items; }
    // The nodes with data in the cut (drawn and frontier): what caches must keep.
    std::vector<uint32_t> pinned() const;
    // The projected error of a node for the last view (pixels; 0 outside the frustum).
    double projected_error(uint32_t node) const;
    // Drops the whole cut (back to the roots) and the outstanding requests.
    void reset();

    // Recomputes everything from scratch and compares with the incremental state: R closed under
    // parents, the drawn and frontier sets, the totals. Empty string when consistent.
    std::string check(const Residency& residency) const;

private:
    struct DenseSet {
        std::vector<uint32_t> items;
        std::vector<uint32_t> pos;
        bool contains(uint32_t n) const { return pos[n] != kNoNode; }
        void insert(uint32_t n);
        void erase(uint32_t n);
    };
    struct Totals {
        uint64_t primitives = 0, gpu = 0, cpu = 0;
    };
    struct Op {
        uint32_t node;
        bool refine;
    };
    struct Want {
        RequestReason reason = RequestReason::Coarsen;
        double priority = -1;
    };

    struct Range {
        const uint32_t* b;
        const uint32_t* e;
        const uint32_t* begin() const { return b; }
        const uint32_t* end() const { return e; }
        bool empty() const { return b == e; }
    };
    Range parents(uint32_t n) const { return {par_.data() + par_off_[n], par_.data() + par_off_[n + 1]}; }
    Range children(uint32_t n) const { return {ch_.data() + ch_off_[n], ch_.data() + ch_off_[n + 1]}; }
    bool has_data(uint32_t n) const { return (flags_[n] & 1) != 0; }
    bool leaf(uint32_t n) const { return (flags_[n] & 2) != 0; }

    bool is_active(uint32_t n) const;
    bool is_frontier(uint32_t n) const { return refined_[n] && refined_children_[n] == 0; }
    // What n draws while `parent` is refined is resident (always for virtual nodes).
    bool ready(uint32_t n, uint32_t parent) const { return !has_data(n) || residency_->ready(n, parent); }
    // What n draws under its refined parents (a root: its parts) is resident.
    bool drawable(uint32_t n) const;
    // Fetch units: what one request names. For a node fetched by parts, one per parent edge
    // (the parts that parent creates: unit par_off_[n] + the parent's position in parents(n))
    // and one for a root's parts; for a node fetched whole, one (units_from_edges_ + n).
    uint32_t unit_of(uint32_t n, uint32_t parent) const;
    bool unit_ready(uint32_t u) const { return ready(unit_node_[u], unit_parent_[u]); }
    double proj(uint32_t n);       // 0 outside the frustum
    double keep_proj(uint32_t n);  // for coarsening: 0 only outside the grown frustum
    bool in_view(uint32_t n);
    void recount(uint32_t n);
    void set_refined(uint32_t n, bool on, std::vector<Op>* log);
    void revert(std::vector<Op>& log, size_t to);
    bool fits(const Totals& before) const;
    bool exceeds() const;
    void closure(uint32_t n, std::vector<uint32_t>& out);
    void add_closure(uint32_t n, std::vector<uint32_t>& out);  // to a set started by closure()
    void want(uint32_t n, uint32_t parent, RequestReason reason, double priority);
    // Wants every unit n needs to be drawn under its refined parents that is not resident.
    void want_drawable(uint32_t n, RequestReason reason, double priority);
    void coarsen_phase();
    bool try_coarsen(uint32_t n, std::vector<Op>& log);
    void enforce_budgets();
    void refine_phase();
    bool make_room(double limit, std::vector<Op>& log, const Totals& before);
    void emit_requests();

    const Hierarchy& h_;
    // The hierarchy in a compact layout for the per-frame loops (no pointer chasing).
    std::vector<uint32_t> par_off_, par_, ch_off_, ch_;
    std::vector<uint32_t> box_off_;           // view boxes of node n: box_[box_off_[n] .. box_off_[n + 1])
    std::vector<double> box_width_;           // the largest extent of their union
    std::vector<std::array<double, 6>> box_;  // min xyz, max xyz
    std::vector<double> error_;
    std::vector<uint8_t> flags_;  // bit 0 has data, bit 1 leaf, bit 2 fetched by parts
    std::vector<uint32_t> unit_node_, unit_parent_;  // per fetch unit (unit_of)
    uint32_t units_from_edges_ = 0;                  // units below this are parent edges
    std::vector<uint16_t> level_;
    const DrawCounter& counter_;
    CutBudgets budgets_;
    ViewParams view_;
    const Residency* residency_ = nullptr;
    double k_ = 1;
    uint64_t frame_number_ = 0;
    size_t refined_count_ = 0;

    std::vector<uint8_t> refined_;
    std::vector<uint32_t> refined_parents_, refined_children_;
    DenseSet active_, frontier_;
    std::vector<uint64_t> c_prim_, c_gpu_, c_cpu_;  // counted contributions
    Totals totals_;

    std::vector<double> proj_, keep_proj_;
    std::vector<uint8_t> visible_;
    std::vector<uint64_t> proj_frame_;
    std::vector<uint32_t> mark_;  // closure stamps
    uint32_t stamp_ = 0;
    std::vector<uint32_t> stack_;  // closure scratch
    const Residency* last_residency_ = nullptr;
    uint64_t residency_cursor_ = 0;
    bool full_refresh_ = true;
    std::vector<uint32_t> changed_;

    // Requests, by fetch unit.
    std::vector<Want> want_;
    std::vector<uint32_t> wanted_;       // units with a want this frame
    std::vector<uint8_t> outstanding_;
    std::vector<uint32_t> outstanding_list_;
    std::vector<uint64_t> want_frame_;

    std::vector<std::pair<double, uint32_t>> room_heap_;  // frontier min-heap for make_room
    bool room_heap_built_ = false;

    CutFrame frame_;
};

}  // namespace catpaq
