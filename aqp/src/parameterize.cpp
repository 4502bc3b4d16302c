// MAPS-style parameterization (Lee, Sweldens, Schroeder, Cowsar, Dobkin 1998), with half-edge
// collapses instead of vertex removals: the surface is simplified to the base domain one collapse
// at a time, and every removed vertex keeps its place in the simplified mesh as a base triangle
// and barycentric coordinates.
//
// A collapse of v into its neighbour u flattens v's 1-ring (MAPS's z^a map: the angles at v
// scaled to sum to 2 pi, or pi on the border, the radii raised to the same power), so the old
// triangles around v and the new fan around u tile the same polygon. Every point that lay in the
// old triangles (and v itself, at the origin) is placed by its barycentric coordinates in the
// flattened old triangle and re-expressed in the new triangle holding it. A collapse is allowed
// only when the new fan is positively oriented in the flattening (so the tiling is exact and the
// map stays bijective), the topology stays a manifold (link condition; border vertices move along
// the border), no new triangle folds over in space, base triangles keep their shape and base
// valences stay within one of the surface degree (see collapse_cost).
//
// Then smooth_parameterization (param_smooth.cpp) improves the map in the final domain and
// check_parameterization (param_check.cpp) must find it bijective.
#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <queue>

#include <tbb/parallel_invoke.h>

#include "aqp/domain.h"
#include "vec3.h"
#include "base/error.h"
#include "base/progress.h"

namespace catpaq::aqp {

void smooth_parameterization(const Mesh& surface, Parameterization& param, int sweeps);  // param_smooth.cpp

namespace {

using Tri = std::array<uint32_t, 3>;
constexpr double kPi = 3.14159265358979323846;
// The halves (simplify_halves) stop at this many times their share of the target, or at a 16th
// of their triangles if that is more: the whole then evens out the band, which the halves leave
// at full resolution. (Stopping at 8 times the target, the 1M scan's band stayed a strip of small
// triangles beside the large ones, and its base domain folded; at 1/8, 1/16 and 1/32 the 1M
// scans' distortions matched the sequential run's.)
constexpr size_t kHalvesTargetFactor = 8;
constexpr size_t kHalvesReduction = 16;
// Rounds of halves: the second cuts across the first's band and takes the halves a further 16
// times down, so that less is left to the whole, whose collapses are the costliest (each moves
// the points of its ring's triangles, more the coarser they are).
constexpr int kHalvesRounds = 2;
// A half leaves at least this many of its side's vertices of any component to the whole.
constexpr size_t kHalfComponentFloor = 64;

double length(const Vec3d& a) { return std::sqrt(dot(a, a)); }
// 4 sqrt(3) area / (sum of squared edges): 1 for an equilateral triangle, 0 for a degenerate
// one; about 0.35 with a 20 degree angle between equal sides.
double triangle_quality(const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    const Vec3d ab = sub(b, a), bc = sub(c, b), ca = sub(a, c);
    return 2 * std::sqrt(3.0) * length(cross(ab, sub(c, a))) / std::max(dot(ab, ab) + dot(bc, bc) + dot(ca, ca), 1e-300);
}
constexpr double kMinBaseQuality = 0.3;
constexpr double kMaxFlatAngle = 0.9 * kPi;
constexpr size_t kSmallestSimplified = 64;
constexpr int kValenceOverDegree = 1;  // triangles (about twice the vertices) of a component

double orient(const Vec2& a, const Vec2& b, const Vec2& c) {
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
}

// Sum of squared distances to planes, area weighted (Garland and Heckbert).
struct Quadric {
    double q[10] = {};  // xx xy xz xw yy yz yw zz zw ww
    double area = 0;
    void add_plane(const Vec3d& n, double d, double weight) {
        const double p[4] = {n[0], n[1], n[2], d};
        int k = 0;
        for (int i = 0; i < 4; ++i)
            for (int j = i; j < 4; ++j) q[k++] += weight * p[i] * p[j];
        area += weight;
    }
    void add(const Quadric& o) {
        for (int k = 0; k < 10; ++k) q[k] += o.q[k];
        area += o.area;
    }
    // Mean squared distance of p to the planes.
    double mean_error(const Vec3d& p) const {
        const double x = p[0], y = p[1], z = p[2];
        double e = q[0] * x * x + 2 * q[1] * x * y + 2 * q[2] * x * z + 2 * q[3] * x + q[4] * y * y +
                   2 * q[5] * y * z + 2 * q[6] * y + q[7] * z * z + 2 * q[8] * z + q[9];
        return area > 0 ? std::max(e, 0.0) / area : 0.0;
    }
};

// Barycentric coordinates of p in the flat triangle (a, b, c) (which must have area).
std::array<double, 3> flat_bary(const Vec2& p, const Vec2& a, const Vec2& b, const Vec2& c) {
    double area = orient(a, b, c);
    double l1 = orient(a, p, c) / area, l2 = orient(a, b, p) / area;
    return {1.0 - l1 - l2, l1, l2};
}

class DomainSimplifier {
public:
    explicit DomainSimplifier(const Mesh& mesh);
    // Simplifies to `target` triangles: the two halves of a large surface first, at once, then
    // the whole (see simplify_halves).
    void simplify(size_t target, size_t halves_min_vertices, Progress* progress, DomainReport& report);
    Parameterization finish() const;
    size_t alive_triangles() const { return alive_triangles_; }
    // Triangles of the components too small to simplify (kept whole).
    size_t frozen_triangles() const { return frozen_triangles_; }

private:
    // The 1-ring of v counter-clockwise: triangle t[i] = (v, w[i], w[i+1]); a closed ring has as
    // many vertices as triangles (indices wrap), an open one (v on the border) one more.
    struct Ring {
        std::vector<uint32_t> w, t;
        bool open = false;
        mutable double quality = -1;  // of its worst triangle (triangle_quality), -1 until computed
        size_t next(size_t i) const { return (i + 1) % w.size(); }
    };
    struct Entry {
        double cost;
        uint32_t v, stamp;
        bool operator<(const Entry& o) const { return cost > o.cost; }  // smallest cost first
    };

