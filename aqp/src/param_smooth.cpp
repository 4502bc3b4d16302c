// Parameter smoothing in the final domain (the geodesic images check_parameterization judges):
// Gauss-Seidel sweeps over the free vertices (not base vertices, not on the border). Each vertex
// tries a Newton step on its energy, then steps towards the mean-value combination of its
// neighbours (Floater 2003) in the chart of its base triangle, each halved up to three times,
// and moves to the first position that lowers the
// symmetric Dirichlet energy of its triangles (s1^2 + s2^2 + 1/s1^2 + 1/s2^2 per unit of surface
// area, the domain scaled to the surface's area): a barrier at folds, so no move folds anything,
// and the energy only goes down. A vertex around which something is folded (rounding in the
// collapses) moves to the position folding fewest.
//
// Plain mean-value sweeps, tried first, made things worse: with only the base vertices held,
// they pull the surface away from those isolated points (a point constraint holds nothing in
// the limit), and the sphere's largest angle distortion went from 4.5 to 469 in 8 sweeps.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include "aqp/domain.h"
#include "vec3.h"

namespace catpaq::aqp {
namespace {

constexpr double kSqrt3Over2 = 0.86602540378443864676;
constexpr double kSliver = 1e-4;  // triangle shape quality (1: equilateral) below which it is a sliver


// Triangles in `tris` whose image is folded (zero or negative area) or ill-defined.
size_t folded_around(const Mesh& surface, const Parameterization& param, const std::vector<uint32_t>& tris) {
    size_t folded = 0;
    for (uint32_t t : tris) {
        double area;
        folded += !triangle_image_area(param, &surface.indices[3 * t], area) || !(area > 0);
    }
    return folded;
}

// One triangle around the moving vertex: its neighbours' chart positions and the surface
// triangle's shape in an orthonormal frame of its plane (v at the origin, edge to a on x).
struct Corner {
    Vec2 a, b;              // lattice coordinates in the vertex's chart
    double la, bx, by;      // surface: a at (la, 0), b at (bx, by)
    double area;            // surface area
    bool sliver;
};

class VertexSmoother {
public:
    VertexSmoother(const Mesh& surface, Parameterization& param, double scale)
        : surface_(surface), param_(param), scale_(scale) {}

