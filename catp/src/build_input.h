#pragma once
// The converter's input, read as a stream (private to the catp module): all vertices once, then
// the triangles, as often as needed (a second pass computes normals when the file has none).
// A PLY file is streamed from disk in chunks, so the converter never holds the input; other
// formats, and meshes already in memory, are served from a Mesh.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "mesh/mesh.h"

namespace catpaq {

class BuildInput {
public:
    virtual ~BuildInput() = default;
    virtual std::string name() const = 0;
    virtual uint64_t vertex_count() const = 0;
    // Number of triangles, exact or estimated: a PLY file declares polygons, so its input reads the
    // first faces to learn how many triangles a polygon makes. Call after the vertices are read.
    virtual uint64_t triangle_estimate() = 0;
    virtual bool has_normals() const = 0;
    virtual bool has_colors() const = 0;
    // Appends up to `max` further vertices (normals / colours only when offered and requested).
    // Returns the number read; 0 once all are read. Called only before the first triangle pass.
    virtual size_t read_vertices(size_t max, std::vector<Vec3d>& positions, std::vector<Vec3f>* normals,
                                 std::vector<Rgb8>* colors) = 0;
    // Starts a pass over the triangles (from the first one).
    virtual void rewind_triangles() = 0;
    // Appends the corner indices of up to about `max` further triangles; returns the number of
    // triangles appended, 0 at the end of the pass. Indices are checked to be in range.
    virtual size_t read_triangles(size_t max, std::vector<uint32_t>& indices) = 0;
    // After the last pass: checks that the file holds nothing beyond what its header declares.
    virtual void finish() = 0;
    // What the file holds that the converter cannot keep (read_mesh's `dropped`), one sentence
    // per kind.
    virtual std::vector<std::string> dropped() const { return {}; }
};

// Serves a mesh in memory (which must pass validate_mesh); the mesh must outlive the input.
std::unique_ptr<BuildInput> mesh_build_input(const Mesh& mesh, std::string name = "mesh");
// Streams a PLY file; reads other formats (OBJ, OFF, STL) whole with read_mesh.
std::unique_ptr<BuildInput> file_build_input(const std::string& path);

}  // namespace catpaq
