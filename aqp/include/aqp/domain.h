#pragma once
// The base domain of AQP and the parameterization of the surface over it.
//
// The base domain is a coarse triangle mesh whose vertices are surface vertices. Abstractly every
// base triangle is an equilateral triangle of side 1: the domain is a piecewise flat surface with
// cone points at base vertices (60 degrees per incident triangle). A point of the domain is a
// base triangle and barycentric coordinates in its corner order (DomainPoint).
//
// Charts. Each base triangle has its own chart in which its corners sit at the lattice points
// (0,0), (1,0), (0,1) of the triangular lattice (basis e1 = (1,0), e2 = (1/2, sqrt(3)/2)), so
// that a point's chart coordinates are its barycentric coordinates 1 and 2. A neighbouring base
// triangle unfolds into the chart across the shared edge (its far corner is the parallelogram
// point P_k + P_k+1 - P_k+2), so every unfolded corner is an integer lattice point: unfolding is
// exact. Triangles around a corner of the chart's triangle unfold by walking the corner's fan the
// shorter way round.
//
// The parameterization gives every surface vertex a DomainPoint (build_parameterization: MAPS,
// Lee et al. 1998, with half-edge collapses and conformal z^a flattening of 1-rings). A surface
// triangle's image is the straight triangle between its vertices' points in an unfolding of the
// base triangles they lie in (a geodesic triangle of the piecewise flat domain). The map is
// bijective when every image is positively oriented and the images' areas sum to the domain's
// area (check_parameterization).
#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "mesh/mesh.h"

namespace catpaq {
class Progress;
}

namespace catpaq::aqp {

constexpr uint32_t kNone = UINT32_MAX;

using Vec2 = std::array<double, 2>;
using Lattice2 = std::array<int32_t, 2>;

struct DomainPoint {
    uint32_t triangle = 0;
    std::array<double, 3> bary{1, 0, 0};  // non-negative, sum 1
};

struct BaseDomain {
    std::vector<uint32_t> vertex_source;            // base vertex -> surface vertex
    std::vector<std::array<uint32_t, 3>> triangles;  // base vertex ids, counter-clockwise
    // Across edge k (corner k to corner k+1): the neighbouring triangle (kNone on the border) and
    // the index of the same edge in it.
    std::vector<std::array<uint32_t, 3>> neighbour;
    std::vector<std::array<uint8_t, 3>> neighbour_edge;

