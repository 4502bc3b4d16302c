#include "clip.h"

#include <algorithm>
#include <cassert>
#include <cmath>

#include "common_codec/exact_predicates.h"

namespace catpaq {

double snap_to_grid(double v) { return std::nearbyint(v / kSnapGrid) * kSnapGrid; }

static Vec3d to_vec(const LatticePoint& p) { return {double(p[0]), double(p[1]), double(p[2])}; }

LatticePlane make_plane(LatticePoint a, LatticePoint b, LatticePoint c) {
    LatticePlane plane;
    plane.points = {a, b, c};
    std::sort(plane.points.begin(), plane.points.end());
    int64_t u[3], v[3], n[3];
    for (int i = 0; i < 3; ++i) {
        u[i] = int64_t(b[i]) - a[i];
        v[i] = int64_t(c[i]) - a[i];
    }
    n[0] = u[1] * v[2] - u[2] * v[1];
    n[1] = u[2] * v[0] - u[0] * v[2];
    n[2] = u[0] * v[1] - u[1] * v[0];
    // Every face of the hierarchy has a normal proportional to a vector with entries in {-1,0,1}.
    int64_t scale = 0;
    for (int i = 0; i < 3; ++i)
        if (n[i] != 0) scale = scale == 0 ? int64_t(std::llabs(n[i])) : std::min<int64_t>(scale, std::llabs(n[i]));
    assert(scale > 0);
    for (int i = 0; i < 3; ++i) {
        assert(n[i] % scale == 0 && std::llabs(n[i] / scale) <= 1);
        plane.n[i] = int(n[i] / scale);
    }
    plane.d = int64_t(plane.n[0]) * a[0] + int64_t(plane.n[1]) * a[1] + int64_t(plane.n[2]) * a[2];
    // orient3d(p0, p1, p2, x) > 0 when x is on the side of (p1-p0) x (p2-p0); record whether that
    // cross product points along n, so plane_side() is positive on the side n points to.
    const auto& q = plane.points;
    int64_t s[3], t[3];
    for (int i = 0; i < 3; ++i) {
        s[i] = int64_t(q[1][i]) - q[0][i];
        t[i] = int64_t(q[2][i]) - q[0][i];
    }
    int64_t cx = s[1] * t[2] - s[2] * t[1], cy = s[2] * t[0] - s[0] * t[2], cz = s[0] * t[1] - s[1] * t[0];
    plane.orientation = (cx * plane.n[0] + cy * plane.n[1] + cz * plane.n[2]) > 0 ? 1 : -1;
    return plane;
}

int plane_side_exact(const LatticePlane& plane, const Vec3d& p) {
    // plane_side's floating-point filter removes almost every call of this from clipping.
    Vec3d a = to_vec(plane.points[0]), b = to_vec(plane.points[1]), c = to_vec(plane.points[2]);
    return plane.orientation * orient3d(a.data(), b.data(), c.data(), p.data());
}

Vec3d snap_onto_plane(const LatticePlane& plane, const Vec3d& p) {
    Vec3d q = {snap_to_grid(p[0]), snap_to_grid(p[1]), snap_to_grid(p[2])};
    int k = plane.n[0] != 0 ? 0 : (plane.n[1] != 0 ? 1 : 2);
    // n.q = d with n_k = +-1: q_k = n_k * (d - sum_{i != k} n_i q_i), exact on the grid.
    double rest = double(plane.d);
    for (int i = 0; i < 3; ++i)
        if (i != k) rest -= plane.n[i] * q[i];
    q[k] = plane.n[k] * rest;
    return q;
}

Vec3d snap_onto_line(const LatticePoint& a, const LatticePoint& b, const Vec3d& p) {
    int32_t len = 0;
    int dir[3];
    for (int i = 0; i < 3; ++i) len = std::max(len, std::abs(b[i] - a[i]));
    for (int i = 0; i < 3; ++i) dir[i] = (b[i] - a[i]) / len;  // entries in {-1, 0, 1}
    // Parametrise by one coordinate k along which the line moves: snapping that coordinate and
    // deriving the others from it gives the same grid point whichever lattice point of the line
    // is used as `a` (they differ by integer steps).
    int k = dir[0] != 0 ? 0 : (dir[1] != 0 ? 1 : 2);
    double t = snap_to_grid(p[k]);
    Vec3d q;
    for (int i = 0; i < 3; ++i) q[i] = a[i] + dir[i] * dir[k] * (t - a[k]);
    return q;
}

namespace {

// The support of a polygon edge: an edge of the source triangle (0..2) or a clip plane (3 + j).
using Support = int;

struct PolyVertex {
    ClipVertex v;
    Support out;  // support of the edge to the next vertex
};

bool same_position(const Vec3d& a, const Vec3d& b) { return a[0] == b[0] && a[1] == b[1] && a[2] == b[2]; }

bool is_collinear(const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    return orient2d(a.data(), b.data(), c.data(), 0, 1) == 0 && orient2d(a.data(), b.data(), c.data(), 1, 2) == 0 &&
           orient2d(a.data(), b.data(), c.data(), 0, 2) == 0;
}

// Closest point on the lattice line (a, b) to the line (lo, hi): their intersection when the two
// are coplanar and cross. Canonical: endpoints are sorted first.
Vec3d line_line_point(Vec3d lo, Vec3d hi, LatticePoint a, LatticePoint b) {
    if (hi < lo) std::swap(lo, hi);
    if (b < a) std::swap(a, b);
    double u[3], v[3], w[3];
    for (int i = 0; i < 3; ++i) {
        u[i] = double(b[i] - a[i]);
        v[i] = hi[i] - lo[i];
        w[i] = double(a[i]) - lo[i];
    }
    auto dot = [](const double* x, const double* y) { return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]; };
    double uu = dot(u, u), uv = dot(u, v), vv = dot(v, v), uw = dot(u, w), vw = dot(v, w);
    double denom = uu * vv - uv * uv;
    double s = denom != 0 ? (uv * vw - vv * uw) / denom : 0.0;  // parameter along (a, b)
    return {a[0] + s * u[0], a[1] + s * u[1], a[2] + s * u[2]};
}

double plane_value(const LatticePlane& plane, const Vec3d& p) {
    return plane.n[0] * p[0] + plane.n[1] * p[1] + plane.n[2] * p[2] - double(plane.d);
}

// Canonical intersection of the source edge (corners k, k+1) with a clip plane.
ClipVertex edge_plane_point(const std::array<Vec3d, 3>& tri, int k, const ClipPlane& cp) {
    int ia = k, ib = (k + 1) % 3;
    // Compute from the lexicographically smaller endpoint so both neighbours get the same bits.
    bool swap = tri[ib] < tri[ia];
    const Vec3d& lo = swap ? tri[ib] : tri[ia];
    const Vec3d& hi = swap ? tri[ia] : tri[ib];
    double flo = plane_value(cp.plane, lo), fhi = plane_value(cp.plane, hi);
    double t = flo / (flo - fhi);
    if (!(t >= 0.0)) t = 0.0;
    if (t > 1.0) t = 1.0;
    Vec3d x = {lo[0] + t * (hi[0] - lo[0]), lo[1] + t * (hi[1] - lo[1]), lo[2] + t * (hi[2] - lo[2])};
    Vec3d snapped = snap_onto_plane(cp.plane, x);
    // An edge crossing exactly through a lattice corner or line of the face gets that exact point.
    bool done = false;
    for (const LatticePoint& c : cp.corners) {
        Vec3d cv = to_vec(c);
        if (is_collinear(lo, hi, cv)) {
            snapped = cv;
            done = true;
            break;
        }
    }
    if (!done) {
        for (const auto& line : cp.lines) {
            Vec3d a = to_vec(line[0]), b = to_vec(line[1]);
            if (orient3d(a.data(), b.data(), lo.data(), hi.data()) == 0) {
                // The edge crosses the lattice line: intersect the two lines directly (a function of
                // the edge and the line only, so every cell sharing the line gets the same bits).
                snapped = snap_onto_line(line[0], line[1], line_line_point(lo, hi, line[0], line[1]));
                break;
            }
        }
    }
    ClipVertex out;
    out.position = snapped;
    double tk = swap ? 1.0 - t : t;  // parameter from corner ia to ib
    out.weights = {0, 0, 0};
    out.weights[ia] = 1.0 - tk;
    out.weights[ib] = tk;
    return out;
}

// Barycentric weights of p in the triangle (least squares in its plane).
std::array<double, 3> triangle_weights(const std::array<Vec3d, 3>& tri, const Vec3d& p) {
    double e0[3], e1[3], d[3];
    for (int i = 0; i < 3; ++i) {
        e0[i] = tri[1][i] - tri[0][i];
        e1[i] = tri[2][i] - tri[0][i];
        d[i] = p[i] - tri[0][i];
    }
    auto dot = [](const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; };
    double d00 = dot(e0, e0), d01 = dot(e0, e1), d11 = dot(e1, e1), d20 = dot(d, e0), d21 = dot(d, e1);
    double denom = d00 * d11 - d01 * d01;
    if (!(std::fabs(denom) > 0)) return {1.0 / 3, 1.0 / 3, 1.0 / 3};
    double v = (d11 * d20 - d01 * d21) / denom, w = (d00 * d21 - d01 * d20) / denom;
    return {1.0 - v - w, v, w};
}

// Canonical intersection of the source triangle's plane with the lattice line shared by two clip
// planes (an edge of the clipping cell).
ClipVertex triangle_line_point(const std::array<Vec3d, 3>& tri, const ClipPlane& p1, const ClipPlane& p2,
                               const Vec3d& approx) {
    // The common corners of the two faces are the line's endpoints.
    LatticePoint ends[2];
    int found = 0;
    for (const LatticePoint& a : p1.corners)
        for (const LatticePoint& b : p2.corners)
            if (a == b && found < 2) ends[found++] = a;
    ClipVertex out;
    if (found < 2) {  // not adjacent faces: keep the approximate point on the later plane
        out.position = snap_onto_plane(p2.plane, approx);
        out.weights = triangle_weights(tri, out.position);
        return out;
    }
    if (ends[1] < ends[0]) std::swap(ends[0], ends[1]);
    Vec3d a = to_vec(ends[0]), b = to_vec(ends[1]);
    std::array<Vec3d, 3> sorted = tri;
    std::sort(sorted.begin(), sorted.end());
    if (orient3d(sorted[0].data(), sorted[1].data(), sorted[2].data(), a.data()) == 0) {
        out.position = a;
    } else if (orient3d(sorted[0].data(), sorted[1].data(), sorted[2].data(), b.data()) == 0) {
        out.position = b;
    } else {
        double e0[3], e1[3], n[3];
        for (int i = 0; i < 3; ++i) {
            e0[i] = sorted[1][i] - sorted[0][i];
            e1[i] = sorted[2][i] - sorted[0][i];
        }
        n[0] = e0[1] * e1[2] - e0[2] * e1[1];
        n[1] = e0[2] * e1[0] - e0[0] * e1[2];
        n[2] = e0[0] * e1[1] - e0[1] * e1[0];
        double fa = 0, fb = 0;
        for (int i = 0; i < 3; ++i) {
            fa += n[i] * (a[i] - sorted[0][i]);
            fb += n[i] * (b[i] - sorted[0][i]);
        }
        // Not clamped to the segment: intermediate polygons of the successive clips extend
        // beyond the cell, so the crossing can lie anywhere on the line (later planes cut it off).
        double mu = fa / (fa - fb);
        if (!std::isfinite(mu)) {  // the triangle's plane contains the line: keep the local point
            out.position = snap_onto_line(ends[0], ends[1], approx);
            out.weights = triangle_weights(tri, out.position);
            return out;
        }
        Vec3d x = {a[0] + mu * (b[0] - a[0]), a[1] + mu * (b[1] - a[1]), a[2] + mu * (b[2] - a[2])};
        out.position = snap_onto_line(ends[0], ends[1], x);
    }
    out.weights = triangle_weights(tri, out.position);
    return out;
}

}  // namespace

