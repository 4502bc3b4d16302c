#pragma once
// Barycentric vertex positions: a point in a tetrahedron as four integer weights on a grid.
//
// The four corners of a tetrahedron are integer lattice points (see catp/lattice.h). They are
// always taken in *canonical order*: sorted lexicographically by (x, y, z). A position is four
// non-negative integer weights w0..w3 with w0 + w1 + w2 + w3 = G, the dataset's *grid* (463 in
// the 24-bit vertex layout, up to 16383 in the 48-bit one, see packed_vertex.h), and it is
//     p = (w0*C0 + w1*C1 + w2*C2 + w3*C3) / G.
// It is decoded relative to an integer anchor A near the camera (so that nearby positions keep
// their precision in floats), from the corners' offsets Di = Ci - A, in two integer sums: with
// wi = 128 hi_i + lo_i, Sh = sum hi_i*Di and Sl = sum lo_i*Di (both exact in 32-bit signed
// integers for |Di| <= 2^20 and G < 2^14), then p - A = (float(Sh) * 128 + float(Sl)) * (1 / G),
// and times the lattice cell for world units. Two tetrahedra that decode the same weights for
// the same corners therefore run the same operations on the same values and produce
// bit-identical positions, whatever their other corners are (a zero weight adds exactly zero).
//
// The face rule (what makes cuts crack-free): a point on a face, edge or corner of the
// tetrahedron gets exactly zero weight for every corner outside that face (edge, corner), and
// the weights of the remaining corners are computed from those corners alone, in their canonical
// order. The caller states the support (which corners may carry weight), decided by exact
// predicates or by construction; this module never guesses it with a tolerance.
//
// Packing (24- and 30-bit layouts): the weights (w1, w2, w3) are mapped to a single index by the
// tetrahedral-number enumeration (w0 implied), which holds a grid of up to 463 steps per edge in
// 24 bits (versus 255 with three 8-bit weights: 1.8x finer for the same 3 bytes), and of 1858
// steps in 30 bits. The enumeration does not depend on the grid: a smaller grid uses the first
// indices.
#include <array>
#include <cstdint>

namespace catpaq {

constexpr int kBaryGrid = 463;            // the largest grid of the 24-bit enumeration
constexpr int32_t kMaxIndexGrid = 1858;   // the largest grid of the 30-bit enumeration
constexpr int32_t kMaxWideGrid = 16383;   // the largest grid of the 48-bit layout (weights < 2^14)
constexpr uint32_t kBaryIndexCount =
    uint32_t((kBaryGrid + 1)) * (kBaryGrid + 2) * (kBaryGrid + 3) / 6;  // 16,757,360 < 2^24
static_assert(kBaryIndexCount <= (1u << 24), "barycentric index must fit 24 bits");

using BaryWeights = std::array<int32_t, 4>;  // w0..w3 for canonical corners C0..C3
using LatticePoint = std::array<int32_t, 3>;

// Number of valid indices for a grid of `grid` <= kMaxIndexGrid steps (Tet(grid + 1)).
constexpr uint32_t bary_index_count(int32_t grid) {
    return uint32_t(uint64_t(grid + 1) * uint64_t(grid + 2) * uint64_t(grid + 3) / 6);
}
// Packs (w1, w2, w3) of valid weights (all >= 0, summing to a grid of at most kMaxIndexGrid)
// into the index.
uint32_t bary_pack(const BaryWeights& w);
// Unpacks an index for a grid of at most kMaxIndexGrid steps; returns false for an index
// >= bary_index_count(grid) (corrupt data).
bool bary_unpack(uint32_t index, int32_t grid, BaryWeights& w);

// Support of a point: bit i set means canonical corner Ci may carry weight. A point strictly
// inside has all four bits; on a face three; on an edge two; at a corner one.
using SupportMask = uint8_t;

// Quantizes point p (lattice coordinates, double) in the tetrahedron with canonical corners c
// to weights summing to `grid`, with zero weight outside `support`. Weights of the supporting
// corners are the barycentric coordinates of p in the simplex they span (computed from those
// corners only), rounded to integers summing to `grid` by largest remainder (ties to the lower
// corner index). Coordinates outside [0, 1] (p slightly outside the simplex) are clamped first.
BaryWeights bary_quantize(const double p[3], const std::array<LatticePoint, 4>& c, SupportMask support,
                          int32_t grid = kBaryGrid);

// The exact integer sum S = sum wi*Ci (grid times the lattice position): identical integers
// mean bit-identical decoded positions.
std::array<int64_t, 3> bary_integer_sum(const BaryWeights& w, const std::array<LatticePoint, 4>& c);

// CPU mirror of the vertex shader's position decode (see the top of this file): `offsets` are the
// canonical corners minus the anchor (|coordinates| <= 2^20), `scale` is the lattice cell in the
// rendering frame divided by the grid. Weights must sum to at most kMaxWideGrid.
void bary_decode(const BaryWeights& w, const std::array<LatticePoint, 4>& offsets, float scale, float out[3]);

// Sorts four corners into canonical order; returns the permutation applied (perm[i] = old index).
std::array<int, 4> canonical_order(std::array<LatticePoint, 4>& corners);

}  // namespace catpaq