    // Tries to move v; returns true if it moved.
    bool smooth(uint32_t v, const std::vector<uint32_t>& tris) {
        const uint32_t chart = param_.points[v].triangle;
        Vec2 here;
        if (!param_.domain.chart_position(param_.points[v], chart, here) || !gather(v, chart, here, tris)) return false;
        // When everything around v lies in v's own base triangle, this chart is the one the
        // check uses: a finite energy means nothing is folded, and the slow test is not needed.
        const double energy_here = energy(here);
        const size_t folded_before = all_local_ && energy_here < INFINITY ? 0 : folded_around(surface_, param_, tris);
        const double energy_before = folded_before ? INFINITY : energy_here;
        // Directions: a Newton step on the energy (when it is convex here), then the mean-value
        // centre (which also unfolds: it is inside the ring's kernel for a star-shaped ring), and
        // where something is folded the centroid of the neighbours.
        Vec2 directions[3];
        int count = 0;
        if (!folded_before && newton_step(here, energy_here, directions[count])) ++count;
        const Vec2 centre = mean_value_centre();
        directions[count++] = {centre[0] - here[0], centre[1] - here[1]};
        if (folded_before) {
            // Around a sliver (a vertex almost on its neighbours' edge) the mean-value centre
            // lies on that edge; the plain centroid of the neighbours does not.
            Vec2 centroid{0, 0};
            for (const Corner& c : corners_) centroid[0] += c.a[0] + c.b[0], centroid[1] += c.a[1] + c.b[1];
            centroid[0] /= 2.0 * double(corners_.size());
            centroid[1] /= 2.0 * double(corners_.size());
            directions[count++] = {centroid[0] - here[0], centroid[1] - here[1]};
        }
        for (int d = 0; d < count; ++d)
            for (double step : {1.0, 0.5, 0.25, 0.125}) {
                Vec2 x{here[0] + step * directions[d][0], here[1] + step * directions[d][1]};
                if (!(energy(x) < energy_before) && !folded_before) continue;
                DomainPoint placed;
                if (!param_.domain.locate(chart, x, placed)) continue;
                if (all_local_ && !folded_before && placed.triangle == chart) {
                    param_.points[v] = placed;
                    return true;
                }
                const DomainPoint old = param_.points[v];
                param_.points[v] = placed;
                // The images as the check sees them (the walk may have crossed into another chart).
                const size_t folded_after = folded_around(surface_, param_, tris);
                if (folded_after == 0 || folded_after < folded_before) return true;
                param_.points[v] = old;
            }
        return false;
    }

private:
    bool gather(uint32_t v, uint32_t chart, const Vec2& here, const std::vector<uint32_t>& tris) {
        corners_.clear();
        all_local_ = true;
        const Vec3d& p = surface_.positions[v];
        for (uint32_t t : tris) {
            const uint32_t* tri = &surface_.indices[3 * t];
            int i = tri[0] == v ? 0 : tri[1] == v ? 1 : 2;
            uint32_t a = tri[(i + 1) % 3], b = tri[(i + 2) % 3];
            all_local_ = all_local_ && local(a, chart) && local(b, chart);
            Corner c;
            if (!param_.domain.chart_position(param_.points[a], chart, c.a, &here) ||
                !param_.domain.chart_position(param_.points[b], chart, c.b, &here))
                return false;
            Vec3d ea = sub(surface_.positions[a], p), eb = sub(surface_.positions[b], p);
            c.la = std::sqrt(dot(ea, ea));
            const double lb = std::sqrt(dot(eb, eb));
            if (!(c.la > 0) || !(lb > 0)) return false;
            c.bx = dot(eb, ea) / c.la;
            const Vec3d n{ea[1] * eb[2] - ea[2] * eb[1], ea[2] * eb[0] - ea[0] * eb[2], ea[0] * eb[1] - ea[1] * eb[0]};
            c.by = std::sqrt(dot(n, n)) / c.la;  // (accurate for slivers, unlike |eb|^2 - bx^2)
            c.area = 0.5 * c.la * c.by;
            // A sliver (shape quality below kSliver) gets neither energy nor a mean-value weight:
            // it would pull its image flat, onto the edge it almost lies on, where rounding folds
            // it. Any positive image of it will do.
            const double e2 = dot(sub(eb, ea), sub(eb, ea));
            c.sliver = 4 * std::sqrt(3.0) * c.area < kSliver * (c.la * c.la + lb * lb + e2);
            corners_.push_back(c);
        }
        return !corners_.empty();
    }

    // Whether vertex w's point is in base triangle `chart` or is one of its corners.
    bool local(uint32_t w, uint32_t chart) const {
        const DomainPoint& p = param_.points[w];
        if (p.triangle == chart) return true;
        const uint32_t b = param_.base_vertex[w];
        const auto& corners = param_.domain.triangles[chart];
        return b != kNone && (corners[0] == b || corners[1] == b || corners[2] == b);
    }

    // Mean-value weights: tan(alpha/2) of both angles at v beside an edge, over its length.
    Vec2 mean_value_centre() const {
        double wsum = 0, y[2] = {0, 0};
        for (const Corner& c : corners_) {
            if (c.sliver) continue;
            double lb = std::sqrt(c.bx * c.bx + c.by * c.by);
            double half_tan = std::tan(0.5 * std::atan2(c.by, c.bx));
            double wa = half_tan / c.la, wb = half_tan / lb;
            y[0] += wa * c.a[0] + wb * c.b[0];
            y[1] += wa * c.a[1] + wb * c.b[1];
            wsum += wa + wb;
        }
        if (!(wsum > 0)) return {corners_[0].a[0], corners_[0].a[1]};
        return {y[0] / wsum, y[1] / wsum};
    }

