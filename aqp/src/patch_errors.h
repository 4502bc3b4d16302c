#pragma once
// The error bound of every (patch, level) node: the largest distance between corresponding
// points of the level's surface (decoded samples, grid cells split along their (i,j)-(i+1,j+1)
// diagonal) and the input surface, over the patch. Both are piecewise linear over the patch's
// (u, v) square, so their difference is linear on every cell of the overlay of the two
// triangulations and peaks at an overlay vertex: a grid sample, an input vertex, or a point where
// an input edge crosses a grid line (u = i / 2^l, v = j / 2^l, or a cell diagonal u - v =
// m / 2^l). All three are evaluated, so the bound is the distance's supremum over the patch
// (quantization included: the level's surface is made of decoded positions). Then each level's
// bound becomes at least its finer level's (monotone).
//
// Every surface triangle whose image overlaps a patch (SurfaceMap's images of the patch's base
// triangles) contributes its three edges. One approximation, documented in docs/formats/aqp.md:
// in border patches (bilinear, not affine) an input edge is sampled every quarter of a finest
// cell instead of at its exact crossings.
#include <functional>
#include <vector>

#include "aqp/domain.h"
#include "aqp/quad_layout.h"
#include "aqp/surface_map.h"
#include "mesh/mesh.h"

namespace catpaq {
class Progress;
}

namespace catpaq::aqp {

// error[p][l] for every patch p and level 0..k. `exact` is each distinct finest sample's true
// surface position, `decoded(s)` its decoded world position.
std::vector<std::vector<double>> measure_patch_errors(const Mesh& surface, const Parameterization& param,
                                                      const QuadLayout& layout, const SurfaceMap& map,
                                                      const SampleNumbering& numbering,
                                                      const std::vector<Vec3d>& exact,
                                                      const std::function<Vec3d(uint32_t)>& decoded, Progress* progress);

}  // namespace catpaq::aqp
