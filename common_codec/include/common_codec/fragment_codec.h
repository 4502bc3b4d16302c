#pragma once
// The lossless fragment codec for disk and network.
//
// A fragment is the part of the surface inside one tetrahedron: a list of 64-bit vertices
// (common_codec/packed_vertex.h) of one vertex layout and triangles indexing them. The codec is
// lossless up to a permutation of the vertices, a permutation of the triangles, and a rotation
// of each triangle's corners (orientation is kept). Layout of an encoded fragment (all
// little-endian):
//
//   u32 magic 'CFRG' | u8 version | u8 vertex layout | u16 grid (0: 463) | u32 vertex_count |
//   u32 triangle_count | u64 checksum (XXH3 of everything after this field) | payload
//
// API in the style of meshoptimizer: the caller owns the output, encoders have a bound(), and
// the decoder returns an error code on bad bytes. The decoder is safe on untrusted input: it
// never reads or writes out of bounds and never loops unboundedly, whatever the bytes.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "common_codec/packed_vertex.h"

namespace catpaq {

struct FragmentMesh {
    VertexLayout layout;  // how the vertices are packed (the dataset's)
    std::vector<PackedVertex> vertices;
    std::vector<uint32_t> indices;  // 3 per triangle, each < vertices.size()

    size_t triangle_count() const { return indices.size() / 3; }
};

enum class FragmentStatus {
    Ok = 0,
    Truncated,         // fewer bytes than the header or the payload needs
    BadMagic,          // not a fragment
    UnsupportedVersion,
    ChecksumMismatch,  // bytes changed in storage or transit
    Corrupt,           // checksum matched but the payload is inconsistent
    TooLarge,          // counts above the limits below
};
const char* fragment_status_name(FragmentStatus status);

// Bitstream versions: the encoder writes kFragmentVersion unless told otherwise, the decoder
// reads every version from kFragmentOldestVersion on (docs/formats/fragment.md).
constexpr int kFragmentVersion = 2;
constexpr int kFragmentOldestVersion = 1;

constexpr uint32_t kFragmentMaxVertices = 1u << 22;
constexpr uint32_t kFragmentMaxTriangles = 1u << 23;

// Upper bound of the encoded size, for sizing output buffers.
size_t fragment_encode_bound(size_t vertex_count, size_t triangle_count);

// Reads the header only: counts, for sizing before decoding. Checks magic, version, layout and
// sizes, not the checksum.
FragmentStatus fragment_peek(const uint8_t* data, size_t size, uint32_t& vertex_count, uint32_t& triangle_count);
// The vertex layout a fragment's header names (after fragment_peek returned Ok).
VertexLayout fragment_layout(const uint8_t* data);

// Decodes a fragment (verifying the checksum first) into `out` (previous contents replaced).
FragmentStatus fragment_decode(const uint8_t* data, size_t size, FragmentMesh& out);

// Per-stream sizes of the last encode, for reports (bits per vertex by component).
struct FragmentEncodeStats {
    size_t header_bytes = 0, connectivity_bytes = 0, position_bytes = 0, normal_bytes = 0, color_bytes = 0;
};
// Encodes `mesh` (indices must be in range and its layout valid; asserts otherwise) and appends
// to `out`, in bitstream `version` (kFragmentOldestVersion..kFragmentVersion; older versions for
// tests and comparisons: they decode to the same mesh, slower).
// Returns the number of bytes appended; fills `stats` when given.
size_t fragment_encode(const FragmentMesh& mesh, std::vector<uint8_t>& out, FragmentEncodeStats* stats = nullptr,
                       int version = kFragmentVersion);

}  // namespace catpaq
