// fetch_bench: where do the bytes a view fetches go?
//
// A close view of a large scan fetches far more of the dataset than the share of the surface it
// sees (docs/RESULTS.md 3.2: 70% of the file for 20% of the vertices in the frustum). The unit of
// fetching is a node: refining a diamond P needs every child C resident, and C carries all its
// slots, also those created by C's other parents (slot s of C is drawn only while
// slot_parent(C, s) is refined). This bench measures, on the converged cut a cold-start client
// reaches for a view, how those bytes split, to decide how to restructure fetching:
//
//  (a) node model (today): the bytes of every node with data the cut needs: refined nodes and
//      drawn nodes (what a cold-start client fetches at least);
//  (b) drawn: the slot fragments on screen (of each drawn node, the slots whose creating parent
//      is refined; all slots of an unrefined root);
//  (c) refinement-payload model: storing and fetching per refinement R(P) = the child slots that
//      refining P creates, plus the root's slots: sum of R(P) over the refined diamonds P;
//  (d) the share of the finest level (leaf diamonds: triangles by centroid, vertices, bytes
//      weighted by triangles) inside the view frustum (no occlusion);
//  (e) what closure and grown boxes add. The engine used to judge a diamond by a box grown to
//      hold all its descendants' (whose slots created by other parents lie outside it); it now
//      judges it by its view boxes (the tetrahedra holding geometry, client/hierarchy.h), so the
//      "cut" and "needed" columns agree. It refines with every ancestor (closure under parents). Two counterfactual refined sets separate the two:
//      "own": the refined diamonds whose own error, projected with the box of their own slots'
//      tetrahedra, exceeds the tolerance (not closed: not a valid cut); "needed": that set closed
//      under parents, which is what an engine judging own boxes converges to (checked: the
//      fixpoint of refining drawn own-error diamonds from the roots). needed - own is the
//      closure's share, cut - needed the grown boxes' share, under (a) and (c).
// Also the bytes whose node (a) or slot tetrahedron (b, c) lies entirely outside the frustum, and
// all of it per diamond level (a slot's bytes count at the level of the diamond holding it, one
// level finer than the refinement that creates it). Slot bytes are the payload's `u32 size | fragment`
// (catp/format.h); the node's `u8 slot_mask` is counted apart ("masks"). Identities checked for
// every closed set: (a) = (c) + undrawn slots of drawn nodes + masks, (c) = (b) + all slots of
// refined diamonds.
//
// The cut: the project's CutEngine (client/cut_engine.h) on the CATP hierarchy
// (build_catp_hierarchy), every node resident with its exact bytes and per-slot triangle counts
// (from decoding every node with CatpFormat::decode, as a session does on arrival), no budgets,
// the view built from the camera exactly as StreamingSession::step builds it; run until nothing
// changes.
// On the report's 2M-triangle scans (first and last views of its paths) `catpaq render FILE
// --camera-path VIEW --stats` fetched exactly the 64 KiB prefix probe plus (a), with the same
// requests, triangles, refined and drawn counts and certified error, when sessions fetched whole
// diamonds and dropped the probe's bytes past the prefix. Sessions now decode the nodes the probe
// holds whole from it: the cold-start line below subtracts them.
//
// usage: fetch_bench DATASET.cpq PATH.json [PATH.json ...] [--tolerance PX] [--json FILE]
//   Every frame of every camera path (the JSON of `catpaq render --camera-path`) is one view.
//   Prints a readable report per view and one JSON line per view (prefixed "json: "; --json FILE
//   also writes the bare lines to FILE).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "base/atomic_file.h"
#include "base/bytes.h"
#include "base/error.h"
#include "base/options.h"
#include "catp/dataset.h"
#include "catp/format.h"
#include "catp/lattice.h"
#include "catp_client/catp_format.h"
#include "client/camera.h"
#include "client/cut_engine.h"
#include "client/fetcher.h"
#include "client/hierarchy.h"

using namespace catpaq;

