#pragma once
// The quad patches of AQP over a base domain (aqp/domain.h), as in the paper: one quad vertex at
// every base triangle's barycentre, one quad per base edge joining the barycentres of the two
// triangles beside the edge and the edge's two ends. A border edge has one triangle: its quad's
// fourth corner is the edge's midpoint (the quad covers a third of that triangle).
//
// Patch p of base edge (a, b), with T1 the triangle running a -> b and T2 the one running b -> a:
//
//      grid (0,N) = b  ------ edge 2 ------  (N,N) = c2 (T2's barycentre, or the midpoint of ab)
//            |                                   |
//          edge 3                              edge 1          u = i / N to the right,
//            |                                   |             v = j / N upwards:
//      grid (0,0) = c1 ----- edge 0 ------  (N,0) = a          counter-clockwise seen from outside
//
// Edges run counter-clockwise: 0 c1->a, 1 a->c2, 2 c2->b, 3 b->c1. The base edge ab is the
// diagonal from (N,0) to (0,N); below it (u + v <= 1) the patch lies in T1, above it in T2, and
// the map from the unit square to the domain is affine on each side (and on the whole square:
// the two equilateral halves form a 60/120 degree rhombus). In the domain a grid cell is a small
// rhombus whose short diagonal runs from (i,j) to (i+1,j+1): split along it, the grid's
// triangles are equilateral in the domain. A border patch maps the square bilinearly onto
// (c1, a, midpoint, b).
//
// Every edge of a patch joins a barycentre (or midpoint) to a base vertex. Patch edges between a
// barycentre and a base vertex ("spokes") are shared by exactly two patches, which run them in
// opposite directions; the halves of a border edge belong to one patch.
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "aqp/domain.h"

namespace catpaq::aqp {

struct PatchLink {
    uint32_t patch = kNone;  // the patch across the edge, kNone on the surface's border
    uint8_t edge = 0;        // the same edge's index in that patch
    bool reversed = true;    // runs the edge the other way (always, for a consistently oriented domain)
};

struct QuadPatch {
    std::array<uint32_t, 2> triangle{kNone, kNone};  // T1 and T2 (kNone: a border edge's patch)
    std::array<uint8_t, 2> edge{0, 0};               // index of the base edge in T1 and in T2
    // Quad vertex ids of the corners (0,0), (N,0), (N,N), (0,N): ids below the base vertex count
    // are base vertices, then come the base triangles' barycentres, then border edges' midpoints.
    std::array<uint32_t, 4> corner{};
    std::array<PatchLink, 4> link;
    bool border() const { return triangle[1] == kNone; }
};

class QuadLayout {
public:
    explicit QuadLayout(const BaseDomain& domain);

    const BaseDomain& domain() const { return *domain_; }
    const std::vector<QuadPatch>& patches() const { return patches_; }
    size_t patch_count() const { return patches_.size(); }
    size_t quad_vertex_count() const { return domain_->vertex_count() + domain_->triangle_count() + border_edges_; }
    size_t border_edges() const { return border_edges_; }

    // The patch of edge k of base triangle t (covering the third of t beside that edge).
    uint32_t patch_of_edge(uint32_t t, int k) const { return patch_of_edge_[t][k]; }
    // The domain point at (u, v) in [0,1]^2 of patch p.
    DomainPoint point(uint32_t p, double u, double v) const;
    // The patch holding domain point x and x's (u, v) in it (the inverse of point()).
    void locate(const DomainPoint& x, uint32_t& patch, double& u, double& v) const;

private:
    const BaseDomain* domain_;
    std::vector<QuadPatch> patches_;
    std::vector<std::array<uint32_t, 3>> patch_of_edge_;  // per base triangle and edge
    size_t border_edges_ = 0;
};

// Global numbering of the samples of every patch at the finest level N = 2^k, each sample shared
// by several patches (corners, edges) numbered once: the converter evaluates, quantizes and
// encodes each number once, and every patch showing it copies the same bits.
class SampleNumbering {
public:
    SampleNumbering(const QuadLayout& layout, int k);

    int level() const { return k_; }
    int size() const { return n_ + 1; }  // samples per side at the finest level
    size_t sample_count() const { return total_; }
    // The sample at grid position (i, j), 0 <= i, j <= N, of patch p.
    uint32_t id(uint32_t p, int i, int j) const;
    // Quad vertex number of a corner sample, or kNone if `sample` is not a quad vertex.
    uint32_t quad_vertex(uint32_t sample) const { return sample < corners_ ? sample : kNone; }

private:
    struct EdgeRun {
        uint32_t first;  // id of the run's sample 1 (the one next to the run's start)
        bool reversed;   // the patch edge walks the run backwards
    };
    const QuadLayout* layout_;
    int k_, n_;
    size_t corners_, total_;
    std::vector<std::array<EdgeRun, 4>> edge_runs_;  // per patch and edge
    std::vector<uint32_t> interior_first_;           // per patch
};

}  // namespace catpaq::aqp