    // -H^-1 g of the energy at x, by central differences over a step of a thousandth of the
    // ring's size; false where the energy is not convex or a difference touches a fold.
    bool newton_step(const Vec2& x, double e0, Vec2& out) const {
        double size = INFINITY;
        for (const Corner& c : corners_)
            for (const Vec2& q : {c.a, c.b}) size = std::min(size, std::hypot(q[0] - x[0], q[1] - x[1]));
        const double h = 1e-3 * size;
        if (!(h > 0)) return false;
        auto e = [&](double dx, double dy) { return energy({x[0] + dx * h, x[1] + dy * h}); };
        const double ex1 = e(1, 0), ex0 = e(-1, 0), ey1 = e(0, 1), ey0 = e(0, -1);
        const double exy = e(1, 1) - e(1, -1) - e(-1, 1) + e(-1, -1);
        if (!std::isfinite(ex1 + ex0 + ey1 + ey0 + exy)) return false;
        const double gx = (ex1 - ex0) / (2 * h), gy = (ey1 - ey0) / (2 * h);
        const double hxx = (ex1 - 2 * e0 + ex0) / (h * h), hyy = (ey1 - 2 * e0 + ey0) / (h * h), hxy = exy / (4 * h * h);
        const double det = hxx * hyy - hxy * hxy;
        if (!(hxx > 0) || !(det > 0)) return false;
        out = {-(hyy * gx - hxy * gy) / det, -(hxx * gy - hxy * gx) / det};
        return std::isfinite(out[0]) && std::isfinite(out[1]);
    }

    // Symmetric Dirichlet energy of the triangles around v with v at chart position x;
    // infinite if one is folded.
    double energy(const Vec2& x) const {
        double e = 0;
        for (const Corner& c : corners_) {
            // Image edge vectors in the plane, scaled to surface units.
            auto plane = [&](const Vec2& q) {
                return Vec2{scale_ * ((q[0] - x[0]) + 0.5 * (q[1] - x[1])), scale_ * kSqrt3Over2 * (q[1] - x[1])};
            };
            Vec2 da = plane(c.a), db = plane(c.b);
            double det_image = da[0] * db[1] - da[1] * db[0];
            if (!(det_image > 0)) return INFINITY;
            if (c.sliver) continue;
            // J = D E^-1, E = [la bx; 0 by].
            double j11 = da[0] / c.la, j21 = da[1] / c.la;
            double j12 = (db[0] - j11 * c.bx) / c.by, j22 = (db[1] - j21 * c.bx) / c.by;
            double frob = j11 * j11 + j12 * j12 + j21 * j21 + j22 * j22;
            double det = j11 * j22 - j12 * j21;
            // s1^2 + s2^2 = |J|^2 and 1/s1^2 + 1/s2^2 = |J|^2 / det^2.
            e += c.area * (frob + frob / (det * det));
        }
        return e;
    }

