#include "common_codec/packed_vertex.h"

#include "common_codec/octahedral.h"

namespace catpaq {

bool decode_packed_vertex(PackedVertex v, const std::array<LatticePoint, 4>& corners,
                          const std::array<int32_t, 3>& anchor_times_grid, float scale, DecodedVertex& out) {
    BaryWeights w;
    if (!bary_unpack(v.position_index(), w)) return false;
    bary_decode(w, corners, anchor_times_grid, scale, out.position);
    oct_decode(v.normal(), out.normal);
    out.color[0] = float(v.r()) / 255.0f;
    out.color[1] = float(v.g()) / 255.0f;
    out.color[2] = float(v.b()) / 255.0f;
    return true;
}

}  // namespace catpaq