namespace {

const char* kUsage =
    "usage: fetch_bench DATASET.cpq PATH.json [PATH.json ...] [--tolerance PX] [--json FILE]\n"
    "  For every frame of every camera path: the converged cut with every node resident, and the\n"
    "  bytes it needs per node (today), per refinement payload, drawn, for closure and for grown\n"
    "  boxes, per level.\n"
    "  --tolerance PX  screen-space error tolerance in pixels (default 1.5)\n"
    "  --json FILE     also write one JSON line per view to FILE\n";

using Vec3 = std::array<double, 3>;

// ---------------------------------------------------------------------------------------------
// The dataset, decoded once

// One part of a node (a slot with geometry), in the order of HierarchyNode::parts.
struct PartInfo {
    uint32_t bytes = 0;  // u32 size + fragment, as stored in the payload
    Aabb box;            // world box of the slot's tetrahedron
};

struct NodeInfo {
    std::vector<PartInfo> parts;
    Aabb own_box;  // union of the parts' tetrahedra (the hierarchy grows boxes to hold descendants')
    double own_error = 0;
    NodeBytes memory;  // decoded sizes, as the session counts them
};

// The finest level in world coordinates: vertices, triangle centroids and each triangle's share
// of its slot's bytes.
struct FinestLevel {
    std::vector<Vec3> vertices, centroids;
    std::vector<double> triangle_bytes;
    size_t nodes = 0;
    double bytes = 0;
};

struct Dataset {
    std::unique_ptr<CatpFile> file;
    std::unique_ptr<CatpFormat> format;  // decodes as the session does (catp_client/catp_format.h)
    Hierarchy hierarchy;
    std::unique_ptr<PartDrawCounter> counter;
    std::vector<NodeInfo> nodes;  // by hierarchy node
    FinestLevel finest;
    uint64_t node_bytes = 0;      // sum of the payloads: the denominator of every fraction
    uint64_t prefix_bytes = 0;    // header + meta + index
    uint64_t local_prefix_read = 0;  // what fetch_prefix reads from a local file (64 KiB probe)
    int max_level = 0;
};

// Size of each slot's `u32 size | fragment` in a node payload (catp/format.h); 0 if absent.
std::array<uint32_t, 8> slot_sizes(const uint8_t* data, size_t size, uint64_t key) {
    std::array<uint32_t, 8> out{};
    ByteReader r(data, size);
    uint8_t mask = r.u8();
    for (int s = 0; s < 8; ++s) {
        if (!(mask & (1 << s))) continue;
        uint32_t n = r.u32();
        if (!r.take(n)) break;
        out[size_t(s)] = 4 + n;
    }
    if (!r.ok() || r.remaining() != 0) fail("diamond %llu: malformed payload", (unsigned long long)key);
    return out;
}

// World box of a tetrahedron given in lattice coordinates.
Aabb lattice_box_to_world(const CatpIndex& index, const Tetrahedron& t) {
    Aabb box;
    for (const LatticePoint& p : t) {
        double lattice[3] = {double(p[0]), double(p[1]), double(p[2])}, world[3];
        index.lattice_to_world(lattice, world);
        box.extend(Vec3{world[0], world[1], world[2]});
    }
    return box;
}

// Appends a leaf slot's vertices and triangles in world coordinates (exact integer decode).
void add_finest_slot(const CatpIndex& index, const DiamondInfo& info, int slot, const FragmentMesh& fragment,
                     uint32_t slot_bytes, FinestLevel& out) {
    std::vector<std::array<int64_t, 3>> integer;
    if (!decode_fragment_integer_positions(fragment, info, slot, integer))
        fail("diamond %llu slot %d: corrupt vertex", (unsigned long long)info.id.bits, slot);
    const CatpMeta& m = index.meta();
    size_t base = out.vertices.size();
    for (const auto& s : integer) {
        Vec3 p;
        for (int k = 0; k < 3; ++k) p[size_t(k)] = m.origin[k] + double(s[size_t(k)]) / m.layout.grid * m.cell;
        out.vertices.push_back(p);
    }
    size_t triangles = fragment.triangle_count();
    for (size_t t = 0; t < triangles; ++t) {
        Vec3 c{0, 0, 0};
        for (int k = 0; k < 3; ++k)
            for (int i = 0; i < 3; ++i) c[size_t(i)] += out.vertices[base + fragment.indices[3 * t + size_t(k)]][size_t(i)] / 3;
        out.centroids.push_back(c);
        out.triangle_bytes.push_back(double(slot_bytes) / double(triangles));
    }
    out.bytes += slot_bytes;
}

// Reads node n (with data): its slots' sizes and tetrahedra boxes, its exact draw counts (given to
// the counter) and decoded sizes; a leaf's geometry goes to the finest level.
void load_node(Dataset& d, uint32_t n) {
    const CatpIndex& index = d.file->index();
    const HierarchyNode& node = d.hierarchy.node(n);
    const ArchiveEntry& entry = index.entries()[node.entry];
    std::string error;
    const uint8_t* payload = d.file->archive().node(node.entry, &error);
    if (!payload) fail("%s", error.c_str());
    // The session's decode and accounting (CatpFormat::decode): sizes, exact per-slot counts.
    std::shared_ptr<const DecodedNode> decoded;
    std::string problem = d.format->decode(n, payload, entry.size, decoded);
    if (!problem.empty()) fail("diamond %llu: %s", (unsigned long long)node.key, problem.c_str());
    const DiamondFragments& fragments = catp_fragments(*decoded);
    std::array<uint32_t, 8> sizes = slot_sizes(payload, entry.size, node.key);
    DiamondInfo info = diamond_info(DiamondId{node.key});
    NodeInfo& out = d.nodes[n];
    out.own_error = std::max(0.0, double(entry.error));
    for (const HierarchyPart& part : node.parts) {
        PartInfo p{sizes[part.id], lattice_box_to_world(index, diamond_tetrahedron(info, part.id))};
        out.own_box.extend(p.box);
        out.parts.push_back(p);
        if (node.leaf) add_finest_slot(index, info, part.id, fragments.slots[part.id], p.bytes, d.finest);
    }
    d.finest.nodes += node.leaf;
    out.memory = decoded->bytes;
    d.counter->set_counts(n, decoded->part_primitives.data(), decoded->part_primitives.size());
    d.node_bytes += node.payload_bytes;
}

// Opens the dataset, builds the client's hierarchy and reads every node.
Dataset load_dataset(const std::string& path) {
    Dataset d;
    d.file = std::make_unique<CatpFile>(path);
    d.format = std::make_unique<CatpFormat>(
        DatasetPrefix::parse(d.file->archive().data(), d.file->archive().prefix_size(), path));
    d.hierarchy = d.format->hierarchy();
    d.counter = std::make_unique<PartDrawCounter>(d.hierarchy);
    d.nodes.resize(d.hierarchy.size());
    d.prefix_bytes = d.file->archive().prefix_size();
    d.local_prefix_read =
        std::min<uint64_t>(d.file->archive().size(), std::max<uint64_t>(d.prefix_bytes, kPrefixProbeBytes));
    for (uint32_t n = 0; n < d.hierarchy.size(); ++n) {
        d.max_level = std::max(d.max_level, int(d.hierarchy.node(n).level));
        if (d.hierarchy.node(n).has_data) load_node(d, n);
    }
    return d;
}

// How much bigger the hierarchy's boxes (grown to hold every descendant's) are than the nodes'
// own boxes: quantiles (10%, 50%, 90%, max) of the ratio of their diagonals over nodes with data.
std::array<double, 4> box_growth(const Dataset& d) {
    auto diagonal = [](const Aabb& b) {
        double s = 0;
        for (int i = 0; i < 3; ++i) s += (b.max[i] - b.min[i]) * (b.max[i] - b.min[i]);
        return std::sqrt(s);
    };
    std::vector<double> ratio;
    for (uint32_t n = 0; n < d.hierarchy.size(); ++n)
        if (d.hierarchy.node(n).has_data && !d.nodes[n].own_box.empty())
            ratio.push_back(diagonal(d.hierarchy.node(n).bounds) / diagonal(d.nodes[n].own_box));
    if (ratio.empty()) return {};
    std::sort(ratio.begin(), ratio.end());
    return {ratio[ratio.size() / 10], ratio[ratio.size() / 2], ratio[ratio.size() * 9 / 10], ratio.back()};
}

// ---------------------------------------------------------------------------------------------
// The converged cut of a view

// Everything resident, with the sizes decoding gave; nothing ever changes.
class AllResident : public Residency {
public:
    explicit AllResident(const std::vector<NodeInfo>& nodes) : nodes_(nodes) {}
    bool resident(uint32_t) const override { return true; }
    NodeBytes bytes(uint32_t node) const override { return nodes_[node].memory; }
    bool changes_since(uint64_t&, std::vector<uint32_t>&) const override { return true; }

private:
    const std::vector<NodeInfo>& nodes_;
};

// The view StreamingSession::step gives the engine for `camera` (client/src/session.cpp).
ViewParams view_of(const Camera& camera, const CatpMeta& m, double tolerance) {
    Camera cam = camera;
    if (!cam.has_clip_planes())
        cam.fit_clip_planes({m.bounds_min[0], m.bounds_min[1], m.bounds_min[2]},
                            {m.bounds_max[0], m.bounds_max[1], m.bounds_max[2]});
    ViewParams view = ViewParams::look_at({camera.eye.x, camera.eye.y, camera.eye.z},
                                          {camera.target.x, camera.target.y, camera.target.z},
                                          {camera.up.x, camera.up.y, camera.up.z},
                                          camera.fov_y_degrees * 3.14159265358979323846 / 180.0, camera.width,
                                          camera.height, cam.near_plane, cam.far_plane);
    view.tolerance_px = tolerance;
    return view;
}

// Runs the engine from the roots (a cold start) until a frame changes nothing.
void converge(CutEngine& engine, const ViewParams& view, const Residency& residency) {
    engine.reset();
    for (int frame = 0; frame < 1000; ++frame) {
        const CutFrame& f = engine.update(view, residency);
        if (f.stats.refinements == 0 && f.stats.coarsenings == 0) {
            std::string problem = engine.check(residency);
            if (!problem.empty()) fail("cut engine inconsistent: %s", problem.c_str());
            return;
        }
    }
    fail("the cut did not converge in 1000 frames");
}

// ---------------------------------------------------------------------------------------------
// Accounting

bool point_inside(const ViewParams& view, const Vec3& p) {
    for (const auto& pl : view.planes)
        if (pl[0] * p[0] + pl[1] * p[1] + pl[2] * p[2] + pl[3] < 0) return false;
    return true;
}

// Projected error of a node with its own error and the box of its own slots' tetrahedra (the
// engine uses boxes and errors grown to hold every descendant's): 0 outside the frustum.
double own_projected_error(const NodeInfo& node, const ViewParams& view) {
    if (node.own_box.empty() || !view.may_see(node.own_box)) return 0;
    return node.own_error * view.k() / std::max(node.own_box.distance_to(view.eye), view.near);
}

// Adds n and every ancestor of n to `set`.
void add_with_ancestors(const Hierarchy& h, uint32_t n, std::vector<uint8_t>& set) {
    if (set[n]) return;
    set[n] = 1;
    std::vector<uint32_t> stack{n};
    while (!stack.empty()) {
        uint32_t m = stack.back();
        stack.pop_back();
        for (uint32_t p : h.node(m).parents)
            if (!set[p]) {
                set[p] = 1;
                stack.push_back(p);
            }
    }
}

// Closure of `set` under parents.
std::vector<uint8_t> closure_under_parents(const Hierarchy& h, const std::vector<uint8_t>& set) {
    std::vector<uint8_t> out(h.size(), 0);
    for (uint32_t n = 0; n < h.size(); ++n)
        if (set[n]) add_with_ancestors(h, n, out);
    return out;
}

// The refined sets compared: the engine's converged cut; the cut an engine judging each diamond
// by its own box would reach (the own-error set closed under parents: "needed"); and the
// own-error diamonds alone (not closed, so not a valid cut: the closure's share).
enum SetKind { kCut = 0, kNeeded = 1, kOwn = 2, kSets = 3 };
const char* const kSetNames[kSets] = {"cut", "needed", "own"};
using RefinedSets = std::array<std::vector<uint8_t>, kSets>;

// The refined set an engine judging own boxes converges to from the roots: an own-error diamond
// is refined (with its closure) once it is drawn, i.e. a root or a child of a refined diamond.
// Equal to the closure of the own-error set when every own-error diamond is reachable that way.
std::vector<uint8_t> own_engine_fixpoint(const Hierarchy& h, const std::vector<uint8_t>& own) {
    std::vector<uint8_t> refined(h.size(), 0);
    for (bool changed = true; changed;) {
        changed = false;
        for (uint32_t n = 0; n < h.size(); ++n) {
            if (!own[n] || refined[n]) continue;
            bool drawn = h.node(n).parents.empty();
            for (uint32_t p : h.node(n).parents) drawn = drawn || refined[p];
            if (!drawn) continue;
            add_with_ancestors(h, n, refined);
            changed = true;
        }
    }
    return refined;
}

RefinedSets refined_sets(const Dataset& d, const CutEngine& engine, const ViewParams& view) {
    const Hierarchy& h = d.hierarchy;
    RefinedSets s;
    s[kCut].assign(h.size(), 0);
    s[kOwn].assign(h.size(), 0);
    for (uint32_t n : engine.refined_nodes()) {
        s[kCut][n] = 1;
        const HierarchyNode& node = h.node(n);
        s[kOwn][n] = node.has_data && !node.leaf && own_projected_error(d.nodes[n], view) > view.tolerance_px;
    }
    s[kNeeded] = closure_under_parents(h, s[kOwn]);
    if (own_engine_fixpoint(h, s[kOwn]) != s[kNeeded])
        fail("an own-box engine would not reach the closure of the own-error diamonds");
    for (uint32_t n = 0; n < h.size(); ++n)
        if (s[kNeeded][n] && !s[kCut][n]) fail("the closure of the own-error diamonds is not inside the cut");
    return s;
}

// Bytes of one diamond level (or of all levels) for one refined set R. A data node is fetched
// under the node model when it is refined or drawn (not refined, and a root or a child of R).
struct LevelBytes {
    uint64_t nodes_a = 0;    // data nodes fetched under the node model
    uint64_t a = 0;          // (a) their payloads
    uint64_t refined = 0;    //   of which refined nodes
    uint64_t drawn = 0;      //   (b) drawn slots: of drawn nodes, created by a refined parent (or root)
    uint64_t undrawn = 0;    //   slots of drawn nodes whose creating parent is not refined
    uint64_t masks = 0;      //   slot_mask bytes
    uint64_t c = 0;          // (c) slots created by a refined diamond, and the root's
    uint64_t outside_a = 0;  // (a) nodes whose slots' tetrahedra are all outside the frustum
    uint64_t outside_b = 0;  // (b) drawn slots whose tetrahedron is outside the frustum
    uint64_t outside_c = 0;  // (c) slots whose tetrahedron is outside the frustum
    uint64_t in_probe = 0;   // (a) nodes a local session's first read (the 64 KiB probe) holds whole

