// The simplification-error measurement as it was before the fast-measure work (commit af89bda),
// kept verbatim as the reference that measure_bench times against and checks bit for bit.
#pragma once
#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <cstdint>
#include <vector>

#include <tbb/parallel_invoke.h>

#include "../../catp/src/fragment_build.h"

namespace measure_reference {
using catpaq::Vec3d;
using catpaq::WorkFragment;
namespace {
// Closest point on triangle (a, b, c) to p (Ericson, Real-Time Collision Detection 5.1.5);
// returns the squared distance.
double point_triangle_distance2(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    auto sub = [](const Vec3d& x, const Vec3d& y) { return Vec3d{x[0] - y[0], x[1] - y[1], x[2] - y[2]}; };
    auto dot = [](const Vec3d& x, const Vec3d& y) { return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]; };
    auto at = [&](double v, double w) {
        Vec3d q = {a[0] + v * (b[0] - a[0]) + w * (c[0] - a[0]), a[1] + v * (b[1] - a[1]) + w * (c[1] - a[1]),
                   a[2] + v * (b[2] - a[2]) + w * (c[2] - a[2])};
        Vec3d d = sub(p, q);
        return dot(d, d);
    };
    Vec3d ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
    double d1 = dot(ab, ap), d2 = dot(ac, ap);
    if (d1 <= 0 && d2 <= 0) return at(0, 0);
    Vec3d bp = sub(p, b);
    double d3 = dot(ab, bp), d4 = dot(ac, bp);
    if (d3 >= 0 && d4 <= d3) return at(1, 0);
    double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return at(d1 / (d1 - d3), 0);
    Vec3d cp = sub(p, c);
    double d5 = dot(ab, cp), d6 = dot(ac, cp);
    if (d6 >= 0 && d5 <= d6) return at(0, 1);
    double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return at(0, d2 / (d2 - d6));
    double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
        double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return at(1 - w, w);
    }
    double denom = 1.0 / (va + vb + vc);
    return at(vb * denom, vc * denom);
}