    // What one simplifying thread keeps to itself. The halves' two workers (side 1 and 2) write
    // only the mesh data of their own side's vertices and triangles, so they run at once and
    // each does what it would do alone; the last worker (side 0) takes every vertex.
    struct Worker {
        uint8_t side = 0;
        std::priority_queue<Entry> queue;
        uint32_t mark_id = 0;  // the halves' workers count from disjoint ranges
        size_t alive_triangles = 0;  // side 0: all; else those of the side's own vertices
        size_t rejected = 0;
        // Side 1 and 2: the side's own vertices left in each component, and those removed.
        std::vector<uint32_t> component_left, component_removed;
        // Scratch.
        Ring ring;
        std::vector<Vec2> flat;
        std::vector<std::pair<double, size_t>> order;
    };
    // The count the collapse rules see for a component: its vertices left, or for a half's
    // worker its own side's (see simplify_halves: a half keeps more than 12 of a component, so
    // the rules decide as they would on the whole count).
    size_t component_size(const Worker& w, uint32_t c) const {
        return w.side ? w.component_left[c] : component_vertices_[c];
    }
    void simplify_halves(size_t target, int round, Progress* progress);
    void run(Worker& w, size_t target, Progress* progress);

    bool ring_of(uint32_t v, Ring& r) const;
    bool flatten(uint32_t v, const Ring& r, std::vector<Vec2>& flat) const;
    // Whether v may collapse into u = r.w[j], in two halves: the rules that need neither the
    // flattening nor the positions (border, component size, valences, link condition; they
    // refuse most candidates, so update() flattens a ring only once one passes them), then the
    // flattened fan and the shapes, and the cost. collapse_cost runs both.
    bool collapse_topology_ok(Worker& w, uint32_t v, const Ring& r, size_t j, double& valence_change);
    bool collapse_geometry_cost(uint32_t v, const Ring& r, const std::vector<Vec2>& flat, size_t j, double valence_change,
                                double& cost) const;
    bool collapse_cost(Worker& w, uint32_t v, const Ring& r, const std::vector<Vec2>& flat, size_t j, double& cost) {
        double valence_change = 0;
        return collapse_topology_ok(w, v, r, j, valence_change) &&
               collapse_geometry_cost(v, r, flat, j, valence_change, cost);
    }
    void update(Worker& w, uint32_t v);
    void collapse(Worker& w, uint32_t v, uint32_t u);
    double keep_penalty(uint32_t u) const;
    double ring_quality(uint32_t v, const Ring& r) const;
    int corner(uint32_t t, uint32_t v) const {
        return tris_[t][0] == v ? 0 : tris_[t][1] == v ? 1 : tris_[t][2] == v ? 2 : -1;
    }

