#pragma once
// An indexed triangle mesh in memory: positions in double precision (scans are often in
// projected coordinates around 1e6, where float loses millimetres), optional per-vertex normals
// and colours, and three vertex indices per triangle.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace catpaq {

using Vec3d = std::array<double, 3>;
using Vec3f = std::array<float, 3>;
using Rgb8 = std::array<uint8_t, 3>;

struct Bounds {
    Vec3d min{1e300, 1e300, 1e300};
    Vec3d max{-1e300, -1e300, -1e300};
    bool empty() const { return min[0] > max[0]; }
    void add(const Vec3d& p) {
        for (int i = 0; i < 3; ++i) {
            if (p[i] < min[i]) min[i] = p[i];
            if (p[i] > max[i]) max[i] = p[i];
        }
    }
    double diagonal() const;
};

struct Mesh {
    std::vector<Vec3d> positions;
    std::vector<Vec3f> normals;  // empty, or one unit normal per vertex
    std::vector<Rgb8> colors;    // empty, or one colour per vertex
    std::vector<uint32_t> indices;  // 3 per triangle

    size_t vertex_count() const { return positions.size(); }
    size_t triangle_count() const { return indices.size() / 3; }
    bool has_normals() const { return !normals.empty(); }
    bool has_colors() const { return !colors.empty(); }
    Bounds bounds() const;
};

// Checks the invariants a reader guarantees: every coordinate finite, every index in range,
// attribute arrays empty or sized like positions. Throws Error naming `what` on the first problem.
void validate_mesh(const Mesh& mesh, const std::string& what);

// Area-weighted vertex normals (unit length; vertices with no area get +z).
std::vector<Vec3f> compute_vertex_normals(const Mesh& mesh);

// Counts edges used by exactly one triangle (undirected, by vertex index).
size_t count_border_edges(const std::vector<uint32_t>& indices);

// Edge usage statistics over undirected edges (by vertex index), as count_border_edges counts
// them: a triangle's edges are its three corner pairs, skipping pairs of equal indices, so the
// degenerate (a,a,b) uses edge a-b twice and (a,a,a) uses none.
struct EdgeCounts {
    size_t edges = 0;        // distinct undirected edges
    size_t border = 0;       // used by exactly one triangle
    size_t manifold = 0;     // used by exactly two triangles
    size_t nonmanifold = 0;  // used by three or more triangles
    size_t misoriented = 0;  // used by two triangles that traverse it in the same direction
};
EdgeCounts count_edges(const std::vector<uint32_t>& indices);

}  // namespace catpaq
