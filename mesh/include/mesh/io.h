#pragma once
// Mesh files: read_mesh for the four common formats, write_ply, and PlyStream, the chunked PLY
// reader the out-of-core converter uses on files larger than memory.
//
// Every reader throws catpaq::Error on bad input, with a message naming the file, the problem
// and (for text formats) the line: missing file, unknown format, malformed header, truncated
// data, counts that disagree with the data, non-finite coordinates, indices out of range,
// faces with fewer than three vertices. Nothing is silently repaired except what is documented:
// polygons are fan-triangulated, STL corners are welded, file normals that are not unit
// length are normalised (zero normals become +z, as in compute_vertex_normals). Content a Mesh
// cannot hold is not dropped silently: read_mesh and PlyStream report it (`dropped`).
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "mesh/mesh.h"

namespace catpaq {

// Reads a PLY, OBJ, OFF or STL file. The format is chosen by extension (case-insensitive)
// or, for other extensions, by sniffing the first bytes. The result passes validate_mesh and
// has at least one triangle. Normals and colours are kept when the file has them for every
// vertex; OBJ normals given per face corner ("vn" with indices of their own) become per-vertex
// normals (the corners' normals averaged; vertices without any get area-weighted ones).
// `dropped`, if given, receives one sentence per kind of content the mesh cannot hold and the
// reader left out (OBJ texture coordinates, materials, lines; PLY face colours, other
// properties and elements; ...), for the tools to warn about.
Mesh read_mesh(const std::string& path, std::vector<std::string>* dropped = nullptr);

// Writes `mesh` (which must pass validate_mesh) as PLY: binary little-endian or ascii. Positions
// are float, or double when any |coordinate| > 1e5 (projected scan coordinates); normals
// (float) and colours (uchar) are written when present. Faces are "list uchar int
// vertex_indices". The file appears atomically (AtomicFile): readers never see a partial file.
void write_ply(const std::string& path, const Mesh& mesh, bool binary = true);

// Streams the vertex and face elements of a PLY file (ascii, binary_little_endian or
// binary_big_endian) in chunks, holding only a buffer in memory. Other elements and unknown
// properties are skipped. Calls follow file order: read_vertices until it returns 0, then
// read_faces until it returns 0, then finish() to check the file ends where the header says.
// (Files whose face element precedes the vertex element are rejected at open.)
class PlyStream {
public:
    // Opens the file and parses the header; throws Error if either fails. The file must declare
    // a vertex element with x, y, z.
    explicit PlyStream(const std::string& path);
    ~PlyStream();
    PlyStream(const PlyStream&) = delete;
    PlyStream& operator=(const PlyStream&) = delete;

    uint64_t vertex_count() const;
    uint64_t face_count() const;  // polygons as declared; 0 when there is no face element
    bool has_normals() const;     // nx, ny, nz present
    bool has_colors() const;      // red, green, blue present
    bool has_radii() const;       // a splat radius: 'radius' (or 'scale') present; point clouds only
    // What the header declares that a Mesh cannot hold and the reader skips (face colours, other
    // properties and elements), one sentence per kind. A radius property counts as skipped
    // unless `keeps_radii` (a point-cloud reader that asks for radii).
    std::vector<std::string> dropped(bool keeps_radii = false) const;

    // Reads up to `max` further vertices and appends them to `positions` (and to `normals` and
    // `colors`, `radii` when those are non-null; they must then be offered by the file). Returns
    // the number read, 0 once all vertices are read. Throws on truncation, non-finite values and
    // negative radii.
    size_t read_vertices(size_t max, std::vector<Vec3d>& positions, std::vector<Vec3f>* normals,
                         std::vector<Rgb8>* colors, std::vector<float>* radii = nullptr);

    // Reads up to `max` further faces (polygons) and appends 3 indices per triangle to
    // `indices`, fan-triangulating polygons (n corners give n - 2 triangles). Returns the number
    // of faces read, 0 once all are read. Skips unread vertices. Throws on truncation, indices
    // out of range and faces with fewer than three vertices.
    size_t read_faces(size_t max, std::vector<uint32_t>& indices);

    // Skips whatever is left and checks that nothing but whitespace follows the last element
    // (otherwise the counts in the header do not match the data). Throws Error on mismatch.
    void finish();

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace catpaq