    const Mesh& mesh_;
    std::vector<Tri> tris_;
    std::vector<uint8_t> tri_alive_;
    std::vector<std::vector<uint32_t>> vtris_;
    std::vector<uint8_t> alive_, border_;
    std::vector<uint32_t> original_degree_;  // neighbours in the surface (triangles, plus 1 on the border)
    std::vector<uint32_t> component_;
    std::vector<size_t> component_vertices_;
    std::vector<uint8_t> component_open_;
    std::vector<uint8_t> component_frozen_;  // too small to simplify
    std::vector<Quadric> quadric_;
    std::vector<DomainPoint> point_;                // removed vertices
    std::vector<std::vector<uint32_t>> tri_points_;  // removed vertices lying in each triangle
    std::vector<uint32_t> stamp_, target_;
    std::vector<uint32_t> mark_;
    uint32_t mark_id_ = 0;  // the whole's worker's first
    std::vector<uint8_t> side_;  // while the halves simplify: 1 or 2, 0 for the band between them
    size_t alive_triangles_ = 0, frozen_triangles_ = 0;
    size_t rejected_ = 0;
};

DomainSimplifier::DomainSimplifier(const Mesh& mesh) : mesh_(mesh) {
    const size_t nv = mesh.vertex_count(), nt = mesh.triangle_count();
    tris_.resize(nt);
    tri_alive_.assign(nt, 1);
    vtris_.resize(nv);
    quadric_.resize(nv);
    for (uint32_t t = 0; t < nt; ++t) {
        tris_[t] = {mesh.indices[3 * t], mesh.indices[3 * t + 1], mesh.indices[3 * t + 2]};
        for (uint32_t v : tris_[t]) vtris_[v].push_back(t);
        const Vec3d &a = mesh.positions[tris_[t][0]], &b = mesh.positions[tris_[t][1]], &c = mesh.positions[tris_[t][2]];
        Vec3d n = cross(sub(b, a), sub(c, a));
        double len = length(n);
        if (len > 0) {
            Vec3d unit{n[0] / len, n[1] / len, n[2] / len};
            for (uint32_t v : tris_[t]) quadric_[v].add_plane(unit, -dot(unit, a), len / 2);
        }
    }
    alive_triangles_ = nt;
    alive_.assign(nv, 1);
    border_.assign(nv, 0);
    // Border vertices: an edge v->w with no twin w->v.
    for (uint32_t v = 0; v < nv; ++v) {
        for (uint32_t t : vtris_[v]) {
            int i = corner(t, v);
            uint32_t w = tris_[t][(i + 1) % 3];
            bool twin = false;
            for (uint32_t s : vtris_[w]) {
                int j = corner(s, w);
                if (tris_[s][(j + 1) % 3] == v) twin = true;
            }
            if (!twin) border_[v] = border_[w] = 1;
        }
    }
    original_degree_.resize(nv);
    for (uint32_t v = 0; v < nv; ++v) original_degree_[v] = uint32_t(vtris_[v].size()) + border_[v];
    // Components (by vertex), their sizes and whether they have a border.
    component_.assign(nv, kNone);
    std::vector<uint32_t> stack;
    for (uint32_t seed = 0; seed < nv; ++seed) {
        if (component_[seed] != kNone || vtris_[seed].empty()) continue;
        uint32_t id = uint32_t(component_vertices_.size());
        component_vertices_.push_back(0);
        component_open_.push_back(0);
        component_frozen_.push_back(0);
        component_[seed] = id;
        stack.assign(1, seed);
        while (!stack.empty()) {
            uint32_t v = stack.back();
            stack.pop_back();
            ++component_vertices_[id];
            if (border_[v]) component_open_[id] = 1;
            for (uint32_t t : vtris_[v])
                for (uint32_t w : tris_[t])
                    if (component_[w] == kNone) component_[w] = id, stack.push_back(w);
        }
        // A small component is its own base domain: every triangle a base triangle, the map
        // the identity (bijective whatever the shape; needles defeat the flattenings).
        component_frozen_[id] = component_vertices_[id] * 2 < kSmallestSimplified;
    }
    for (const Tri& t : tris_) frozen_triangles_ += component_frozen_[component_[t[0]]];
    point_.resize(nv);
    tri_points_.resize(nt);
    stamp_.assign(nv, 0);
    target_.assign(nv, kNone);
    mark_.assign(nv, 0);
}

bool DomainSimplifier::ring_of(uint32_t v, Ring& r) const {
    const std::vector<uint32_t>& ts = vtris_[v];
    const size_t d = ts.size();
    r.w.clear();
    r.t.clear();
    r.open = border_[v];
    if (d == 0) return false;
    auto from = [&](uint32_t t) { return tris_[t][(corner(t, v) + 1) % 3]; };
    auto to = [&](uint32_t t) { return tris_[t][(corner(t, v) + 2) % 3]; };
    uint32_t start = from(ts[0]);
    if (r.open) {
        start = kNone;
        for (uint32_t t : ts) {
            bool is_end = false;
            for (uint32_t s : ts) is_end |= to(s) == from(t);
            if (!is_end) start = from(t);
        }
        if (start == kNone) return false;
    }
    uint32_t cur = start;
    for (size_t step = 0; step < d; ++step) {
        uint32_t found = kNone;
        for (uint32_t t : ts)
            if (from(t) == cur) found = t;
        if (found == kNone) return false;
        r.w.push_back(cur);
        r.t.push_back(found);
        cur = to(found);
    }
    if (r.open)
        r.w.push_back(cur);
    else if (cur != start)
        return false;
    r.quality = -1;  // computed when needed (ring_quality)
    return true;
}

// The radii's exponent: the angles are scaled by `scale`, and z^a with a = scale is conformal
// (MAPS); clamped so that needle tips (tiny total angles) do not crush or blow up the radii.
double radius_power(double scale) { return std::clamp(scale, 0.5, 2.0); }

bool DomainSimplifier::flatten(uint32_t v, const Ring& r, std::vector<Vec2>& flat) const {
    const Vec3d& p = mesh_.positions[v];
    const size_t n = r.w.size(), d = r.t.size();
    flat.resize(n);
    double total = 0, mean_radius = 0;
    for (size_t i = 0; i < n; ++i) mean_radius += length(sub(mesh_.positions[r.w[i]], p)) / double(n);
    if (!(mean_radius > 0)) return false;
    // The angle of each triangle at v, then the scale that closes the ring (2 pi) or flattens the
    // border (pi).
    double angle[64];
    if (d > 64) return false;
    for (size_t i = 0; i < d; ++i) {
        Vec3d a = sub(mesh_.positions[r.w[i]], p), b = sub(mesh_.positions[r.w[r.next(i)]], p);
        angle[i] = std::atan2(length(cross(a, b)), dot(a, b));
        if (!(angle[i] > 0)) return false;
        total += angle[i];
    }
    if (!(total > 0)) return false;
    const double target = r.open ? kPi : 2 * kPi;
    const double scale = target / total;
    // Scaled angles, none above kMaxFlatAngle: a vertex almost on an edge (a cap, angle near pi)
    // would flatten to a degenerate or folded triangle. Clamped angles give their excess to the
    // others in proportion (any star-shaped flattening keeps the map bijective).
    double flat_angle[64];
    for (size_t i = 0; i < d; ++i) flat_angle[i] = angle[i] * scale;
    for (int pass = 0; pass < 8; ++pass) {
        double clamped = 0, free_sum = 0;
        for (size_t i = 0; i < d; ++i) {
            if (flat_angle[i] >= kMaxFlatAngle) flat_angle[i] = kMaxFlatAngle, clamped += kMaxFlatAngle;
            else free_sum += flat_angle[i];
        }
        if (clamped == 0) break;
        if (!(free_sum > 0) || clamped >= target) return false;
        bool over = false;
        for (size_t i = 0; i < d; ++i)
            if (flat_angle[i] < kMaxFlatAngle) over |= (flat_angle[i] *= (target - clamped) / free_sum) >= kMaxFlatAngle;
        if (!over) break;
    }
    double phi = 0;
    for (size_t i = 0; i < n; ++i) {
        double radius = std::pow(length(sub(mesh_.positions[r.w[i]], p)) / mean_radius, radius_power(scale));
        flat[i] = {radius * std::cos(phi), radius * std::sin(phi)};
        if (i < d) {
            if (!(flat_angle[i] < kPi * (1 - 1e-9))) return false;
            phi += flat_angle[i];
        }
    }
    return true;
}

bool DomainSimplifier::collapse_topology_ok(Worker& worker, uint32_t v, const Ring& r, size_t j, double& valence_change) {
    const uint32_t u = r.w[j];
    const size_t n = r.w.size(), d = r.t.size();
    // Border vertices move only along the border; an ear (one triangle) has nowhere to put its
    // points.
    if (r.open && ((j != 0 && j != n - 1) || d < 2)) return false;
    const uint32_t c = component_[v];
    const size_t size = component_size(worker, c);
    if (component_frozen_[c] || size <= (component_open_[c] ? 3u : 4u)) return false;
    if (worker.side && size <= kHalfComponentFloor) return false;
    // Valences near 6 (4 on the border): a base vertex of valence 3 is a cone of 180 degrees in
    // the domain, where the surface around it must be squeezed to half its angle.
    auto valence = [&](uint32_t w) { return int(vtris_[w].size()) + border_[w]; };
    auto deviation = [&](uint32_t w, int val) {
        const int target = border_[w] ? 4 : 6;
        return double((val - target) * (val - target));
    };
    const int u_after = valence(u) + int(n) - (r.open ? 3 : 4);
    if (u_after < (border_[u] ? 2 : 4) && size > 12) return false;
    // Around a base vertex the surface's triangles share a cone of 60 degrees per base triangle:
    // with more base triangles than surface triangles there (a valence 8 base vertex with 6
    // surface triangles spans 480 degrees) they are stretched past what the second ring of
    // surface triangles can follow (folds seen on the bunny and a 200k scan).
    if (u_after > int(original_degree_[u]) + kValenceOverDegree && size > 12) return false;
    valence_change = deviation(u, u_after) - deviation(u, valence(u)) - deviation(v, int(n));
    for (size_t o : {j == 0 ? (r.open ? n : n - 1) : j - 1, j + 1}) {
        if (o >= n) continue;  // (the open ring's ends have one neighbour on the edge's side)
        const uint32_t x = r.w[o];
        const int after = valence(x) - 1;
        if (after < (border_[x] ? 2 : 4) && size > 12) return false;
        valence_change += deviation(x, after) - deviation(x, valence(x));
    }
    // Link condition: u and v share exactly the vertices of the triangles on edge uv.
    const uint32_t mark = ++worker.mark_id;
    for (uint32_t w : r.w) mark_[w] = mark;
    size_t common = 0;
    for (uint32_t t : vtris_[u])
        for (uint32_t w : tris_[t])
            if (w != u && w != v && mark_[w] == mark) {
                ++common;
                mark_[w] = mark - 1;  // count each once
            }
    const bool border_edge = r.open;  // (j is an end of an open ring)
    return common == (border_edge ? 1u : 2u);
}

bool DomainSimplifier::collapse_geometry_cost(uint32_t v, const Ring& r, const std::vector<Vec2>& flat, size_t j,
                                              double valence_change, double& cost) const {
    const uint32_t u = r.w[j];
    const size_t d = r.t.size();
    // The new fan around u must be positively oriented in the flattening and must not fold in space.
    const Vec3d& pu = mesh_.positions[u];
    const Vec3d& pv = mesh_.positions[v];
    double min_quality = 1.0, max_edge2 = 0;
    for (size_t i = 0; i < d; ++i) {
        size_t i1 = r.next(i);
        if (i == j || i1 == j) continue;
        if (!(orient(flat[j], flat[i], flat[i1]) > 1e-9)) return false;
        const Vec3d& a = mesh_.positions[r.w[i]];
        const Vec3d& b = mesh_.positions[r.w[i1]];
        Vec3d n_new = cross(sub(a, pu), sub(b, pu)), n_old = cross(sub(a, pv), sub(b, pv));
        if (!(dot(n_new, n_old) > 0)) return false;
        min_quality = std::min(min_quality, triangle_quality(pu, a, b));
        max_edge2 = std::max({max_edge2, dot(sub(a, pu), sub(a, pu)), dot(sub(pu, b), sub(pu, b))});
    }
    // Base triangles with a small angle stretch the angles of the surface around that corner
    // (every base triangle is equilateral in the domain): an angle of 20 degrees is stretched
    // threefold, and a surface triangle there can end up spanning more than 180 degrees, which
    // no straight image can. Such collapses are refused unless the ring is that bad already.
    if (min_quality < kMinBaseQuality && min_quality < ring_quality(v, r)) return false;
    // Short edges first (base triangles of even size), weighted by the shape error, the worst
    // new triangle's shape (nearly equilateral base triangles) and the valences.
    Quadric q = quadric_[u];
    q.add(quadric_[v]);
    double shape_error = q.mean_error(pu);
    double length2 = dot(sub(pu, pv), sub(pu, pv));
    cost = (length2 + 0.25 * max_edge2 + 16 * shape_error) / std::max(min_quality, 1e-3) *
           (1 + 0.25 * std::max(valence_change, 0.0)) * keep_penalty(u);
    return true;
}

// Surface vertices of low degree make poor base vertices: all their triangles meet at the base
// vertex, spread over its cone of 60 degrees per base triangle, so one may have to span more than
// 180 degrees there, which no straight image can (seen on a 200k scan: a degree-4 base vertex).
// Collapsing into them costs more, so they are removed rather than kept.
double DomainSimplifier::ring_quality(uint32_t v, const Ring& r) const {
    if (r.quality < 0) {
        r.quality = 1;
        for (size_t i = 0; i < r.t.size(); ++i)
            r.quality = std::min(r.quality, triangle_quality(mesh_.positions[v], mesh_.positions[r.w[i]],
                                                             mesh_.positions[r.w[r.next(i)]]));
    }
    return r.quality;
}

double DomainSimplifier::keep_penalty(uint32_t u) const {
    const uint32_t degree = original_degree_[u];
    return degree <= 4 ? 8.0 : degree == 5 ? 2.0 : 1.0;
}

void DomainSimplifier::update(Worker& w, uint32_t v) {
    // A half's worker touches only its side's vertices, and collapses only those whose ring is
    // all of its side: the band's vertices and their data stay as they are until the end.
    if (w.side && side_[v] != w.side) return;
    ++stamp_[v];
    target_[v] = kNone;
    Ring& ring = w.ring;
    if (!alive_[v] || !ring_of(v, ring)) return;
    if (w.side)
        for (uint32_t x : ring.w)
            if (side_[x] != w.side) return;
    std::vector<std::pair<double, size_t>>& order = w.order;
    // Candidates by increasing edge length: a collapse costs at least its squared length (the
    // other terms only add or multiply by at least 1), so once that passes the best cost found,
    // no longer edge can win.
    const Vec3d& p = mesh_.positions[v];
    order.clear();
    for (size_t j = 0; j < ring.w.size(); ++j) {
        const Vec3d e = sub(mesh_.positions[ring.w[j]], p);
        order.push_back({dot(e, e), j});
    }
    std::sort(order.begin(), order.end());
    double best = INFINITY;
    bool flattened = false;
    for (const auto& [length2, j] : order) {
        if (length2 >= best) break;
        double valence_change = 0, cost = 0;
        if (!collapse_topology_ok(w, v, ring, j, valence_change)) continue;
        if (!flattened) {
            if (!flatten(v, ring, w.flat)) return;  // no collapse of v is possible
            flattened = true;
        }
        if (collapse_geometry_cost(v, ring, w.flat, j, valence_change, cost) && cost < best) {
            best = cost;
            target_[v] = ring.w[j];
        }
    }
    if (target_[v] != kNone) w.queue.push({best, v, stamp_[v]});
}

void DomainSimplifier::collapse(Worker& worker, uint32_t v, uint32_t u) {
    Ring r;
    std::vector<Vec2> flat;
    bool ok = ring_of(v, r) && flatten(v, r, flat);
    assert(ok);
    (void)ok;
    const size_t n = r.w.size(), d = r.t.size();
    const size_t j = size_t(std::find(r.w.begin(), r.w.end(), u) - r.w.begin());
    assert(j < n);

    // Flattened corners of the old triangles (storage order) and of the new fan.
    struct Corners {
        uint32_t t;
        Vec2 p[3];
    };
    std::vector<Corners> old_corners(d), new_fan;
    std::vector<std::array<uint32_t, 3>> new_vertices;  // of each new triangle, v replaced by u
    for (size_t i = 0; i < d; ++i) {
        uint32_t t = r.t[i];
        int iv = corner(t, v);
        Corners c{t, {}};
        c.p[iv] = {0, 0};
        c.p[(iv + 1) % 3] = flat[i];
        c.p[(iv + 2) % 3] = flat[r.next(i)];
        old_corners[i] = c;
        if (i == j || r.next(i) == j) continue;
        c.p[iv] = flat[j];
        new_fan.push_back(c);
        std::array<uint32_t, 3> w = tris_[t];
        w[iv] = u;
        new_vertices.push_back(w);
    }
    // The new triangles' edges on the border after the collapse: no other new triangle and no
    // triangle outside the ring has them. (Besides the ring's own border edges, the edge left
    // where a dying triangle's far edge was a border, and the one replacing v's border edge.)
    std::vector<std::pair<size_t, int>> border_edges;  // (index in new_fan, edge k)
    for (size_t f = 0; f < new_fan.size(); ++f)
        for (int k = 0; k < 3; ++k) {
            const uint32_t a = new_vertices[f][k], b = new_vertices[f][(k + 1) % 3];
            bool shared = false;
            for (size_t g = 0; g < new_fan.size() && !shared; ++g)
                if (g != f) {
                    const auto& o = new_vertices[g];
                    shared = (o[0] == a || o[1] == a || o[2] == a) && (o[0] == b || o[1] == b || o[2] == b);
                }
            const uint32_t outside = a == u ? b : a;  // (u's own list does not hold v's ring yet)
            const uint32_t other = a == u ? a : b;
            for (uint32_t s2 : vtris_[outside]) {
                if (shared) break;
                if (std::find(r.t.begin(), r.t.end(), s2) != r.t.end()) continue;
                shared = corner(s2, other) >= 0;
            }
            if (!shared) border_edges.push_back({f, k});
        }

    // Re-place every point of the old triangles, and v, in the new fan.
    std::vector<std::pair<uint32_t, Vec2>> moving;
    moving.push_back({v, {0, 0}});
    for (const Corners& c : old_corners) {
        for (uint32_t id : tri_points_[c.t]) {
            const DomainPoint& p = point_[id];
            Vec2 x{0, 0};
            for (int k = 0; k < 3; ++k) x[0] += p.bary[k] * c.p[k][0], x[1] += p.bary[k] * c.p[k][1];
            moving.push_back({id, x});
        }
        tri_points_[c.t].clear();
    }
    for (const auto& [id, x] : moving) {
        DomainPoint placed;
        if (border_[id] && !border_edges.empty()) {
            // Border points stay exactly on the border: the nearest border edge of the new fan.
            double best = INFINITY;
            for (auto [f, k] : border_edges) {
                const Vec2 &a = new_fan[f].p[k], &b = new_fan[f].p[(k + 1) % 3];
                Vec2 ab{b[0] - a[0], b[1] - a[1]};
                double len2 = ab[0] * ab[0] + ab[1] * ab[1];
                double s = len2 > 0 ? std::clamp(((x[0] - a[0]) * ab[0] + (x[1] - a[1]) * ab[1]) / len2, 0.0, 1.0) : 0.0;
                double dx = a[0] + s * ab[0] - x[0], dy = a[1] + s * ab[1] - x[1];
                if (dx * dx + dy * dy < best) {
                    best = dx * dx + dy * dy;
                    placed.triangle = new_fan[f].t;
                    placed.bary = {0, 0, 0};
                    placed.bary[k] = 1 - s;
                    placed.bary[(k + 1) % 3] = s;
                }
            }
        } else {
            // The triangle holding x (the most inside one: rounding may put x a hair outside all).
            double best = -INFINITY;
            for (const Corners& c : new_fan) {
                std::array<double, 3> b = flat_bary(x, c.p[0], c.p[1], c.p[2]);
                double inside = std::min({b[0], b[1], b[2]});
                if (inside > best) {
                    best = inside;
                    placed.triangle = c.t;
                    placed.bary = b;
                }
            }
            if (best < 0) {
                // Rounding left x a hair outside: clamp it in, and a hair further inside, so that
                // a point off the border never lands on a border edge or on another point there.
                double sum = 0;
                for (double& b : placed.bary) sum += (b = std::max(b, 0.0));
                for (double& b : placed.bary) b = (1 - 1e-9) * b / sum + 1e-9 / 3;
            }
        }
        point_[id] = placed;
        tri_points_[placed.triangle].push_back(id);
    }

    // Topology: the triangles on edge uv die, the others take u for v.
    for (size_t i = 0; i < d; ++i) {
        uint32_t t = r.t[i];
        if (i == j || r.next(i) == j) {
            tri_alive_[t] = 0;
            --worker.alive_triangles;
            for (uint32_t w : tris_[t]) {
                auto& list = vtris_[w];
                list.erase(std::find(list.begin(), list.end(), t));
            }
        } else {
            tris_[t][corner(t, v)] = u;
            vtris_[u].push_back(t);
        }
    }
    vtris_[v].clear();
    alive_[v] = 0;
    if (worker.side) {
        --worker.component_left[component_[v]];
        ++worker.component_removed[component_[v]];
    } else {
        --component_vertices_[component_[v]];
    }
    quadric_[u].add(quadric_[v]);

    // Costs around u changed: u, its neighbours and theirs (the link condition looks that far).
    const uint32_t mark = ++worker.mark_id;
    std::vector<uint32_t> around;
    for (uint32_t t : vtris_[u])
        for (uint32_t w : tris_[t])
            if (mark_[w] != mark) mark_[w] = mark, around.push_back(w);
    for (uint32_t w : around) update(worker, w);
}

// Collapses the worker's cheapest candidates until its triangles are down to `target` or it
// has none left.
void DomainSimplifier::run(Worker& w, size_t target, Progress* progress) {
    for (uint32_t v = 0; v < alive_.size(); ++v)
        if (!vtris_[v].empty()) update(w, v);
    size_t done = 0;
    while (w.alive_triangles > target && !w.queue.empty()) {
        Entry e = w.queue.top();
        w.queue.pop();
        if (!alive_[e.v] || e.stamp != stamp_[e.v]) continue;
        uint32_t u = target_[e.v];
        // Neighbours may have changed since the cost was computed: check again.
        double cost;
        size_t j = 0;
        if (!ring_of(e.v, w.ring) || !flatten(e.v, w.ring, w.flat)) {
            ++w.rejected;
            continue;
        }
        while (j < w.ring.w.size() && w.ring.w[j] != u) ++j;
        if (j == w.ring.w.size() || !collapse_cost(w, e.v, w.ring, w.flat, j, cost)) {
            ++w.rejected;
            update(w, e.v);
            continue;
        }
        collapse(w, e.v, u);
        if (progress && (++done & 1023) == 0) progress->add(1024);
    }
}

// A round of the simplification on both cores: the vertices left are split at the median across
// the longest side of their box (the second longest in the second round), and a band of the
// vertices within two edges of the other side is kept out. Each side's worker then collapses only vertices whose rings are
// all of its side, so it reads the band but never changes it, and the two never touch the same
// data: each does exactly what it would do alone (the result does not depend on the threads).
// A band vertex cannot neighbour both sides (their vertices would be two edges apart, and so in
// the band), and a collapse only links vertices of one ring, so that stays so. The halves stop
// at kHalvesTargetFactor times their share of the target or a kHalvesReduction-th of their
// triangles; the whole is then simplified as one, the band and the last, shape-deciding
// collapses included.
void DomainSimplifier::simplify_halves(size_t target, int round, Progress* progress) {
    const size_t nv = alive_.size();
    const Mesh& mesh = mesh_;
    std::vector<uint32_t> order;
    for (uint32_t v = 0; v < nv; ++v)
        if (alive_[v] && !vtris_[v].empty()) order.push_back(v);
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t v : order)
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], mesh.positions[v][a]);
            hi[a] = std::max(hi[a], mesh.positions[v][a]);
        }
    // The first round cuts across the longest side, the next across the second longest, which
    // cuts the first round's band in two.
    int axes[3] = {0, 1, 2};
    std::stable_sort(axes, axes + 3, [&](int a, int b) { return hi[a] - lo[a] > hi[b] - lo[b]; });
    const int axis = axes[round % 2];
    auto by_coordinate = [&](uint32_t a, uint32_t b) {
        const double x = mesh.positions[a][axis], y = mesh.positions[b][axis];
        return x != y ? x < y : a < b;
    };
    const size_t half = order.size() / 2;
    std::nth_element(order.begin(), order.begin() + ptrdiff_t(half), order.end(), by_coordinate);
    side_.assign(nv, 2);
    for (size_t i = 0; i < half; ++i) side_[order[i]] = 1;
    // The band: the ends of edges between the sides, and their neighbours.
    std::vector<uint8_t> band(nv, 0);
    for (size_t t = 0; t < tris_.size(); ++t) {
        const Tri& c = tris_[t];
        if (tri_alive_[t] && (side_[c[0]] != side_[c[1]] || side_[c[1]] != side_[c[2]]))
            for (uint32_t v : c) band[v] = 1;
    }
    std::vector<uint8_t> wide = band;
    for (size_t t = 0; t < tris_.size(); ++t) {
        const Tri& c = tris_[t];
        if (tri_alive_[t] && (band[c[0]] || band[c[1]] || band[c[2]]))
            for (uint32_t v : c) wide[v] = 1;
    }
    for (uint32_t v = 0; v < nv; ++v)
        if (wide[v]) side_[v] = 0;

    // Marks start afresh: each worker counts from its own half of the range.
    std::fill(mark_.begin(), mark_.end(), 0u);
    Worker halves[2];
    for (int h = 0; h < 2; ++h) {
        Worker& w = halves[h];
        w.side = uint8_t(h + 1);
        w.mark_id = uint32_t(h) << 31;
        w.component_left.assign(component_vertices_.size(), 0);
        w.component_removed.assign(component_vertices_.size(), 0);
        for (uint32_t v = 0; v < nv; ++v)
            if (side_[v] == w.side && alive_[v]) ++w.component_left[component_[v]];
        for (size_t t = 0; t < tris_.size(); ++t) {
            const Tri& c = tris_[t];
            w.alive_triangles += tri_alive_[t] && side_[c[0]] == w.side && side_[c[1]] == w.side && side_[c[2]] == w.side;
        }
    }
    const double share = double(target) * kHalvesTargetFactor / double(std::max<size_t>(alive_triangles_, 1));
    size_t targets[2];
    for (int h = 0; h < 2; ++h)
        targets[h] = std::max(size_t(share * double(halves[h].alive_triangles)), halves[h].alive_triangles / kHalvesReduction);
    tbb::parallel_invoke([&] { run(halves[0], targets[0], progress); }, [&] { run(halves[1], targets[1], progress); });

    for (const Worker& w : halves) {
        for (size_t c = 0; c < component_vertices_.size(); ++c) component_vertices_[c] -= w.component_removed[c];
        rejected_ += w.rejected;
    }
    alive_triangles_ = size_t(std::count(tri_alive_.begin(), tri_alive_.end(), uint8_t(1)));
    std::fill(mark_.begin(), mark_.end(), 0u);
    mark_id_ = 0;
    std::vector<uint8_t>().swap(side_);
}