namespace {

// A polygon during clipping, in fixed storage: a triangle clipped by up to 4 planes has at most 7
// corners (each plane adds at most one), and even with more planes a convex cut of a triangle
// stays small. (Two std::vectors per call were a measured hot spot: clip_triangle runs for every
// input triangle and, while coarsening, for every simplified triangle and slot.)
constexpr size_t kMaxPolygon = 16;
struct Polygon {
    PolyVertex v[kMaxPolygon];
    size_t n = 0;
    void push(const PolyVertex& p) {
        assert(n < kMaxPolygon);
        if (n < kMaxPolygon) v[n++] = p;
    }
};

}  // namespace

void clip_triangle(const std::array<Vec3d, 3>& tri, const std::vector<ClipPlane>& planes, std::vector<ClipVertex>& out) {
    out.clear();
    // Each plane adds at most one corner to a convex polygon; callers pass at most 4 planes.
    assert(3 + planes.size() <= kMaxPolygon);
    Polygon poly, next;
    for (int k = 0; k < 3; ++k) {
        ClipVertex v;
        v.position = tri[k];
        v.weights = {0, 0, 0};
        v.weights[k] = 1.0;
        poly.push({v, k});
    }
    int side[kMaxPolygon];
    for (size_t j = 0; j < planes.size(); ++j) {
        const ClipPlane& cp = planes[j];
        const size_t n = poly.n;
        bool any_in = false, any_out = false;
        for (size_t i = 0; i < n; ++i) {
            side[i] = plane_side(cp.plane, poly.v[i].v.position) * cp.sign;
            any_in |= side[i] > 0;
            any_out |= side[i] < 0;
        }
        if (!any_out) {
            if (any_in) continue;
            // The polygon lies in the plane: keep it only on the side its normal points away from.
            double e0[3], e1[3], nrm[3];
            for (int i = 0; i < 3; ++i) {
                e0[i] = tri[1][i] - tri[0][i];
                e1[i] = tri[2][i] - tri[0][i];
            }
            nrm[0] = e0[1] * e1[2] - e0[2] * e1[1];
            nrm[1] = e0[2] * e1[0] - e0[0] * e1[2];
            nrm[2] = e0[0] * e1[1] - e0[1] * e1[0];
            double toward_kept = cp.sign * (nrm[0] * cp.plane.n[0] + nrm[1] * cp.plane.n[1] + nrm[2] * cp.plane.n[2]);
            if (toward_kept < 0) continue;
            return;  // pointing into the kept side, or degenerate: the neighbour keeps it
        }
        if (!any_in) return;  // outside, or touching in a point or segment
        next.n = 0;
        for (size_t i = 0; i < n; ++i) {
            const PolyVertex& cur = poly.v[i];
            int s0 = side[i], s1 = side[(i + 1) % n];
            Support e = cur.out;
            if (s0 >= 0) next.push({cur.v, (s0 == 0 && s1 < 0) ? Support(3 + j) : e});
            if ((s0 > 0 && s1 < 0) || (s0 < 0 && s1 > 0)) {
                ClipVertex x;
                if (e < 3) {
                    x = edge_plane_point(tri, e, cp);
                } else {
                    Vec3d approx;
                    const Vec3d& p = cur.v.position;
                    const Vec3d& q = poly.v[(i + 1) % n].v.position;
                    double fp = plane_value(cp.plane, p), fq = plane_value(cp.plane, q);
                    double t = fp / (fp - fq);
                    for (int k = 0; k < 3; ++k) approx[k] = p[k] + t * (q[k] - p[k]);
                    x = triangle_line_point(tri, planes[e - 3], cp, approx);
                }
                next.push({x, s0 > 0 ? Support(3 + j) : e});
            }
        }
        // Drop consecutive duplicates (a construction can land on an existing vertex).
        poly.n = 0;
        for (size_t i = 0; i < next.n; ++i) {
            const PolyVertex& pv = next.v[i];
            if (poly.n == 0 || !same_position(poly.v[poly.n - 1].v.position, pv.v.position)) poly.push(pv);
        }
        while (poly.n > 1 && same_position(poly.v[poly.n - 1].v.position, poly.v[0].v.position)) --poly.n;
        if (poly.n < 3) return;
    }
    for (size_t i = 0; i < poly.n; ++i) out.push_back(poly.v[i].v);
}

