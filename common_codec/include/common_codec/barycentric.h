#pragma once
// Barycentric vertex positions: a point in a tetrahedron as four integer weights on a fixed grid.
//
// The four corners of a tetrahedron are integer lattice points (see catp/lattice.h). They are
// always taken in *canonical order*: sorted lexicographically by (x, y, z). A position is four
// non-negative integer weights w0..w3 with w0 + w1 + w2 + w3 = kBaryGrid, and it decodes to
//     p = (w0*C0 + w1*C1 + w2*C2 + w3*C3) / kBaryGrid
// evaluated in *integer* arithmetic (the sum S = sum wi*Ci is exact in 32-bit signed integers for
// lattice coordinates below 2^22), then converted to float once. Two tetrahedra that decode the
// same weights for the same corners therefore produce bit-identical positions, whatever their
// other corners are.
//
// The face rule (what makes cuts crack-free): a point on a face, edge or corner of the
// tetrahedron gets exactly zero weight for every corner outside that face (edge, corner), and
// the weights of the remaining corners are computed from those corners alone, in their canonical
// order. The caller states the support (which corners may carry weight), decided by exact
// predicates or by construction; this module never guesses it with a tolerance.
//
// Packing: the weights (w1, w2, w3) are mapped to a single index in [0, kBaryIndexCount) by the
// tetrahedral-number enumeration (w0 implied), which uses 24 bits with a grid of 463 steps per
// edge (versus 255 with three 8-bit weights): 1.8x finer for the same 3 bytes.
#include <array>
#include <cstdint>

namespace catpaq {

constexpr int kBaryGrid = 463;  // weights sum to this
constexpr uint32_t kBaryIndexCount =
    uint32_t((kBaryGrid + 1)) * (kBaryGrid + 2) * (kBaryGrid + 3) / 6;  // 16,757,360 < 2^24
static_assert(kBaryIndexCount <= (1u << 24), "barycentric index must fit 24 bits");

using BaryWeights = std::array<int32_t, 4>;  // w0..w3 for canonical corners C0..C3
using LatticePoint = std::array<int32_t, 3>;

// Packs (w1, w2, w3) of valid weights (all >= 0, sum == kBaryGrid) into the 24-bit index.
uint32_t bary_pack(const BaryWeights& w);
// Unpacks a 24-bit index; returns false for an index >= kBaryIndexCount (corrupt data).
bool bary_unpack(uint32_t index, BaryWeights& w);

// Support of a point: bit i set means canonical corner Ci may carry weight. A point strictly
// inside has all four bits; on a face three; on an edge two; at a corner one.
using SupportMask = uint8_t;

// Quantizes point p (lattice coordinates, double) in the tetrahedron with canonical corners c
// to weights, with zero weight outside `support`. Weights of the supporting corners are the
// barycentric coordinates of p in the simplex they span (computed from those corners only),
// rounded to integers summing to kBaryGrid by largest remainder (ties to the lower corner index).
// Coordinates outside [0, 1] (p slightly outside the simplex) are clamped first.
BaryWeights bary_quantize(const double p[3], const std::array<LatticePoint, 4>& c, SupportMask support);

// Exact integer sum S = sum wi*Ci minus an anchor (anchor is kBaryGrid times a lattice point,
// so it stays exact); the shader computes the same integers.
std::array<int32_t, 3> bary_weighted_sum(const BaryWeights& w, const std::array<LatticePoint, 4>& c,
                                         const std::array<int32_t, 3>& anchor_times_grid);

// CPU mirror of the vertex shader's position decode: float(S) * scale, where scale is the
// lattice cell size in the rendering frame divided by kBaryGrid.
void bary_decode(const BaryWeights& w, const std::array<LatticePoint, 4>& c,
                 const std::array<int32_t, 3>& anchor_times_grid, float scale, float out[3]);

// Sorts four corners into canonical order; returns the permutation applied (perm[i] = old index).
std::array<int, 4> canonical_order(std::array<LatticePoint, 4>& corners);

}  // namespace catpaq