// Distance from points to a small triangle mesh through a uniform grid of its triangles' boxes.
// (CGAL's AABB tree took half of the converter's time here: a diamond has a few thousand
// triangles and each query lies close to the surface, which a grid answers in a cell or two.)
//
// The caller only wants the largest of many distances (a Hausdorff distance), so a query may
// stop as soon as it finds a triangle within `enough` of the point (the running maximum): the
// point cannot raise the maximum any more. That early exit, with the cheap pre-pass below, made
// the measurement about 4x faster (1M-triangle scan, perf): most points lie on or very near the
// surface, and the triangle containing their projection comes up among the first few of their
// cell.
class GridDistance {
    // 76 bytes: corners by index, not by position. With the positions inline (136 bytes) the
    // measurement was about 5% faster, but the converter's peak memory rose by 2 MiB on a 1M-
    // triangle scan (two grids per diamond, one diamond per thread).
    struct Tri {
        Tri() {}  // left uninitialized: every field is written before use
        Vec3d centre;
        double radius;
        Vec3d normal;   // unit, or zero for a degenerate triangle
        double offset;  // normal . centre
        uint32_t v[3];  // corners
    };

public:
    GridDistance(const std::vector<Vec3d>& positions, const std::vector<uint32_t>& indices) : positions_(positions) {
        const size_t triangles = indices.size() / 3;
        for (int i = 0; i < 3; ++i) {
            lo_[i] = 1e300;
            hi_[i] = -1e300;
        }
        // Per triangle, in one record: bounding sphere, supporting plane, corner indices (not
        // zero-filled first: Tri's constructor leaves it alone).
        tris_.resize(triangles);
        double edges = 0;
        size_t measured = 0;
        for (size_t t = 0; t < triangles; ++t) {
            Tri& tri = tris_[t];
            const Vec3d* q[3];
            for (int k = 0; k < 3; ++k) {
                tri.v[k] = indices[3 * t + k];
                q[k] = &positions[tri.v[k]];
                for (int i = 0; i < 3; ++i) {
                    lo_[i] = std::min(lo_[i], (*q[k])[i]);
                    hi_[i] = std::max(hi_[i], (*q[k])[i]);
                }
            }
            // The mean edge only sizes the grid: a sample of the triangles will do.
            if (t % 8 == 0) {
                for (int k = 0; k < 3; ++k) edges += length(*q[k], *q[(k + 1) % 3]);
                ++measured;
            }
            for (int i = 0; i < 3; ++i) tri.centre[i] = ((*q[0])[i] + (*q[1])[i] + (*q[2])[i]) / 3.0;
            double r2 = 0;
            for (int k = 0; k < 3; ++k) r2 = std::max(r2, length2(*q[k], tri.centre));
            tri.radius = std::sqrt(r2) * 1.000001;
            const Vec3d u = {(*q[1])[0] - (*q[0])[0], (*q[1])[1] - (*q[0])[1], (*q[1])[2] - (*q[0])[2]};
            const Vec3d v = {(*q[2])[0] - (*q[0])[0], (*q[2])[1] - (*q[0])[1], (*q[2])[2] - (*q[0])[2]};
            Vec3d n = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
            const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            // Degenerate triangles get a zero normal: their plane test always passes.
            const double inv = len > 0 ? 1.0 / len : 0.0;
            for (int i = 0; i < 3; ++i) tri.normal[i] = n[i] * inv;
            tri.offset = tri.normal[0] * tri.centre[0] + tri.normal[1] * tri.centre[1] + tri.normal[2] * tri.centre[2];
        }
        const double extent = std::max({hi_[0] - lo_[0], hi_[1] - lo_[1], hi_[2] - lo_[2], 1e-9});
        // Cells of about two mean edge lengths (a surface fills few of them, each holding a few
        // triangles), at most 128 per axis.
        const double mean_edge = measured ? edges / double(3 * measured) : extent;
        cell_ = std::max(extent / 128.0, 2.0 * mean_edge) * 1.0000001;
        // Slack for the cell-box bound: a triangle is filed under the cells its box overlaps as
        // computed by clamp_cell, whose rounding may put a point a hair outside the cell's
        // nominal box. Positions are below 2^22 lattice units, so rounding is below 1e-9.
        slack_ = cell_ * 1e-6 + 1e-6;
        for (int i = 0; i < 3; ++i) dims_[i] = std::max(1, int((hi_[i] - lo_[i]) / cell_) + 1);
        assert(std::max({dims_[0], dims_[1], dims_[2]}) <= 256);  // cell ranges fit in bytes
        max_dim_ = std::max({dims_[0], dims_[1], dims_[2]});
        // Counting sort of (cell, triangle) by cell.
        const size_t cells = size_t(dims_[0]) * dims_[1] * dims_[2];
        start_.assign(cells + 1, 0);
        // Each triangle's cell range, kept for the fill pass: computing it twice (three corner
        // lookups each) was a tenth of the construction. At most 129 cells per axis: one byte.
        std::vector<std::array<uint8_t, 6>> ranges(triangles);
        for (size_t t = 0; t < triangles; ++t) {
            int r[6];
            cell_range(tris_[t], r);
            for (int i = 0; i < 6; ++i) ranges[t][i] = uint8_t(r[i]);
            for (int z = r[2]; z <= r[5]; ++z)
                for (int y = r[1]; y <= r[4]; ++y)
                    for (int x = r[0]; x <= r[3]; ++x) start_[cell_index(x, y, z)]++;
        }
        // Inclusive prefix sums: start_[c] is the end of cell c until the fill below.
        for (size_t c = 1; c < cells; ++c) start_[c] += start_[c - 1];
        start_[cells] = start_[cells - 1];
        items_.resize(start_[cells]);
        // Fill back to front, decrementing the end of each cell: the ends become the starts, and
        // every cell lists its triangles in increasing order.
        for (size_t t = triangles; t-- > 0;) {
            const std::array<uint8_t, 6>& r = ranges[t];
            for (int z = r[2]; z <= r[5]; ++z)
                for (int y = r[1]; y <= r[4]; ++y)
                    for (int x = r[0]; x <= r[3]; ++x) items_[--start_[cell_index(x, y, z)]] = uint32_t(t);
        }
    }