void DomainSimplifier::simplify(size_t target, size_t halves_min_vertices, Progress* progress, DomainReport& report) {
    if (alive_.size() >= halves_min_vertices) {
        for (int round = 0; round < kHalvesRounds && alive_triangles_ > 4 * kHalvesTargetFactor * target; ++round)
            simplify_halves(target, round, progress);
        report.half_collapses = size_t(std::count(alive_.begin(), alive_.end(), uint8_t(0)));
    }
    Worker whole;
    whole.mark_id = mark_id_;
    whole.alive_triangles = alive_triangles_;
    run(whole, target, progress);
    alive_triangles_ = whole.alive_triangles;
    rejected_ += whole.rejected;
    report.collapses = size_t(std::count(alive_.begin(), alive_.end(), uint8_t(0)));
    report.rejected_collapses = rejected_;
}

Parameterization DomainSimplifier::finish() const {
    Parameterization out;
    const size_t nv = mesh_.vertex_count();
    out.base_vertex.assign(nv, kNone);
    for (uint32_t v = 0; v < nv; ++v)
        if (alive_[v] && !vtris_[v].empty()) {
            out.base_vertex[v] = uint32_t(out.domain.vertex_source.size());
            out.domain.vertex_source.push_back(v);
        }
    std::vector<uint32_t> new_triangle(tris_.size(), kNone);
    for (uint32_t t = 0; t < tris_.size(); ++t)
        if (tri_alive_[t]) {
            new_triangle[t] = uint32_t(out.domain.triangles.size());
            out.domain.triangles.push_back(
                {out.base_vertex[tris_[t][0]], out.base_vertex[tris_[t][1]], out.base_vertex[tris_[t][2]]});
        }
    if (!out.domain.connect()) fail("internal error: the base domain is not an oriented manifold");
    out.points.resize(nv);
    for (uint32_t v = 0; v < nv; ++v) {
        if (out.base_vertex[v] != kNone) {
            uint32_t t = vtris_[v][0];
            DomainPoint p;
            p.triangle = new_triangle[t];
            p.bary = {0, 0, 0};
            p.bary[corner(t, v)] = 1;
            out.points[v] = p;
        } else {
            out.points[v] = point_[v];
            out.points[v].triangle = new_triangle[point_[v].triangle];
        }
    }
    return out;
}

}  // namespace