namespace {

// |u x v|^2 and |u|^2 + |v|^2 + |w|^2 for a triangle's edges u = q - p, v = r - p, w = r - q.
struct EdgeMeasures {
    double cross2, edges;
};

EdgeMeasures edge_measures(const Vec3d& p, const Vec3d& q, const Vec3d& r) {
    double u[3], v[3], w[3];
    for (int i = 0; i < 3; ++i) {
        u[i] = q[i] - p[i];
        v[i] = r[i] - p[i];
        w[i] = r[i] - q[i];
    }
    double cx = u[1] * v[2] - u[2] * v[1], cy = u[2] * v[0] - u[0] * v[2], cz = u[0] * v[1] - u[1] * v[0];
    return {cx * cx + cy * cy + cz * cz, u[0] * u[0] + u[1] * u[1] + u[2] * u[2] + v[0] * v[0] + v[1] * v[1] +
                                             v[2] * v[2] + w[0] * w[0] + w[1] * w[1] + w[2] * w[2]};
}

}  // namespace

// Area over the sum of squared edge lengths (0 for collinear corners, decided exactly).
double triangle_quality(const Vec3d& p, const Vec3d& q, const Vec3d& r) {
    const EdgeMeasures m = edge_measures(p, q, r);
    const double area2 = std::sqrt(m.cross2), edges = m.edges;
    // Floating-point filter for the exact collinearity test: for collinear points the computed
    // cross product only holds the rounding of u and v, |u x v| < 1e-15 |u| |v| <= 1e-15 edges,
    // so a quality above 1e-12 proves the points are not collinear. Only near-degenerate corners
    // pay for the exact predicates (9 orient2d calls per triangle were a measured hot spot of
    // leaf clipping, where almost every polygon is a triangle).
    if (!(edges > 0 && area2 > 1e-12 * edges) && is_collinear(p, q, r)) return 0.0;
    return edges > 0 ? area2 / edges : 0.0;
}

