// Up axes (mesh/up_axis.h).
#include "mesh/up_axis.h"

namespace catpaq {

const char* up_axis_name(UpAxis axis) {
    static const char* const kNames[] = {"", "x", "y", "z", "-x", "-y", "-z"};
    return uint8_t(axis) <= uint8_t(UpAxis::NegZ) ? kNames[uint8_t(axis)] : "";
}

bool parse_up_axis(const std::string& text, UpAxis& out) {
    for (uint8_t a = uint8_t(UpAxis::PosX); a <= uint8_t(UpAxis::NegZ); ++a)
        if (text == up_axis_name(UpAxis(a)) || (text.size() == 2 && text[0] == '+' && text.substr(1) == up_axis_name(UpAxis(a)))) {
            out = UpAxis(a);
            return true;
        }
    return false;
}

std::array<double, 3> up_axis_vector(UpAxis axis) {
    switch (axis) {
        case UpAxis::PosX: return {1, 0, 0};
        case UpAxis::PosY: return {0, 1, 0};
        case UpAxis::NegX: return {-1, 0, 0};
        case UpAxis::NegY: return {0, -1, 0};
        case UpAxis::NegZ: return {0, 0, -1};
        default: return {0, 0, 1};
    }
}

}  // namespace catpaq