size_t default_domain_triangles(size_t triangles) {
    // About 0.6 sqrt(n): the bunny (75k) gets 164, a 200k scan 268, a 1M scan 600. Fewer, larger
    // patches compress better (bench/aqp/node_bench: the PNG and per-node overhead; 200k scan at
    // about 260k samples: 40 bits per sample with 670 base triangles, 28 with 170, 23 with 42);
    // more follow the shape better (the bunny fails below about 100: its ears fold).
    double n = 0.6 * std::sqrt(double(triangles));
    return size_t(std::clamp(n, 16.0, 4000.0)) & ~size_t(1);
}

namespace {

// One attempt at `target` base triangles; throws on failure (`folds` says whether the map folded
// rather than its charts being too small, for the next attempt's direction).
Parameterization parameterize_once(const Mesh& surface, const DomainOptions& options, size_t target,
                                   DomainReport& report, Progress* progress, bool& folds) {
    auto t0 = std::chrono::steady_clock::now();
    report.target_triangles = target;
    DomainSimplifier simplifier(surface);
    simplifier.simplify(report.target_triangles + simplifier.frozen_triangles(), options.halves_min_vertices, progress,
                        report);
    if (simplifier.alive_triangles() > 2 * report.target_triangles + 8 + simplifier.frozen_triangles())
        fail("the surface could not be simplified to %zu base triangles (it stopped at %zu): it has handles or thin "
             "parts the domain cannot follow at that size; ask for more domain triangles",
             report.target_triangles, simplifier.alive_triangles());
    Parameterization param = simplifier.finish();
    auto t1 = std::chrono::steady_clock::now();
    report.seconds_simplify += std::chrono::duration<double>(t1 - t0).count();
    smooth_parameterization(surface, param, options.smoothing_sweeps);
    report.seconds_smooth += std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
    report.base_vertices = param.domain.vertex_count();
    report.base_triangles = param.domain.triangle_count();
    report.base_border_edges = 0;
    for (const auto& n : param.domain.neighbour)
        for (uint32_t t : n) report.base_border_edges += t == kNone;
    report.check = check_parameterization(surface, param);
    const ParamCheck& check = report.check;
    if (!check.bijective()) {
        folds = !check.unfold_failures;
        const char* hint = check.unfold_failures
                               ? ": input triangles span more base triangles than a chart holds; ask for fewer domain triangles"
                               : ": folds the smoothing could not undo, usually needle-thin parts; more domain triangles may help";
        fail("the parameterization is not bijective (%s): refusing to build folded patches%s", check.describe().c_str(), hint);
    }
    return param;
}

}  // namespace

Parameterization build_parameterization(const Mesh& surface, const DomainOptions& options, DomainReport* report_out,
                                        Progress* progress) {
    DomainReport report;
    size_t target = options.target_triangles ? options.target_triangles : default_domain_triangles(surface.triangle_count());
    for (int attempt = 0;; ++attempt) {
        const size_t collapses = report.collapses, rejected = report.rejected_collapses, halves = report.half_collapses;
        bool folds = false;
        try {
            Parameterization param = parameterize_once(surface, options, target, report, progress, folds);
            if (report_out) *report_out = report;
            return param;
        } catch (const Error& e) {
            // Only a map that folds or tears is worth another size (a surface that does not
            // simplify far enough fails the same way at any nearby size).
            if (attempt >= options.retries || report.check.triangles == 0 || report.check.bijective()) throw;
            report.refused.emplace_back(target, e.what());
            report.collapses = collapses, report.rejected_collapses = rejected, report.half_collapses = halves;
            report.check = ParamCheck{};
            const size_t next = size_t(double(target) * (folds ? 1.3 : 0.77)) & ~size_t(1);
            if (next < 16 || next == target) throw;
            target = next;
        }
    }
}

}  // namespace catpaq::aqp