    void add(const LevelBytes& o) {
        nodes_a += o.nodes_a, a += o.a, refined += o.refined, drawn += o.drawn, undrawn += o.undrawn;
        masks += o.masks, c += o.c, outside_a += o.outside_a, outside_b += o.outside_b, outside_c += o.outside_c;
        in_probe += o.in_probe;
    }
};

bool is_drawn(const Hierarchy& h, const std::vector<uint8_t>& refined, uint32_t n) {
    if (refined[n]) return false;
    const HierarchyNode& node = h.node(n);
    if (node.parents.empty()) return true;
    for (uint32_t p : node.parents)
        if (refined[p]) return true;
    return false;
}

// Adds data node n's bytes under every model to `row`.
void account_node(const Dataset& d, const ViewParams& view, const std::vector<uint8_t>& refined, uint32_t n,
                  LevelBytes& row) {
    const HierarchyNode& node = d.hierarchy.node(n);
    const NodeInfo& info = d.nodes[n];
    bool drawn = is_drawn(d.hierarchy, refined, n);
    if (!refined[n] && !drawn) return;  // nothing of it is needed (no creating parent is refined)
    uint64_t slot_total = 0;
    for (const PartInfo& p : info.parts) slot_total += p.bytes;
    row.nodes_a++;
    row.a += node.payload_bytes;
    if (node.payload_offset >= d.prefix_bytes && node.payload_offset + node.payload_bytes <= d.local_prefix_read)
        row.in_probe += node.payload_bytes;
    row.masks += node.payload_bytes - slot_total;
    if (refined[n]) row.refined += node.payload_bytes;
    if (info.own_box.empty() || !view.may_see(info.own_box)) row.outside_a += node.payload_bytes;
    for (size_t i = 0; i < node.parts.size(); ++i) {
        uint32_t creator = node.parts[i].parent;
        bool created = creator == kNoNode || refined[creator];
        uint32_t bytes = info.parts[i].bytes;
        bool outside = !view.may_see(info.parts[i].box);
        if (drawn) {
            (created ? row.drawn : row.undrawn) += bytes;
            if (created && outside) row.outside_b += bytes;
        }
        if (!created) continue;
        row.c += bytes;
        if (outside) row.outside_c += bytes;
    }
}

std::vector<LevelBytes> account(const Dataset& d, const ViewParams& view, const std::vector<uint8_t>& refined) {
    std::vector<LevelBytes> levels(size_t(d.max_level) + 1);
    for (uint32_t n = 0; n < d.hierarchy.size(); ++n)
        if (d.hierarchy.node(n).has_data) account_node(d, view, refined, n, levels[d.hierarchy.node(n).level]);
    return levels;
}

// For a set closed under parents: (a) = (c) + undrawn + masks, and (c) = (b) + every slot of the
// refined diamonds (their parents are all refined).
void check_identities(const Dataset& d, const std::vector<uint8_t>& refined, const LevelBytes& t) {
    uint64_t refined_slots = 0;
    for (uint32_t n = 0; n < d.hierarchy.size(); ++n)
        if (refined[n])
            for (const PartInfo& p : d.nodes[n].parts) refined_slots += p.bytes;
    if (t.a != t.c + t.undrawn + t.masks || t.c != t.drawn + refined_slots)
        fail("accounting identities do not hold (a %llu, c %llu, b %llu)", (unsigned long long)t.a,
             (unsigned long long)t.c, (unsigned long long)t.drawn);
}

struct FinestShare {
    double triangles = 0, vertices = 0, bytes = 0;  // fractions of the finest level inside the frustum
    double bytes_inside = 0;
};

// The share of the finest level inside the frustum (triangles by their centroid).
FinestShare finest_share(const FinestLevel& f, const ViewParams& view) {
    FinestShare s;
    size_t v_in = 0, t_in = 0;
    for (const Vec3& p : f.vertices) v_in += point_inside(view, p);
    for (size_t t = 0; t < f.centroids.size(); ++t)
        if (point_inside(view, f.centroids[t])) {
            t_in++;
            s.bytes_inside += f.triangle_bytes[t];
        }
    s.vertices = f.vertices.empty() ? 0 : double(v_in) / double(f.vertices.size());
    s.triangles = f.centroids.empty() ? 0 : double(t_in) / double(f.centroids.size());
    s.bytes = f.bytes > 0 ? s.bytes_inside / f.bytes : 0;
    return s;
}

struct ViewReport {
    std::string label;
    uint64_t triangles = 0;
    double certified_px = 0;
    std::array<size_t, kSets> refined{}, refined_virtual{};
    // Per set: triangles drawn, and the largest projected error of a drawn data node measured
    // with its own box (what an engine judging own boxes would certify).
    std::array<uint64_t, kSets> set_triangles{};
    std::array<double, kSets> own_certified_px{};
    size_t drawn = 0, drawn_data = 0, drawn_nothing = 0;  // of the cut; nothing: no triangle in a drawn slot
    std::array<std::vector<LevelBytes>, kSets> levels;
    std::array<LevelBytes, kSets> total;
    FinestShare finest;
};

// Triangles drawn by refined set `refined`, and the largest own-box projected error of its drawn
// data nodes.
void drawn_quality(const Dataset& d, const ViewParams& view, const std::vector<uint8_t>& refined, uint64_t& triangles,
                   double& own_certified) {
    triangles = 0;
    own_certified = 0;
    for (uint32_t n = 0; n < d.hierarchy.size(); ++n) {
        if (!d.hierarchy.node(n).has_data || !is_drawn(d.hierarchy, refined, n)) continue;
        triangles += d.counter->count(n, RefinedView{refined.data()});
        own_certified = std::max(own_certified, own_projected_error(d.nodes[n], view));
    }
}

// The engine's drawn nodes are the ones the accounting calls drawn; counts those drawing nothing.
void count_drawn(const Dataset& d, const CutEngine& engine, const std::vector<uint8_t>& cut, ViewReport& r) {
    size_t data_drawn = 0;
    for (uint32_t n = 0; n < d.hierarchy.size(); ++n)
        if (d.hierarchy.node(n).has_data && is_drawn(d.hierarchy, cut, n) != engine.drawn(n))
            fail("node %llu: drawn set differs from the engine's", (unsigned long long)d.hierarchy.node(n).key);
    for (uint32_t n : engine.drawn_nodes()) {
        r.drawn++;
        if (!d.hierarchy.node(n).has_data) continue;
        data_drawn++;
        r.drawn_nothing += d.counter->count(n, RefinedView{cut.data()}) == 0;
    }
    r.drawn_data = data_drawn;
}

ViewReport measure_view(const Dataset& d, CutEngine& engine, const Residency& residency, const ViewParams& view,
                        const std::string& label) {
    converge(engine, view, residency);
    ViewReport r;
    r.label = label;
    r.triangles = engine.last_frame().stats.primitives;
    r.certified_px = engine.last_frame().stats.certified_error_px;
    RefinedSets sets = refined_sets(d, engine, view);
    for (int s = 0; s < kSets; ++s) {
        for (uint32_t n = 0; n < d.hierarchy.size(); ++n) {
            r.refined[s] += sets[s][n];
            r.refined_virtual[s] += sets[s][n] && !d.hierarchy.node(n).has_data;
        }
        r.levels[s] = account(d, view, sets[s]);
        for (const LevelBytes& l : r.levels[s]) r.total[s].add(l);
        if (s != kOwn) check_identities(d, sets[s], r.total[s]);
        drawn_quality(d, view, sets[s], r.set_triangles[s], r.own_certified_px[s]);
    }
    count_drawn(d, engine, sets[kCut], r);
    r.finest = finest_share(d.finest, view);
    return r;
}

// ---------------------------------------------------------------------------------------------
// Output

std::string grouped(uint64_t v) {
    std::string s = std::to_string(v), out;
    for (size_t i = 0; i < s.size(); ++i) {
        if (i && (s.size() - i) % 3 == 0) out += ',';
        out += s[i];
    }
    return out;
}

std::string with_share(uint64_t v, uint64_t of) {
    return strprintf("%s %5.1f%%", grouped(v).c_str(), of ? 100.0 * double(v) / double(of) : 0.0);
}

// One row of the summary: a quantity for the three refined sets, bytes and share of the dataset.
void print_row(const char* name, const ViewReport& r, uint64_t all, uint64_t (*get)(const LevelBytes&)) {
    std::printf("  %-40s", name);
    for (int s = 0; s < kSets; ++s) std::printf(" %20s", with_share(get(r.total[s]), all).c_str());
    std::printf("\n");
}

void print_summary(const ViewReport& r, uint64_t all) {
    std::printf("  %-40s %20s %20s %20s\n", "bytes (share of the dataset's nodes)", "cut (engine)", "needed (own boxes)",
                "own error (unclosed)");
    std::printf("  %-40s", "refined diamonds (virtual)");
    for (int s = 0; s < kSets; ++s) std::printf(" %20s", strprintf("%zu (%zu)", r.refined[s], r.refined_virtual[s]).c_str());
    std::printf("\n");
    std::printf("  %-40s", "triangles drawn, own-box certified px");
    for (int s = 0; s < kSets; ++s)
        std::printf(" %20s", strprintf("%s, %.2f", grouped(r.set_triangles[s]).c_str(), r.own_certified_px[s]).c_str());
    std::printf("\n");
    print_row("(a) node model: refined + drawn nodes", r, all, [](const LevelBytes& b) { return b.a; });
    print_row("    refined nodes", r, all, [](const LevelBytes& b) { return b.refined; });
    print_row("    drawn slots of drawn nodes = (b)", r, all, [](const LevelBytes& b) { return b.drawn; });
    print_row("    undrawn slots of drawn nodes", r, all, [](const LevelBytes& b) { return b.undrawn; });
    print_row("    slot masks", r, all, [](const LevelBytes& b) { return b.masks; });
    print_row("(c) refinement payloads + root", r, all, [](const LevelBytes& b) { return b.c; });
    print_row("    slots of refined diamonds", r, all, [](const LevelBytes& b) { return b.c - b.drawn; });
    print_row("(b) drawn slots", r, all, [](const LevelBytes& b) { return b.drawn; });
    print_row("(a) nodes entirely outside the frustum", r, all, [](const LevelBytes& b) { return b.outside_a; });
    print_row("(b) drawn slots outside the frustum", r, all, [](const LevelBytes& b) { return b.outside_b; });
    print_row("(c) payload slots outside the frustum", r, all, [](const LevelBytes& b) { return b.outside_c; });
    print_row("(b) drawn slots in the frustum", r, all, [](const LevelBytes& b) { return b.drawn - b.outside_b; });
    print_row("(c) payload slots in the frustum", r, all, [](const LevelBytes& b) { return b.c - b.outside_c; });
}

// Per level, for the engine's cut: the node model's parts, the refinement payloads, and what
// closure (needed minus own) and grown boxes (cut minus needed) add to each model.
void print_levels(const ViewReport& r) {
    std::printf("  %5s %5s %10s %10s %10s %10s %10s %10s %10s %10s %10s %10s\n", "level", "nodes", "(a) node",
                "refined", "drawn(b)", "undrawn", "(c) R(P)", "clos.(a)", "clos.(c)", "boxes(a)", "boxes(c)", "out(a)");
    for (size_t l = 0; l < r.levels[kCut].size(); ++l) {
        const LevelBytes& b = r.levels[kCut][l];
        const LevelBytes& n = r.levels[kNeeded][l];
        const LevelBytes& o = r.levels[kOwn][l];
        if (!b.nodes_a) continue;
        std::printf("  %5zu %5llu %10s %10s %10s %10s %10s %10s %10s %10s %10s %10s\n", l, (unsigned long long)b.nodes_a,
                    grouped(b.a).c_str(), grouped(b.refined).c_str(), grouped(b.drawn).c_str(),
                    grouped(b.undrawn).c_str(), grouped(b.c).c_str(), grouped(n.a - o.a).c_str(),
                    grouped(n.c - o.c).c_str(), grouped(b.a - n.a).c_str(), grouped(b.c - n.c).c_str(),
                    grouped(b.outside_a).c_str());
    }
}

void print_report(const Dataset& d, const ViewReport& r, double tolerance) {
    const LevelBytes& t = r.total[kCut];
    std::printf("\nview %s (tolerance %.3g px): %s triangles drawn, certified %.3g px, %zu drawn nodes (%zu with data, "
                "%zu drawing nothing)\n",
                r.label.c_str(), tolerance, grouped(r.triangles).c_str(), r.certified_px, r.drawn, r.drawn_data,
                r.drawn_nothing);
    print_summary(r, d.node_bytes);
    std::printf("  (e) closure (needed - own): (a) %s, (c) %s; grown boxes (cut - needed): (a) %s, (c) %s\n",
                with_share(r.total[kNeeded].a - r.total[kOwn].a, d.node_bytes).c_str(),
                with_share(r.total[kNeeded].c - r.total[kOwn].c, d.node_bytes).c_str(),
                with_share(t.a - r.total[kNeeded].a, d.node_bytes).c_str(),
                with_share(t.c - r.total[kNeeded].c, d.node_bytes).c_str());
    std::printf("  (d) finest level (%zu leaf diamonds) in the frustum: %.1f%% of its triangles, %.1f%% of its vertices, "
                "%s bytes = %.1f%% of its bytes = %.1f%% of the dataset\n",
                d.finest.nodes, 100 * r.finest.triangles, 100 * r.finest.vertices,
                grouped(uint64_t(r.finest.bytes_inside)).c_str(), 100 * r.finest.bytes,
                100 * r.finest.bytes_inside / double(d.node_bytes));
    std::printf("  a local cold start reads the %s-byte prefix probe + (a) - what the probe holds of it (%s) = %s "
                "bytes\n",
                grouped(d.local_prefix_read).c_str(), grouped(t.in_probe).c_str(),
                grouped(d.local_prefix_read + t.a - t.in_probe).c_str());
    print_levels(r);
}

std::string level_json(const LevelBytes& b) {
    return strprintf("{\"nodes_a\":%llu,\"a\":%llu,\"refined\":%llu,\"drawn\":%llu,\"undrawn\":%llu,\"masks\":%llu,"
                     "\"c\":%llu,\"outside_a\":%llu,\"outside_b\":%llu,\"outside_c\":%llu}",
                     (unsigned long long)b.nodes_a, (unsigned long long)b.a, (unsigned long long)b.refined,
                     (unsigned long long)b.drawn, (unsigned long long)b.undrawn, (unsigned long long)b.masks,
                     (unsigned long long)b.c, (unsigned long long)b.outside_a, (unsigned long long)b.outside_b,
                     (unsigned long long)b.outside_c);
}

// {"cut": ..., "needed": ..., "own": ...} of one level (or of the totals when level < 0).
std::string sets_json(const ViewReport& r, int level) {
    std::string out = "{";
    for (int s = 0; s < kSets; ++s) {
        const LevelBytes& b = level < 0 ? r.total[s] : r.levels[s][size_t(level)];
        out += strprintf("%s\"%s\":%s", s ? "," : "", kSetNames[s], level_json(b).c_str());
    }
    return out + "}";
}

std::string report_json(const std::string& dataset, const Dataset& d, const ViewReport& r, double tolerance) {
    std::string levels, refined, quality;
    for (size_t l = 0; l < r.levels[kCut].size(); ++l)
        if (r.levels[kCut][l].nodes_a)
            levels += strprintf("%s\"%zu\":%s", levels.empty() ? "" : ",", l, sets_json(r, int(l)).c_str());
    for (int s = 0; s < kSets; ++s) {
        refined += strprintf("%s\"%s\":[%zu,%zu]", s ? "," : "", kSetNames[s], r.refined[s], r.refined_virtual[s]);
        quality += strprintf("%s\"%s\":[%llu,%.4f]", s ? "," : "", kSetNames[s], (unsigned long long)r.set_triangles[s],
                             r.own_certified_px[s]);
    }
    return strprintf(
        "{\"dataset\":\"%s\",\"view\":\"%s\",\"tolerance_px\":%.4g,\"dataset_node_bytes\":%llu,\"prefix_bytes\":%llu,"
        "\"local_prefix_read\":%llu,\"triangles\":%llu,\"certified_px\":%.4f,\"refined_and_virtual\":{%s},"
        "\"triangles_and_own_certified_px\":{%s},"
        "\"drawn\":%zu,\"drawn_data\":%zu,\"drawn_nothing\":%zu,\"finest_triangles_in_frustum\":%.5f,"
        "\"finest_vertices_in_frustum\":%.5f,\"finest_bytes_in_frustum\":%.0f,\"total\":%s,\"levels\":{%s}}",
        dataset.c_str(), r.label.c_str(), tolerance, (unsigned long long)d.node_bytes,
        (unsigned long long)d.prefix_bytes, (unsigned long long)d.local_prefix_read, (unsigned long long)r.triangles,
        r.certified_px, refined.c_str(), quality.c_str(), r.drawn, r.drawn_data, r.drawn_nothing, r.finest.triangles,
        r.finest.vertices, r.finest.bytes_inside, sets_json(r, -1).c_str(), levels.c_str());
}

}  // namespace

