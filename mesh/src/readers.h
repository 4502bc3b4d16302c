#pragma once
// Private to the mesh module: one reader per format (each in its own .cpp) and the small rules
// they share. The readers return the file's content; read_mesh adds validation and the
// empty-mesh check on top.
#include <cmath>
#include <string>
#include <vector>

#include "mesh/mesh.h"

namespace catpaq::mesh_io {

// `dropped` receives what the file holds and the mesh cannot (see read_mesh).
Mesh read_ply(const std::string& path, std::vector<std::string>& dropped);
Mesh read_obj(const std::string& path, std::vector<std::string>& dropped);
Mesh read_off(const std::string& path);
Mesh read_stl(const std::string& path);

// A file normal as a unit Vec3f. Normals already unit length (within float rounding) keep their
// exact bits so write/read round trips are exact; others are normalised, and zero ones become
// +z (the convention of compute_vertex_normals). The caller has checked finiteness.
inline Vec3f unit_normal(double x, double y, double z) {
    double length2 = x * x + y * y + z * z;
    if (std::fabs(length2 - 1.0) <= 1e-6) return {float(x), float(y), float(z)};
    if (!(length2 > 1e-300)) return {0.0f, 0.0f, 1.0f};
    double length = std::sqrt(length2);
    return {float(x / length), float(y / length), float(z / length)};
}

// A colour channel given as a float in [0, 1] (OBJ, PLY float colours, OFF float colours).
inline uint8_t unit_to_byte(double v) {
    if (v <= 0.0) return 0;
    if (v >= 1.0) return 255;
    return uint8_t(std::floor(v * 255.0 + 0.5));
}

// Reserves room for `n` elements and asks the kernel to back the (fresh, untouched) buffer with
// transparent huge pages where it allows them: one first-touch page fault per 4 KB costs more
// than parsing the data (measured: half of binary PLY reading time in a VM).
void advise_huge_pages(void* data, size_t bytes);
template <class T>
void reserve_huge(std::vector<T>& v, size_t n) {
    v.reserve(n);
    advise_huge_pages(v.data(), n * sizeof(T));
}

// Appends one triangle. (push_back beats insert({a, b, c}), which memmoves 12 bytes per call:
// that alone cost a tenth of binary PLY reading time.)
inline void push_triangle(std::vector<uint32_t>& indices, uint32_t a, uint32_t b, uint32_t c) {
    indices.push_back(a);
    indices.push_back(b);
    indices.push_back(c);
}

inline bool finite3(double x, double y, double z) {
    return std::isfinite(x) && std::isfinite(y) && std::isfinite(z);
}

}  // namespace catpaq::mesh_io