    // Distance from p to the mesh; or, when that is at most `enough`, possibly any value between
    // it and `enough` (the search stops at the first triangle within `enough`).
    double distance(const Vec3d& p, double enough = 0.0) const {
        if (tris_.empty()) return 0.0;
        int c[3];
        for (int i = 0; i < 3; ++i) c[i] = clamp_cell(i, p[i]);
        double best2 = 1e300, best = 1e150;  // squared and plain
        const double enough2 = enough * enough;
        // Rings of cells around p's cell. Every triangle not yet seen before ring r is at least
        // margin + (r - 1) cells away, margin being p's distance to the faces of its own cell
        // (0 if p lies outside the grid): stop once the best found is closer than that.
        double margin = 1e300;
        for (int i = 0; i < 3; ++i) {
            double in_cell = p[i] - (lo_[i] + c[i] * cell_);
            margin = std::min({margin, in_cell, cell_ - in_cell});
        }
        margin = std::max(0.0, margin);
        // First, the triangles of p's cell that can be within `enough` by two cheap bounds
        // (bounding sphere, supporting plane): for a point on the surface, usually one or two,
        // one of which ends the query. (Without this, a query computed about 8 exact
        // point-triangle distances before it found the one within `enough`.)
        if (enough > 0) {
            const size_t cell = cell_index(c[0], c[1], c[2]);
            const double plane_limit = enough * 1.000000001 + slack_;
            for (uint32_t k = start_[cell]; k < start_[cell + 1]; ++k) {
                const Tri& t = tris_[items_[k]];
                const double dx = p[0] - t.centre[0], dy = p[1] - t.centre[1], dz = p[2] - t.centre[2];
                const double reach = t.radius + enough;
                if (dx * dx + dy * dy + dz * dz > reach * reach * 1.000000001) continue;
                const double height = t.normal[0] * p[0] + t.normal[1] * p[1] + t.normal[2] * p[2] - t.offset;
                if (std::fabs(height) > plane_limit) continue;
                const double d2 = point_triangle_distance2(p, positions_[t.v[0]], positions_[t.v[1]], positions_[t.v[2]]);
                if (d2 < best2) {
                    best2 = d2;
                    best = std::sqrt(d2);
                    if (best2 <= enough2) return best;
                }
            }
        }
        for (int r = 0; r <= max_dim_; ++r) {
            if (r > 0 && best2 < 1e300 && best <= margin + double(r - 1) * cell_) break;
            for (int z = std::max(0, c[2] - r); z <= std::min(dims_[2] - 1, c[2] + r); ++z) {
                const double gz = axis_gap(2, z, p[2]);
                for (int y = std::max(0, c[1] - r); y <= std::min(dims_[1] - 1, c[1] + r); ++y) {
                    const double gy = axis_gap(1, y, p[1]);
                    const bool shell_zy = std::abs(z - c[2]) == r || std::abs(y - c[1]) == r;
                    for (int x = std::max(0, c[0] - r); x <= std::min(dims_[0] - 1, c[0] + r); ++x) {
                        if (!shell_zy && std::abs(x - c[0]) != r) continue;  // inner rings: done
                        // The cell's box is farther than the best: nothing in it is closer.
                        const double gx = axis_gap(0, x, p[0]);
                        if (gx * gx + gy * gy + gz * gz >= best2) continue;
                        const size_t cell = cell_index(x, y, z);
                        for (uint32_t k = start_[cell]; k < start_[cell + 1]; ++k) {
                            const Tri& t = tris_[items_[k]];
                            // Bounding-sphere lower bound first (|p - centre| - radius >= best),
                            // without a square root, with a relative margin for rounding.
                            const double dx = p[0] - t.centre[0], dy = p[1] - t.centre[1], dz = p[2] - t.centre[2];
                            const double reach = t.radius + best;
                            if (dx * dx + dy * dy + dz * dz > reach * reach * 1.000000001) continue;
                            const double d2 = point_triangle_distance2(p, positions_[t.v[0]], positions_[t.v[1]], positions_[t.v[2]]);
                            if (d2 < best2) {
                                best2 = d2;
                                best = std::sqrt(d2);
                                if (best2 <= enough2) return best;
                            }
                        }
                    }
                }
            }
        }
        return best;
    }

private:
    static double length2(const Vec3d& a, const Vec3d& b) {
        return (a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]);
    }
    static double length(const Vec3d& a, const Vec3d& b) { return std::sqrt(length2(a, b)); }
    // First and last cell per axis of the triangle's box (x, y, z, then x, y, z).
    void cell_range(const Tri& t, int r[6]) const {
        const Vec3d &a = positions_[t.v[0]], &b = positions_[t.v[1]], &c = positions_[t.v[2]];
        for (int i = 0; i < 3; ++i) {
            r[i] = clamp_cell(i, std::min({a[i], b[i], c[i]}));
            r[3 + i] = clamp_cell(i, std::max({a[i], b[i], c[i]}));
        }
    }
    int clamp_cell(int axis, double v) const { return std::max(0, std::min(dims_[axis] - 1, int((v - lo_[axis]) / cell_))); }
    size_t cell_index(int x, int y, int z) const { return (size_t(z) * dims_[1] + y) * dims_[0] + x; }
    // Distance along one axis from v to cell i's slab (0 inside), less the slack.
    double axis_gap(int axis, int i, double v) const {
        const double a = lo_[axis] + i * cell_, b = a + cell_;
        return std::max(0.0, std::max(a - v, v - b) - slack_);
    }

    double lo_[3], hi_[3], cell_ = 1, slack_ = 0;
    int dims_[3] = {1, 1, 1};
    int max_dim_ = 1;
    const std::vector<Vec3d>& positions_;
    std::vector<Tri> tris_;
    std::vector<uint32_t> start_, items_;  // cell c lists items_[start_[c] .. start_[c + 1])
};