    const Mesh& surface_;
    Parameterization& param_;
    double scale_;
    std::vector<Corner> corners_;
    bool all_local_ = true;
};

// The surface ring of v counter-clockwise (closed rings only): false on the border or if the
// triangles around v do not form one fan.
bool ordered_ring(const Mesh& surface, const std::vector<uint32_t>& tris, uint32_t v, std::vector<uint32_t>& ring) {
    ring.clear();
    auto corner = [&](uint32_t t, int step) {
        const uint32_t* tri = &surface.indices[3 * t];
        int i = tri[0] == v ? 0 : tri[1] == v ? 1 : 2;
        return tri[(i + step) % 3];
    };
    uint32_t current = corner(tris[0], 1);
    for (size_t n = 0; n < tris.size(); ++n) {
        ring.push_back(current);
        uint32_t next = kNone;
        for (uint32_t t : tris)
            if (corner(t, 1) == current) next = corner(t, 2);
        if (next == kNone) return false;
        current = next;
    }
    return current == ring[0];
}

// Re-places the surface ring of base vertex v by the geodesic polar map of its star, as a MAPS
// collapse flattens a ring: each neighbour keeps its distance from v in the domain, and the
// angles between neighbours become their angles on the surface scaled to the base vertex's cone
// (60 degrees per base triangle), turned as little as possible. The collapses' per-sector
// placement can stretch one surface angle past 180 degrees (a 90 degree corner of a grid-like
// scan over sectors whose base triangles had 32 degree angles there): a fold no local move can
// undo. Returns false (changing nothing) if the ring or the star is not simple enough.
bool reset_base_ring(const Mesh& surface, Parameterization& param, const std::vector<std::vector<uint32_t>>& vtris,
                     const std::vector<uint8_t>& fixed, uint32_t v) {
    const BaseDomain& d = param.domain;
    const uint32_t b = param.base_vertex[v];
    // The base triangles around b, counter-clockwise, and the corner b has in each.
    std::vector<std::pair<uint32_t, int>> fan;
    uint32_t t = param.points[v].triangle;
    for (int step = 0; step < 64; ++step) {
        int i = d.triangles[t][0] == b ? 0 : d.triangles[t][1] == b ? 1 : 2;
        fan.push_back({t, i});
        t = d.neighbour[t][(i + 2) % 3];
        if (t == kNone) return false;  // a border base vertex
        if (t == fan[0].first) break;
    }
    std::vector<uint32_t> ring;
    if (!ordered_ring(surface, vtris[v], v, ring)) return false;
    const double cone = 60.0 * double(fan.size());
    auto plane = [](const Vec2& l) { return lattice_to_plane(l); };
    const Vec2 standard[3] = {{0, 0}, {1, 0}, {0, 1}};
    // Current angle (degrees round the cone) and distance of each neighbour.
    std::vector<double> angle(ring.size()), radius(ring.size()), surface_angle(ring.size());
    for (size_t n = 0; n < ring.size(); ++n) {
        const DomainPoint& p = param.points[ring[n]];
        size_t sector = 0;
        while (sector < fan.size() && fan[sector].first != p.triangle) ++sector;
        if (sector == fan.size()) return false;
        const int i = fan[sector].second;
        const Vec2 o = plane(standard[i]), first = plane(standard[(i + 1) % 3]);
        const Vec2 x = plane({p.bary[1], p.bary[2]});
        const double a0 = std::atan2(first[1] - o[1], first[0] - o[0]), a1 = std::atan2(x[1] - o[1], x[0] - o[0]);
        double local = (a1 - a0) * 180 / 3.14159265358979323846;
        while (local < 0) local += 360;
        angle[n] = 60.0 * double(sector) + std::min(local, 60.0);
        radius[n] = std::hypot(x[0] - o[0], x[1] - o[1]);
        const Vec3d e0 = sub(surface.positions[ring[n]], surface.positions[v]);
        const Vec3d e1 = sub(surface.positions[ring[(n + 1) % ring.size()]], surface.positions[v]);
        const Vec3d c{e0[1] * e1[2] - e0[2] * e1[1], e0[2] * e1[0] - e0[0] * e1[2], e0[0] * e1[1] - e0[1] * e1[0]};
        surface_angle[n] = std::atan2(std::sqrt(dot(c, c)), dot(e0, e1));
    }
    double total = 0;
    for (double a : surface_angle) total += a;
    if (!(total > 0)) return false;
    // The turn that keeps the neighbours closest to where they are (angles unwrapped from the first).
    std::vector<double> planned(ring.size());
    double turn = 0, sum = 0;
    for (size_t n = 0; n < ring.size(); ++n) {
        planned[n] = sum * cone / total;
        sum += surface_angle[n];
        double current = angle[n];
        while (current < angle[0]) current += cone;
        turn += (current - planned[n]) / double(ring.size());
    }
    std::vector<DomainPoint> placed(ring.size());
    for (size_t n = 0; n < ring.size(); ++n) {
        double a = std::fmod(planned[n] + turn, cone);
        if (a < 0) a += cone;
        const size_t sector = std::min(size_t(a / 60), fan.size() - 1);
        const auto [tri, i] = fan[sector];
        const Vec2 o = plane(standard[i]), first = plane(standard[(i + 1) % 3]);
        const double a0 = std::atan2(first[1] - o[1], first[0] - o[0]) + (a - 60.0 * double(sector)) * 3.14159265358979323846 / 180;
        const Vec2 x{o[0] + radius[n] * std::cos(a0), o[1] + radius[n] * std::sin(a0)};
        // Plane back to lattice coordinates, then to the triangle holding it.
        const Vec2 l{x[0] - x[1] / std::sqrt(3.0), 2 * x[1] / std::sqrt(3.0)};
        if (!d.locate(tri, l, placed[n])) return false;
    }
    for (size_t n = 0; n < ring.size(); ++n)
        if (!fixed[ring[n]]) param.points[ring[n]] = placed[n];
    return true;
}

// Greedy colouring of the free vertices: each takes the smallest colour none of its neighbours
// has. Returns the vertices of each colour.
std::vector<std::vector<uint32_t>> colour_free_vertices(const Mesh& surface, const std::vector<std::vector<uint32_t>>& vtris,
                                                        const std::vector<uint8_t>& fixed) {
    std::vector<uint8_t> colour(surface.vertex_count(), 0xff);
    std::vector<std::vector<uint32_t>> out;
    for (uint32_t v = 0; v < surface.vertex_count(); ++v) {
        if (fixed[v]) continue;
        uint64_t used = 0;
        for (uint32_t t : vtris[v])
            for (int k = 0; k < 3; ++k) {
                const uint8_t c = colour[surface.indices[3 * t + k]];
                if (c < 64) used |= uint64_t(1) << c;
            }
        uint8_t c = 0;
        while (c < 63 && (used >> c & 1)) ++c;
        colour[v] = c;
        if (out.size() <= c) out.resize(size_t(c) + 1);
        out[c].push_back(v);
    }
    return out;
}

}  // namespace

void smooth_parameterization(const Mesh& surface, Parameterization& param, int sweeps) {
    if (sweeps <= 0) return;
    const size_t nv = surface.vertex_count();
    std::vector<std::vector<uint32_t>> vtris(nv);
    double surface_area = 0;
    for (uint32_t t = 0; t < surface.triangle_count(); ++t) {
        const uint32_t* tri = &surface.indices[3 * t];
        for (int k = 0; k < 3; ++k) vtris[tri[k]].push_back(t);
        Vec3d u = sub(surface.positions[tri[1]], surface.positions[tri[0]]);
        Vec3d w = sub(surface.positions[tri[2]], surface.positions[tri[0]]);
        surface_area += 0.5 * std::sqrt(std::max(0.0, dot(u, u) * dot(w, w) - dot(u, w) * dot(u, w)));
    }
    // Border vertices stay where the collapses put them (on the domain's border).
    std::vector<uint8_t> fixed(nv, 0);
    for (uint32_t v = 0; v < nv; ++v) fixed[v] = param.base_vertex[v] != kNone || vtris[v].empty();
    for (uint32_t t = 0; t < surface.triangle_count(); ++t)
        for (int k = 0; k < 3; ++k) {
            uint32_t a = surface.indices[3 * t + k], b = surface.indices[3 * t + (k + 1) % 3];
            bool twin = false;
            for (uint32_t s : vtris[b])
                for (int m = 0; m < 3; ++m)
                    twin |= surface.indices[3 * s + m] == b && surface.indices[3 * s + (m + 1) % 3] == a;
            if (!twin) fixed[a] = fixed[b] = 1;
        }
    const double domain_area = double(param.domain.triangle_count()) * kSqrt3Over2 / 2;
    const double scale = std::sqrt(surface_area / domain_area);
    VertexSmoother smoother(surface, param, scale);
    // Sweeps by colour: no two vertices of a colour share a triangle, so a colour's vertices move
    // in parallel without seeing each other's moves (and the result does not depend on threads).
    const std::vector<std::vector<uint32_t>> colours = colour_free_vertices(surface, vtris, fixed);
    tbb::enumerable_thread_specific<VertexSmoother> smoothers([&] { return VertexSmoother(surface, param, scale); });
    for (int sweep = 0; sweep < sweeps; ++sweep)
        for (const std::vector<uint32_t>& colour : colours)
            tbb::parallel_for(tbb::blocked_range<size_t>(0, colour.size(), 256), [&](const tbb::blocked_range<size_t>& r) {
                VertexSmoother& local = smoothers.local();
                for (size_t i = r.begin(); i != r.end(); ++i) local.smooth(colour[i], vtris[colour[i]]);
            });
    // The vertices within `rings` rings of v.
    auto neighbourhood = [&](uint32_t v, int rings) {
        std::vector<uint32_t> out{v};
        for (size_t first = 0, r = 0; r < size_t(rings); ++r) {
            const size_t end = out.size();
            for (size_t i = first; i < end; ++i)
                for (uint32_t t : vtris[out[i]])
                    for (int m = 0; m < 3; ++m) {
                        const uint32_t w = surface.indices[3 * t + m];
                        if (std::find(out.begin(), out.end(), w) == out.end()) out.push_back(w);
                    }
            first = end;
        }
        return out;
    };
    auto repair_at_base_vertex = [&](uint32_t v) {
        const std::vector<uint32_t> near = neighbourhood(v, 3);
        std::vector<uint32_t> tris;
        for (uint32_t w : near) tris.insert(tris.end(), vtris[w].begin(), vtris[w].end());
        std::sort(tris.begin(), tris.end());
        tris.erase(std::unique(tris.begin(), tris.end()), tris.end());
        std::vector<DomainPoint> saved;
        for (uint32_t w : near) saved.push_back(param.points[w]);
        const size_t before = folded_around(surface, param, tris);
        if (reset_base_ring(surface, param, vtris, fixed, v)) {
            for (int pass = 0; pass < 4; ++pass)
                for (uint32_t w : near)
                    if (!fixed[w]) smoother.smooth(w, vtris[w]);
            if (folded_around(surface, param, tris) < before) return;
        }
        for (size_t i = 0; i < near.size(); ++i) param.points[near[i]] = saved[i];
    };
    // Repair: what is still folded (rounding in the collapses, stretched angles at base
    // vertices), with its neighbourhood growing a ring every fourth round that does not fix it.
    std::vector<uint32_t> region, next;
    std::vector<uint8_t> in_region(nv, 0);
    for (int round = 0; round < 24; ++round) {
        region.clear();
        std::fill(in_region.begin(), in_region.end(), 0);
        for (uint32_t t = 0; t < surface.triangle_count(); ++t) {
            double area;
            const uint32_t* tri = &surface.indices[3 * t];
            if (triangle_image_area(param, tri, area) && area > 0) continue;
            // A fold at a base vertex: try its ring by the polar map, then smooth around it, and
            // keep that if less is folded there.
            for (int k = 0; k < 3 && round % 4 == 0; ++k)
                if (param.base_vertex[tri[k]] != kNone) repair_at_base_vertex(tri[k]);
            for (int k = 0; k < 3; ++k)
                if (!in_region[tri[k]]) in_region[tri[k]] = 1, region.push_back(tri[k]);
        }
        if (region.empty()) return;
        for (int ring = 0; ring < 1 + round / 4; ++ring) {
            next = region;
            for (uint32_t v : region)
                for (uint32_t t : vtris[v])
                    for (int k = 0; k < 3; ++k) {
                        uint32_t w = surface.indices[3 * t + k];
                        if (!in_region[w]) in_region[w] = 1, next.push_back(w);
                    }
            region.swap(next);
        }
        for (int pass = 0; pass < 4; ++pass)
            for (uint32_t v : region)
                if (!fixed[v]) smoother.smooth(v, vtris[v]);
    }
}

}  // namespace catpaq::aqp
