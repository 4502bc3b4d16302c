// Parameter smoothing in the final domain (the geodesic images check_parameterization judges):
// Gauss-Seidel sweeps over the free vertices (not base vertices, not on the border). Each vertex
// tries a few positions between where it is and the mean-value combination of its neighbours
// (Floater 2003) in the chart of its base triangle, and moves to the first that lowers the
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
#include <vector>

#include "aqp/domain.h"

namespace catpaq::aqp {
namespace {

constexpr double kSqrt3Over2 = 0.86602540378443864676;

Vec3d sub(const Vec3d& a, const Vec3d& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
double dot(const Vec3d& a, const Vec3d& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

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
};

class VertexSmoother {
public:
    VertexSmoother(const Mesh& surface, Parameterization& param, double scale)
        : surface_(surface), param_(param), scale_(scale) {}

    // Tries to move v; returns true if it moved.
    bool smooth(uint32_t v, const std::vector<uint32_t>& tris) {
        const uint32_t chart = param_.points[v].triangle;
        Vec2 here;
        if (!param_.domain.chart_position(param_.points[v], chart, here) || !gather(v, chart, tris)) return false;
        const Vec2 target = mean_value_centre();
        // When everything around v lies in v's own base triangle, this chart is the one the
        // check uses: a finite energy means nothing is folded, and the slow test is not needed.
        const double energy_here = energy(here);
        const size_t folded_before = all_local_ && energy_here < INFINITY ? 0 : folded_around(surface_, param_, tris);
        const double energy_before = folded_before ? INFINITY : energy_here;
        for (double step : {1.0, 0.5, 0.25, 0.125}) {
            Vec2 x{here[0] + step * (target[0] - here[0]), here[1] + step * (target[1] - here[1])};
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
    bool gather(uint32_t v, uint32_t chart, const std::vector<uint32_t>& tris) {
        corners_.clear();
        all_local_ = true;
        const Vec3d& p = surface_.positions[v];
        for (uint32_t t : tris) {
            const uint32_t* tri = &surface_.indices[3 * t];
            int i = tri[0] == v ? 0 : tri[1] == v ? 1 : 2;
            uint32_t a = tri[(i + 1) % 3], b = tri[(i + 2) % 3];
            all_local_ = all_local_ && local(a, chart) && local(b, chart);
            Corner c;
            if (!param_.domain.chart_position(param_.points[a], chart, c.a) ||
                !param_.domain.chart_position(param_.points[b], chart, c.b))
                return false;
            Vec3d ea = sub(surface_.positions[a], p), eb = sub(surface_.positions[b], p);
            c.la = std::sqrt(dot(ea, ea));
            if (!(c.la > 0)) return false;
            c.bx = dot(eb, ea) / c.la;
            double by2 = dot(eb, eb) - c.bx * c.bx;
            if (!(by2 > 0)) return false;
            c.by = std::sqrt(by2);
            c.area = 0.5 * c.la * c.by;
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
            double lb = std::sqrt(c.bx * c.bx + c.by * c.by);
            double half_tan = std::tan(0.5 * std::atan2(c.by, c.bx));
            double wa = half_tan / c.la, wb = half_tan / lb;
            y[0] += wa * c.a[0] + wb * c.b[0];
            y[1] += wa * c.a[1] + wb * c.b[1];
            wsum += wa + wb;
        }
        return {y[0] / wsum, y[1] / wsum};
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
    VertexSmoother smoother(surface, param, std::sqrt(surface_area / domain_area));
    for (int sweep = 0; sweep < sweeps; ++sweep)
        for (uint32_t v = 0; v < nv; ++v)
            if (!fixed[v]) smoother.smooth(v, vtris[v]);
}

}  // namespace catpaq::aqp
