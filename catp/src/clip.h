#pragma once
// Clipping triangles by lattice planes, robustly (private to the catp module).
//
// Why this is crack-free: every vertex the clipper creates is a *canonical construction* — a
// function of the original edge or triangle and of the lattice plane or line only, never of the
// tetrahedron doing the clipping — and it is snapped exactly onto that plane (line) on a fixed
// 2^-32 lattice-unit grid. Sides are decided by exact predicates on these concrete points. So
// two tetrahedra sharing a face F build the same vertices on F and the same segments along it.
#include <array>
#include <cstdint>
#include <vector>

#include "catp/lattice.h"
#include "mesh/mesh.h"

namespace catpaq {

// Fixed-point grid on which all clipping positions live (lattice units).
constexpr double kSnapGrid = 1.0 / 4294967296.0;  // 2^-32
double snap_to_grid(double v);

// A plane through three lattice points, with integer normal entries in {-1, 0, 1} (true for every
// face of the hierarchy) and an integer offset: n . p = d.
struct LatticePlane {
    std::array<LatticePoint, 3> points;  // canonical (sorted) — used by exact predicates
    std::array<int, 3> n{0, 0, 0};
    int64_t d = 0;
    int orientation = 1;  // +1 if orient3d(points) agrees with the direction of n, else -1
    bool operator==(const LatticePlane& o) const { return points == o.points; }
};
LatticePlane make_plane(LatticePoint a, LatticePoint b, LatticePoint c);
// Exact side of p: +1, 0, -1 (sign of orient3d with the canonical points). Inline: the
// floating-point filter decides almost every call, and the clipper and clip_into_slots make
// several per vertex; only points near the plane call the exact predicate.
int plane_side_exact(const LatticePlane& plane, const Vec3d& p);
inline int plane_side(const LatticePlane& plane, const Vec3d& p) {
    // n has entries in {-1,0,1} and |p|, |d| < 2^22, so n.p - d is computed with an absolute
    // error below 2^-28; outside that band its sign is certain.
    double value = plane.n[0] * p[0] + plane.n[1] * p[1] + plane.n[2] * p[2] - double(plane.d);
    if (value > 1e-8) return 1;
    if (value < -1e-8) return -1;
    return plane_side_exact(plane, p);
}

// Moves p exactly onto the plane (p must be on the 2^-32 grid; the result is too).
Vec3d snap_onto_plane(const LatticePlane& plane, const Vec3d& p);
// Moves p exactly onto the line through lattice points a and b.
Vec3d snap_onto_line(const LatticePoint& a, const LatticePoint& b, const Vec3d& p);

// A vertex of a clipped polygon: position plus the barycentric weights of the original triangle's
// corners (for interpolating normals and colours).
struct ClipVertex {
    Vec3d position;
    std::array<double, 3> weights;  // of the source triangle's corners 0, 1, 2
};

// One half-space of a clip: keep the side where plane_side * sign >= 0. `edges` are the lattice
// lines bounding the plane's face in the clipping cell (used to recognise an edge or a triangle
// crossing exactly through a line); `corners` the lattice points of that face.
struct ClipPlane {
    LatticePlane plane;
    int sign = 1;
    std::vector<std::array<LatticePoint, 2>> lines;
    std::vector<LatticePoint> corners;
};

// Clips triangle (p0, p1, p2) (grid positions) by the half-spaces. A triangle lying in one of the
// planes is kept only if its normal points out of the kept side (so exactly one of the two cells
// sharing that face keeps it). Returns the polygon (possibly empty); `out` is cleared first.
void clip_triangle(const std::array<Vec3d, 3>& tri, const std::vector<ClipPlane>& planes, std::vector<ClipVertex>& out);

// True unless the triangle's corners are collinear (decided exactly): what clipping keeps of a
// triangle with no plane to clip it.
bool has_area(const std::array<Vec3d, 3>& tri);

// Triangulates a convex planar polygon (the output of clip_triangle) without sliver fans: picks
// the fan apex that maximises the smallest triangle quality. Appends index triples (into the
// polygon) to `out`. Polygons with collinear vertices produce no triangle.
void triangulate_polygon(const std::vector<ClipVertex>& polygon, std::vector<std::array<int, 3>>& out);

}  // namespace catpaq
