// Stitched patch edges (aqp_client/stitch.h), on the CPU: what the vertex shader does, for the
// drawn geometry and the tests.
#include "aqp_client/stitch.h"

namespace catpaq {

namespace {

// t snapped to the nearest multiple of 2^shift (ties up): floor((t + half) / step) * step.
int snap(int t, int shift) {
    if (shift <= 0) return t;
    const int step = 1 << shift;
    return ((t + step / 2) >> shift) << shift;
}

}  // namespace

std::array<int, 2> snap_sample(int i, int j, int level, const std::array<int, 4>& edge_level) {
    const int last = 1 << level;
    if (j == 0) i = snap(i, level - edge_level[0]);
    else if (j == last) i = snap(i, level - edge_level[2]);
    if (i == last) j = snap(j, level - edge_level[1]);
    else if (i == 0) j = snap(j, level - edge_level[3]);
    return {i, j};
}

std::vector<uint32_t> grid_triangles(int level) {
    const uint32_t size = (1u << level) + 1;
    std::vector<uint32_t> out;
    out.reserve(size_t(size - 1) * (size - 1) * 6);
    for (uint32_t j = 0; j + 1 < size; ++j)
        for (uint32_t i = 0; i + 1 < size; ++i) {
            const uint32_t a = j * size + i, b = a + 1, c = a + size + 1, d = a + size;
            out.insert(out.end(), {a, b, c, a, c, d});
        }
    return out;
}

std::vector<uint32_t> stitched_triangles(int level, const std::array<int, 4>& edge_level) {
    const int size = (1 << level) + 1;
    std::vector<uint32_t> out = grid_triangles(level);
    for (uint32_t& v : out) {
        const std::array<int, 2> s = snap_sample(int(v) % size, int(v) / size, level, edge_level);
        v = uint32_t(s[1] * size + s[0]);
    }
    size_t kept = 0;
    for (size_t t = 0; t + 2 < out.size(); t += 3) {
        const uint32_t a = out[t], b = out[t + 1], c = out[t + 2];
        if (a == b || b == c || a == c) continue;
        out[kept++] = a, out[kept++] = b, out[kept++] = c;
    }
    out.resize(kept);
    return out;
}

}  // namespace catpaq