    size_t vertex_count() const { return vertex_source.size(); }
    size_t triangle_count() const { return triangles.size(); }
    // Fills `neighbour` and `neighbour_edge` from `triangles`; false if an edge has more than two
    // triangles or two triangles run an edge the same way (not an oriented manifold).
    bool connect();
    // Steps from triangle t across its edge k: t becomes the neighbour and `corners` (t's corners
    // in some chart) the neighbour's corners in the same chart. False on the border.
    bool across(uint32_t& t, uint32_t k, std::array<Lattice2, 3>& corners) const;
    // Where the corners of `from` lie in the chart of `to` (integer lattice points), for every
    // way of walking from `to` to `from` round a corner they share (an edge neighbour is one step
    // either way). Round a cone point the ways differ: the domain is flat only piecewise.
    struct Unfolding {
        std::array<Lattice2, 3> corners;
        int steps;
    };
    void unfoldings(uint32_t from, uint32_t to, std::vector<Unfolding>& out) const;
    // The unfolding of fewest steps; false when `from` shares no corner with `to`.
    bool unfold(uint32_t from, uint32_t to, std::array<Lattice2, 3>& corners, int* steps = nullptr) const;
    // The lattice coordinates of `p` in the chart of `to`: through the unfolding of fewest steps,
    // and of those the one putting it nearest `near` (lattice coordinates in the same chart). A
    // base vertex (one coordinate 1) that is a corner of `to` is that corner; otherwise it unfolds
    // from the triangles around it. False when no unfolding reaches.
    bool chart_position(const DomainPoint& p, uint32_t to, Vec2& out, const Vec2* near = nullptr) const;
    // The domain point at lattice coordinates `x` of the chart of `start`, found by walking
    // across the edges x lies beyond (at most `max_steps` triangles); false if the walk leaves
    // the domain or does not arrive.
    bool locate(uint32_t start, const Vec2& x, DomainPoint& out, int max_steps = 16) const;
};

// Euclidean coordinates of lattice coordinates (a, b): a e1 + b e2.
inline Vec2 lattice_to_plane(const Vec2& l) { return {l[0] + 0.5 * l[1], 0.86602540378443864676 * l[1]}; }

struct Parameterization {
    BaseDomain domain;
    std::vector<DomainPoint> points;      // one per surface vertex
    std::vector<uint32_t> base_vertex;    // per surface vertex: its base vertex, or kNone
};

// The image of the surface triangle with vertices `tri`, in lattice coordinates of the chart of
// `chart`: the base triangle of its first vertex that is not a base vertex (a base vertex sits
// at a corner of every triangle around it, so its own triangle says nothing about where the
// image lies). False if the vertices' base triangles do not unfold into one chart.
bool triangle_image(const Parameterization& param, const uint32_t tri[3], Vec2 out[3], uint32_t* chart = nullptr);
// The signed area of that image (domain units: the base triangles have area sqrt(3)/4), checked
// in the chart of every vertex that is not a base vertex: false if a chart cannot hold it or the
// charts disagree (the image would wrap around a cone point).
bool triangle_image_area(const Parameterization& param, const uint32_t tri[3], double& area);

// Whether two 2D triangles (counter-clockwise, any affine frame) overlap with area: touching at a
// point or along an edge does not count.
bool triangles_overlap(const Vec2 a[3], const Vec2 b[3]);

// The image of surface triangle `tri` developed across the base edges it overlaps, breadth first
// from its own chart, each base triangle once: calls fn(base triangle, image corners in that
// triangle's chart) for every base triangle the image overlaps with area. Returns false (calling
// nothing) if the image has no chart. An image with a corner at a base vertex touches every
// triangle round it, and developed round the cone the far ones would be wrong copies: only
// overlaps with area continue the development.
bool develop_image(const Parameterization& param, const uint32_t tri[3],
                   const std::function<void(uint32_t base, const Vec2 image[3])>& fn);

struct DomainOptions {
    // Base triangles to simplify to (the simplification may stop above it: each closed
    // component keeps at least 4, and every handle needs more); 0 chooses from the size.
    size_t target_triangles = 0;
    // Sweeps of parameter smoothing after simplification (each moves every free vertex towards
    // the mean-value centre of its neighbours when that flips nothing).
    int smoothing_sweeps = 4;
    // Surfaces of at least this many vertices are first simplified in two halves at once, one a
    // core (the result does not depend on the threads; the whole then finishes it). Smaller ones
    // convert in a second or two anyway, and the band between the halves weighs more there (the
    // bunny's distortion at the 99th percentile grew by a third).
    size_t halves_min_vertices = 100000;
    // When the map is not bijective, build it again this many times with another domain size:
    // 1.3x the base triangles after folds (they are what more base triangles cure), 0.77x after
    // charts too small for their input triangles. The simplification's order changes with the
    // target, and a fold left by one order (one triangle in millions on a 2.3M-triangle scan)
    // is rarely left by another. The converter allows 3 when it chose the size.
    int retries = 0;
};

// The default number of base triangles for a surface of `triangles` triangles.
size_t default_domain_triangles(size_t triangles);

// Distortion of the map from surface triangles to their images, with the domain scaled to the
// surface's area: per triangle the singular values s1 >= s2 of the affine map; angle distortion
// s1 / s2 (1: conformal), area distortion s1 s2 (1: area preserving).
struct ParamCheck {
    size_t triangles = 0;
    size_t flipped = 0;          // image with negative signed area
    size_t degenerate = 0;       // image with zero area
    size_t unfold_failures = 0;  // vertices in base triangles too far apart to share a chart
    size_t wrapped = 0;          // image not the same in its vertices' charts (it wraps a cone point)
    size_t bad_points = 0;       // barycentric coordinates negative, not summing to 1, or a bad triangle
    size_t base_vertices_off_corner = 0;  // a base vertex's point is not its corner
    double image_area = 0, domain_area = 0;  // in domain units (equilateral triangles of side 1)
    double angle_distortion_mean = 0, angle_distortion_max = 0;  // area-weighted mean
    double area_distortion_mean = 0, area_distortion_max = 0;    // max of max(s1 s2, 1 / (s1 s2))
    // The values 99% of the surface's area stays within (an area-weighted percentile).
    double angle_distortion_p99 = 0, area_distortion_p99 = 0;
    std::vector<uint32_t> worst_triangles;  // the 16 with the largest angle distortion, worst first
    bool bijective() const;
    // Surface vertices of the flipped, degenerate and wrapped triangles (for diagnosis).
    std::vector<uint32_t> bad_vertices;
    std::string describe() const;  // one line
};

struct DomainReport {
    size_t target_triangles = 0;
    size_t base_vertices = 0, base_triangles = 0, base_border_edges = 0;
    size_t collapses = 0;
    size_t rejected_collapses = 0;  // candidate collapses refused (flips, topology)
    size_t half_collapses = 0;      // of the collapses, those the two halves did at once
    double seconds_simplify = 0, seconds_smooth = 0;
    ParamCheck check;  // of the result
    // Every domain size tried before the one that gave the result, and why it was refused.
    std::vector<std::pair<size_t, std::string>> refused;
};

// Simplifies `surface` (an oriented two-manifold: aqp/clean.h) to a base domain and gives every
// vertex its DomainPoint. Throws Error when the surface cannot be simplified to within twice the
// target (handles of genus too high for the domain size, or a collapse-resistant shape), or
// when the resulting map is not bijective. `progress`, if given, counts collapses.
Parameterization build_parameterization(const Mesh& surface, const DomainOptions& options, DomainReport* report,
                                        Progress* progress = nullptr);

ParamCheck check_parameterization(const Mesh& surface, const Parameterization& param);

}  // namespace catpaq::aqp
