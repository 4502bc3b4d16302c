#pragma once
// Which world axis points up, as every dataset format records it for viewers (from the input's
// convention or `convert --up`); the numbering is the one stored in CATP, AQP and point metadata.
#include <array>
#include <cstdint>
#include <string>

namespace catpaq {

enum class UpAxis : uint8_t { Unknown = 0, PosX, PosY, PosZ, NegX, NegY, NegZ };
// "x", "y", "z", "-x", "-y", "-z" (or "" for Unknown); parse returns false on anything else.
const char* up_axis_name(UpAxis axis);
bool parse_up_axis(const std::string& text, UpAxis& out);
// The unit vector of an axis (+z for Unknown).
std::array<double, 3> up_axis_vector(UpAxis axis);
// A stored code (0-6) as an UpAxis; Unknown for anything else.
inline UpAxis up_axis_from_code(unsigned code) { return code <= uint8_t(UpAxis::NegZ) ? UpAxis(code) : UpAxis::Unknown; }
// The axis as viewers take it (client/format.h, DatasetFormat::up_axis): 1 (y), 2 (z), 0 none.
inline int viewer_up_axis(UpAxis axis) {
    if (axis == UpAxis::PosY || axis == UpAxis::NegY) return 1;
    if (axis == UpAxis::PosZ || axis == UpAxis::NegZ) return 2;
    return 0;
}
// What `info` says of it.
inline std::string up_axis_summary(UpAxis axis) {
    return axis == UpAxis::Unknown ? "not recorded (z assumed)" : up_axis_name(axis);
}

}  // namespace catpaq