int main(int argc, char** argv) try {
    Options options(argc, argv, kUsage);
    if (options.help()) {
        std::printf("%s", kUsage);
        return 0;
    }
    double tolerance = options.number("tolerance", 1.5, 0.01, 1e6);
    std::string json_path = options.get("json", "");
    options.finish();
    const std::vector<std::string>& args = options.positional();
    if (args.size() < 2) fail("expected a dataset and at least one camera path (see --help)");
    std::vector<std::pair<std::string, CameraPath>> paths;
    for (size_t i = 1; i < args.size(); ++i) paths.emplace_back(std::filesystem::path(args[i]).stem().string(), load_camera_path(args[i]));

    Dataset d = load_dataset(args[0]);
    std::printf("dataset %s: %zu nodes with data (%zu virtual), node bytes %s, prefix %s, finest level: %zu diamonds, "
                "%zu triangles\n",
                args[0].c_str(), d.hierarchy.data_count(), d.hierarchy.virtual_count(), grouped(d.node_bytes).c_str(),
                grouped(d.prefix_bytes).c_str(), d.finest.nodes, d.finest.centroids.size());
    std::array<double, 4> growth = box_growth(d);
    std::printf("hierarchy box / own box diagonal: 10%% %.2f, median %.2f, 90%% %.2f, max %.2f\n", growth[0], growth[1],
                growth[2], growth[3]);
    AllResident residency(d.nodes);
    CutEngine engine(d.hierarchy, *d.counter, CutBudgets{});
    std::string name = std::filesystem::path(args[0]).filename().string(), json;
    for (const auto& [stem, path] : paths)
        for (size_t f = 0; f < path.frames.size(); ++f) {
            ViewParams view = view_of(path.frames[f], d.file->index().meta(), tolerance);
            ViewReport r = measure_view(d, engine, residency, view, strprintf("%s#%zu", stem.c_str(), f));
            print_report(d, r, tolerance);
            std::string line = report_json(name, d, r, tolerance);
            std::printf("json: %s\n", line.c_str());
            json += line + "\n";
        }
    if (!json_path.empty()) write_file_atomic(json_path, json.data(), json.size());
    return 0;
} catch (const std::exception& e) {
    std::fprintf(stderr, "fetch_bench: %s\n", e.what());
    return 2;
}
