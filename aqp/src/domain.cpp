// BaseDomain connectivity and charts (aqp/domain.h).
#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "aqp/domain.h"

namespace catpaq::aqp {

bool BaseDomain::connect() {
    const size_t n = triangles.size();
    neighbour.assign(n, {kNone, kNone, kNone});
    neighbour_edge.assign(n, {0, 0, 0});
    std::unordered_map<uint64_t, uint32_t> directed;  // (start << 32 | end) -> triangle * 3 + k
    directed.reserve(n * 3);
    for (uint32_t t = 0; t < n; ++t)
        for (uint32_t k = 0; k < 3; ++k) {
            uint64_t key = (uint64_t(triangles[t][k]) << 32) | triangles[t][(k + 1) % 3];
            if (!directed.emplace(key, t * 3 + k).second) return false;
        }
    for (uint32_t t = 0; t < n; ++t)
        for (uint32_t k = 0; k < 3; ++k) {
            uint64_t twin = (uint64_t(triangles[t][(k + 1) % 3]) << 32) | triangles[t][k];
            auto it = directed.find(twin);
            if (it == directed.end()) continue;
            neighbour[t][k] = it->second / 3;
            neighbour_edge[t][k] = uint8_t(it->second % 3);
        }
    return true;
}

namespace {

// The corners of the neighbour across edge k of a triangle whose corners are `c`.
bool unfold_across(const BaseDomain& d, uint32_t& t, uint32_t k, std::array<Lattice2, 3>& c) {
    uint32_t n = d.neighbour[t][k];
    if (n == kNone) return false;
    uint32_t m = d.neighbour_edge[t][k];
    std::array<Lattice2, 3> out;
    out[m] = c[(k + 1) % 3];
    out[(m + 1) % 3] = c[k];
    const Lattice2& far = c[(k + 2) % 3];
    out[(m + 2) % 3] = {c[k][0] + c[(k + 1) % 3][0] - far[0], c[k][1] + c[(k + 1) % 3][1] - far[1]};
    c = out;
    t = n;
    return true;
}

}  // namespace

bool BaseDomain::across(uint32_t& t, uint32_t k, std::array<Lattice2, 3>& corners) const {
    return unfold_across(*this, t, k, corners);
}

namespace {

int corner_of(const BaseDomain& d, uint32_t t, uint32_t v) {
    for (int i = 0; i < 3; ++i)
        if (d.triangles[t][i] == v) return i;
    return -1;
}

// Walks the fan of base vertex v from `to` (corners in `c`) one way round until `from`; returns
// the number of steps, or -1 (a border, or back at the start).
int walk_fan(const BaseDomain& d, uint32_t v, uint32_t to, uint32_t from, bool counter_clockwise,
             std::array<Lattice2, 3>& c) {
    uint32_t t = to;
    for (int steps = 1; steps <= 64; ++steps) {
        int i = corner_of(d, t, v);
        // Counter-clockwise around v the next triangle shares the edge (corner i+2 -> corner i).
        uint32_t k = counter_clockwise ? uint32_t(i + 2) % 3 : uint32_t(i);
        if (!unfold_across(d, t, k, c)) return -1;
        if (t == from) return steps;
        if (t == to) return -1;
    }
    return -1;
}

}  // namespace

void BaseDomain::unfoldings(uint32_t from, uint32_t to, std::vector<Unfolding>& out) const {
    const std::array<Lattice2, 3> standard = {Lattice2{0, 0}, Lattice2{1, 0}, Lattice2{0, 1}};
    out.clear();
    if (from == to) {
        out.push_back({standard, 0});
        return;
    }
    // An edge neighbour is one step away (the other ways round are longer).
    for (uint32_t k = 0; k < 3; ++k)
        if (neighbour[to][k] == from) {
            std::array<Lattice2, 3> c = standard;
            uint32_t t = to;
            unfold_across(*this, t, k, c);
            out.push_back({c, 1});
            return;
        }
    auto add = [&](const std::array<Lattice2, 3>& c, int steps) {
        for (Unfolding& u : out)
            if (u.corners == c) {
                u.steps = std::min(u.steps, steps);
                return;
            }
        out.push_back({c, steps});
    };
    for (int i = 0; i < 3; ++i) {
        const uint32_t v = triangles[to][i];
        if (corner_of(*this, from, v) < 0) continue;
        for (bool ccw : {true, false}) {
            std::array<Lattice2, 3> c = standard;
            const int steps = walk_fan(*this, v, to, from, ccw, c);
            if (steps > 0) add(c, steps);
        }
    }
}

bool BaseDomain::unfold(uint32_t from, uint32_t to, std::array<Lattice2, 3>& corners, int* steps_out) const {
    std::vector<Unfolding> all;
    unfoldings(from, to, all);
    int best = -1;
    for (const Unfolding& u : all)
        if (best < 0 || u.steps < best) {
            best = u.steps;
            corners = u.corners;
        }
    if (steps_out) *steps_out = best;
    return best >= 0;
}

bool BaseDomain::chart_position(const DomainPoint& p, uint32_t to, Vec2& out, const Vec2* near) const {
    const Lattice2 standard[3] = {{0, 0}, {1, 0}, {0, 1}};
    // Candidates: where p lands through each unfolding. Fewest steps wins (the way round a cone
    // point the short way); among as few, the one nearest `near`.
    double best_steps = INFINITY, best_distance = INFINITY;
    auto consider = [&](const Vec2& x, int steps) {
        double distance = 0;
        if (near) {
            const Vec2 d = lattice_to_plane({x[0] - (*near)[0], x[1] - (*near)[1]});
            distance = d[0] * d[0] + d[1] * d[1];
        }
        if (steps < best_steps || (steps == best_steps && distance < best_distance)) {
            best_steps = steps;
            best_distance = distance;
            out = x;
        }
    };
    std::vector<Unfolding> all;
    for (int i = 0; i < 3; ++i)
        if (p.bary[i] == 1.0) {
            // A base vertex: a corner of every triangle around it, however far its own triangle.
            const uint32_t v = triangles[p.triangle][i];
            const int j = corner_of(*this, to, v);
            if (j >= 0) {
                out = {double(standard[j][0]), double(standard[j][1])};
                return true;
            }
            for (bool ccw : {true, false}) {
                uint32_t t = p.triangle;
                for (int step = 0; step < 64; ++step) {
                    unfoldings(t, to, all);
                    for (const Unfolding& u : all) {
                        const Lattice2& c = u.corners[corner_of(*this, t, v)];
                        consider({double(c[0]), double(c[1])}, u.steps);
                    }
                    const int k = corner_of(*this, t, v);
                    t = neighbour[t][ccw ? uint32_t(k + 2) % 3 : uint32_t(k)];
                    if (t == kNone || t == p.triangle) break;
                }
            }
            return best_steps < INFINITY;
        }
    unfoldings(p.triangle, to, all);
    for (const Unfolding& u : all) {
        Vec2 x{0, 0};
        for (int i = 0; i < 3; ++i) {
            x[0] += p.bary[i] * u.corners[i][0];
            x[1] += p.bary[i] * u.corners[i][1];
        }
        consider(x, u.steps);
    }
    return best_steps < INFINITY;
}

bool BaseDomain::locate(uint32_t start, const Vec2& x, DomainPoint& out, int max_steps) const {
    std::array<Lattice2, 3> c = {Lattice2{0, 0}, Lattice2{1, 0}, Lattice2{0, 1}};
    uint32_t t = start;
    for (int step = 0; step <= max_steps; ++step) {
        // Barycentric coordinates of x in the unfolded triangle (affine in lattice coordinates).
        double ax = c[1][0] - c[0][0], ay = c[1][1] - c[0][1], bx = c[2][0] - c[0][0], by = c[2][1] - c[0][1];
        double det = ax * by - ay * bx;  // +1 or -1 times the unit triangle's: never zero
        double px = x[0] - c[0][0], py = x[1] - c[0][1];
        double l1 = (px * by - py * bx) / det, l2 = (ax * py - ay * px) / det;
        std::array<double, 3> b = {1.0 - l1 - l2, l1, l2};
        int worst = 0;
        for (int i = 1; i < 3; ++i)
            if (b[i] < b[worst]) worst = i;
        if (b[worst] >= -1e-12) {  // on an edge, up to rounding
            double sum = 0;
            for (double& v : b) sum += (v = std::max(v, 0.0));
            for (double& v : b) v /= sum;
            out.triangle = t;
            out.bary = b;
            return true;
        }
        // Cross the edge opposite the most negative coordinate.
        if (!unfold_across(*this, t, uint32_t(worst + 1) % 3, c)) return false;
    }
    return false;
}

bool triangle_image(const Parameterization& param, const uint32_t tri[3], Vec2 out[3], uint32_t* chart_out) {
    int first = 0;
    while (first < 3 && param.base_vertex[tri[first]] != kNone) ++first;
    uint32_t chart = param.points[tri[first % 3]].triangle;
    if (first == 3) {
        // Three base vertices: a surface triangle no collapse touched, so a base triangle itself
        // (its fan round tri[0] holds it).
        const BaseDomain& d = param.domain;
        const uint32_t b0 = param.base_vertex[tri[0]], b1 = param.base_vertex[tri[1]], b2 = param.base_vertex[tri[2]];
        const uint32_t start = param.points[tri[0]].triangle;
        bool found = false;
        for (bool ccw : {true, false}) {
            uint32_t t = start;
            for (int step = 0; step < 64 && t != kNone && !found; ++step) {
                const auto& c = d.triangles[t];
                auto has = [&](uint32_t b) { return c[0] == b || c[1] == b || c[2] == b; };
                if (has(b0) && has(b1) && has(b2)) {
                    chart = t;
                    found = true;
                }
                t = d.neighbour[t][ccw ? (corner_of(d, t, b0) + 2) % 3 : corner_of(d, t, b0)];
                if (t == start) break;
            }
        }
    }
    if (chart_out) *chart_out = chart;
    // The chart's own vertex first; the others where they are nearest to it (the image is the
    // short geodesic triangle, which also settles which way round a cone point they unfold).
    const int own = first % 3;
    if (!param.domain.chart_position(param.points[tri[own]], chart, out[own])) return false;
    for (int k = 0; k < 3; ++k)
        if (k != own && !param.domain.chart_position(param.points[tri[k]], chart, out[k], &out[own])) return false;
    return true;
}

bool triangle_image_area(const Parameterization& param, const uint32_t tri[3], double& area) {
    constexpr double kPlaneArea = 0.86602540378443864676 / 2;  // lattice area to plane area, halved
    auto area_of = [](const Vec2 x[3]) {
        return kPlaneArea * ((x[1][0] - x[0][0]) * (x[2][1] - x[0][1]) - (x[1][1] - x[0][1]) * (x[2][0] - x[0][0]));
    };
    Vec2 x[3];
    uint32_t chart;
    if (!triangle_image(param, tri, x, &chart)) return false;
    area = area_of(x);
    for (int s = 0; s < 3; ++s) {
        const uint32_t other = param.points[tri[s]].triangle;
        if (param.base_vertex[tri[s]] != kNone || other == chart) continue;
        if (!param.domain.chart_position(param.points[tri[s]], other, x[s])) return false;
        for (int k = 0; k < 3; ++k)
            if (k != s && !param.domain.chart_position(param.points[tri[k]], other, x[k], &x[s])) return false;
        if (std::fabs(area_of(x) - area) > 1e-9 * (std::fabs(area) + 1e-6)) return false;
    }
    return true;
}

bool triangles_overlap(const Vec2 a[3], const Vec2 b[3]) {
    // Separating axis theorem: the two triangles' edge lines are the only candidate separating
    // lines (in any affine frame). A tiny positive tolerance makes touching count as apart.
    constexpr double kTouch = 1e-13;
    auto separated = [](const Vec2 p[3], const Vec2 q[3]) {
        for (int i = 0; i < 3; ++i) {
            const Vec2& s = p[i];
            const Vec2& e = p[(i + 1) % 3];
            const double ex = e[0] - s[0], ey = e[1] - s[1];
            bool all_outside = true;
            for (int j = 0; j < 3 && all_outside; ++j) all_outside = ex * (q[j][1] - s[1]) - ey * (q[j][0] - s[0]) <= kTouch;
            if (all_outside) return true;
        }
        return false;
    };
    return !separated(a, b) && !separated(b, a);
}

bool develop_image(const Parameterization& param, const uint32_t tri[3],
                   const std::function<void(uint32_t base, const Vec2 image[3])>& fn) {
    Vec2 x[3];
    uint32_t chart;
    if (!triangle_image(param, tri, x, &chart)) return false;
    Vec2 image[3] = {x[0], x[1], x[2]};
    const double area = (x[1][0] - x[0][0]) * (x[2][1] - x[0][1]) - (x[1][1] - x[0][1]) * (x[2][0] - x[0][0]);
    if (area < 0) std::swap(image[1], image[2]);  // (for the overlap test; a valid map has none)
    std::vector<std::pair<uint32_t, std::array<Lattice2, 3>>> queue;
    queue.push_back({chart, {Lattice2{0, 0}, Lattice2{1, 0}, Lattice2{0, 1}}});
    for (size_t q = 0; q < queue.size() && q < 32; ++q) {
        const auto [base, corners] = queue[q];
        const Vec2 cell[3] = {{double(corners[0][0]), double(corners[0][1])},
                              {double(corners[1][0]), double(corners[1][1])},
                              {double(corners[2][0]), double(corners[2][1])}};
        if (!triangles_overlap(image, cell)) continue;
        // The image in this triangle's chart: y = c0 + l1 (c1 - c0) + l2 (c2 - c0).
        const double ax = cell[1][0] - cell[0][0], ay = cell[1][1] - cell[0][1];
        const double bx = cell[2][0] - cell[0][0], by = cell[2][1] - cell[0][1];
        const double det = ax * by - ay * bx;  // +-1: a lattice triangle of the unit's area
        Vec2 here[3];
        for (int k = 0; k < 3; ++k) {
            const double qx = x[k][0] - cell[0][0], qy = x[k][1] - cell[0][1];
            here[k] = {(qx * by - qy * bx) / det, (ax * qy - ay * qx) / det};
        }
        fn(base, here);
        for (uint32_t k = 0; k < 3; ++k) {
            uint32_t next = base;
            std::array<Lattice2, 3> c = corners;
            if (!param.domain.across(next, k, c)) continue;
            bool seen = false;
            for (const auto& v : queue) seen |= v.first == next;
            if (!seen) queue.push_back({next, c});
        }
    }
    return true;
}

}  // namespace catpaq::aqp