// Largest distance from the vertices that the simplification removed to the simplified surface.
double removed_vertices_error(const std::vector<Vec3d>& pos, const std::vector<uint32_t>& simplified) {
    std::vector<uint8_t> kept(pos.size(), 0);
    for (uint32_t v : simplified) kept[v] = 1;
    GridDistance to_simplified(pos, simplified);
    double error = 0;
    for (size_t v = 0; v < pos.size(); ++v)
        if (!kept[v]) error = std::max(error, to_simplified.distance(pos[v], error));
    return error;
}

// Largest distance from the simplified triangles' centroids and edge midpoints to the gathered
// surface.
double simplified_points_error(const std::vector<Vec3d>& pos, const std::vector<uint32_t>& gathered,
                               const std::vector<uint32_t>& simplified) {
    GridDistance to_gathered(pos, gathered);
    double error = 0;
    for (size_t i = 0; i + 2 < simplified.size(); i += 3) {
        const Vec3d &a = pos[simplified[i]], &b = pos[simplified[i + 1]], &c = pos[simplified[i + 2]];
        const Vec3d centroid = {(a[0] + b[0] + c[0]) / 3, (a[1] + b[1] + c[1]) / 3, (a[2] + b[2] + c[2]) / 3};
        error = std::max(error, to_gathered.distance(centroid, error));
    }
    // Edges, each once: bucketed by their smaller vertex (a counting sort; sorting 64-bit edge
    // keys cost a third as much as the queries it saved), duplicates found within a bucket.
    std::vector<uint32_t> first(pos.size() + 1, 0);
    for (size_t i = 0; i < simplified.size(); ++i) {
        const uint32_t u = simplified[i], w = simplified[i % 3 == 2 ? i - 2 : i + 1];
        first[std::min(u, w) + 1]++;
    }
    for (size_t v = 1; v < first.size(); ++v) first[v] += first[v - 1];
    std::vector<uint32_t> other(simplified.size());
    {
        std::vector<uint32_t> fill(first.begin(), first.end() - 1);
        for (size_t i = 0; i < simplified.size(); ++i) {
            const uint32_t u = simplified[i], w = simplified[i % 3 == 2 ? i - 2 : i + 1];
            other[fill[std::min(u, w)]++] = std::max(u, w);
        }
    }
    for (size_t u = 0; u < pos.size(); ++u)
        for (uint32_t k = first[u]; k < first[u + 1]; ++k) {
            const uint32_t w = other[k];
            if (std::find(&other[first[u]], &other[k], w) != &other[k]) continue;  // seen
            const Vec3d &a = pos[u], &b = pos[w];
            const Vec3d midpoint = {(a[0] + b[0]) / 2, (a[1] + b[1]) / 2, (a[2] + b[2]) / 2};
            error = std::max(error, to_gathered.distance(midpoint, error));
        }
    return error;
}


// Hausdorff-style distance between the gathered surface and its simplification, both ways:
// removed vertices to the simplified surface, and the simplified triangles' centroids and edge
// midpoints to the gathered surface. (The simplifier's quadric cost is a mean, not a bound:
// measured here so the stored errors can be trusted by the cut engine.)
//
// The result is exactly the maximum of the sample points' distances: every query gets the
// running maximum as its `enough`, so a query is only cut short when its distance cannot raise
// the maximum; and an edge shared by two simplified triangles has one midpoint, measured once
// (the same point, bit for bit, as (a + b) / 2 is symmetric).
double measured_simplification_error(const WorkFragment& gathered, const std::vector<uint32_t>& simplified) {
    if (simplified.size() == gathered.indices.size()) return 0.0;
    // The two directions are independent (each is the exact maximum over its own points), so
    // they may run side by side.
    double removed = 0, points = 0;
    tbb::parallel_invoke([&] { removed = removed_vertices_error(gathered.positions, simplified); },
                         [&] { points = simplified_points_error(gathered.positions, gathered.indices, simplified); });
    return std::max(removed, points);
}
}  // namespace
}  // namespace measure_reference