bool has_area(const std::array<Vec3d, 3>& tri) {
    // triangle_quality's filter without its square root and division (has_area runs for every
    // whole triangle the converter adds; weld_bench: leaves 6%, clip 4% faster): |u x v|^2 >
    // 2e-24 edges^2 implies |u x v| > 1e-12 edges however the square root rounds, so the quality
    // is positive. Everything else goes to triangle_quality, which decides as before.
    const EdgeMeasures m = edge_measures(tri[0], tri[1], tri[2]);
    if (m.edges > 0 && m.cross2 > 2e-24 * m.edges * m.edges) return true;
    return triangle_quality(tri[0], tri[1], tri[2]) > 0.0;
}

void triangulate_polygon(const std::vector<ClipVertex>& polygon, std::vector<std::array<int, 3>>& out) {
    int n = int(polygon.size());
    if (n < 3) return;
    auto quality = [&](int a, int b, int c) {
        return triangle_quality(polygon[a].position, polygon[b].position, polygon[c].position);
    };
    if (n == 3) {
        // A triangle (most polygons are whole input triangles) is its own triangulation: every
        // apex gives it, only rotated. (Searching the best apex cost four quality evaluations
        // per triangle; it was 2.7% of a 10M build's CPU time.)
        if (quality(0, 1, 2) > 0.0) out.push_back({0, 1, 2});
        return;
    }
    int best_apex = 0;
    double best = -1.0;
    for (int a = 0; a < n; ++a) {
        double worst = 1e300;
        for (int i = 1; i + 1 < n; ++i) worst = std::min(worst, quality(a, (a + i) % n, (a + i + 1) % n));
        if (worst > best) {
            best = worst;
            best_apex = a;
        }
    }
    for (int i = 1; i + 1 < n; ++i) {
        int b = (best_apex + i) % n, c = (best_apex + i + 1) % n;
        if (quality(best_apex, b, c) > 0.0) out.push_back({best_apex, b, c});
    }
}

}  // namespace catpaq
