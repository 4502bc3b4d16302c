#pragma once
// Private to the points module: the splat the converter works with, and the simplifier that
// turns two children's splats into their parent's (seed 002 section 3.2: merging by proximity).
#include <cstddef>
#include <cstdint>
#include <vector>

namespace catpaq::points_detail {

struct Splat {
    double p[3];      // centre, relative to the dataset origin
    float n[3];       // unit normal
    float color[3];   // RGB 0..255 (averaged, so fractional)
    float radius;     // splat radius: covers the splats it was merged from
    float cover;      // bound of the distance from every input point it stands for to p
    float weight;     // area it stands for (pi r^2 at the leaves, summed by merges)
};

// The smallest ball that holds the balls (a, radius a) and (b, radius b) of two splats, as the
// merged splat: area-weighted normal and colour, summed weight, and its cover grown by how far
// the centre moved. Returns it.
Splat merge_splats(const Splat& a, const Splat& b);

// Reduces `splats` to `target` (>= 1) by repeatedly merging the pair, among each splat's four
// nearest, whose merged splat is smallest (a pair whose normals face away from each
// other costs four times its radius: the two sides of a thin wall are merged last). Splats
// keep their order otherwise. Deterministic.
void simplify_splats(std::vector<Splat>& splats, size_t target);

}  // namespace catpaq::points_detail
