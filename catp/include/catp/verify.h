#pragma once
// `catpaq verify`: decodes a CATP dataset and checks its invariants; with the original mesh it
// also measures, per level, the distance between the level's surface and the original.
#include <cstdint>
#include <string>
#include <vector>

#include "common_codec/packed_vertex.h"
#include "mesh/mesh.h"

namespace catpaq {

struct VerifyLevel {
    int level = 0;
    size_t diamonds = 0, fragments = 0, triangles = 0;
    size_t vertices = 0;      // stored in the level's fragments (shared ones once per fragment)
    size_t cut_vertices = 0;  // of the uniform cut at this level, welded by exact position
    uint64_t bytes = 0;
    // Of the diamonds the level's uniform cut draws: the level's own and the leaves of coarser
    // levels (leaves follow the density), world units:
    double stored_error = 0;       // the largest stored error bound
    double quantization_step = 0;  // the largest tetrahedron edge / grid
    // Measured on the uniform cut at this level (every coarser diamond refined), world units:
    double distance_to_original_max = -1, distance_to_original_rms = -1;    // level -> original
    double distance_from_original_max = -1, distance_from_original_rms = -1;  // original -> level
    bool bound_exceeded = false;  // a measured maximum above stored_error
    // Border edges of the level's cut farther than stored_error + quantization_step from the
    // original's border (with the original only).
    size_t border_edges_off_original = 0;
};

struct VerifyReport {
    size_t nodes = 0, fragments = 0, triangles = 0;
    uint64_t file_bytes = 0;
    double diagonal = 0;  // of the stored bounds
    size_t checksum_failures = 0, corrupt_nodes = 0, monotonicity_violations = 0, bad_flags = 0;
    // Shared faces whose two sides end at different edges (cracks), and the edges where only one
    // side ends in a face: the input's own border lying in the face's plane, or missing geometry
    // (told apart by the border check with the original).
    size_t face_mismatches = 0, faces_checked = 0, face_border_edges = 0;
    // With the original: levels whose measured distance exceeds the stored bound, and border
    // edges of the cuts (uniform and mixed) that are not on the original's border.
    size_t bound_violations = 0, border_cracks = 0;
    bool border_checked = false;
    VertexLayout layout;   // of the dataset's vertices
    double precision = 0;  // the finest level's guaranteed distance to the input (world; 0: none recorded)
    double mean_edge = 0;  // of the input (world; 0: not recorded)
    // With the original: the finest level's measured distance (either direction) exceeds it.
    bool precision_exceeded = false;
    std::vector<VerifyLevel> levels;
    std::vector<std::string> problems;  // first few, human readable
    bool ok() const {
        return checksum_failures == 0 && corrupt_nodes == 0 && monotonicity_violations == 0 && bad_flags == 0 &&
               face_mismatches == 0 && bound_violations == 0 && border_cracks == 0 && !precision_exceeded;
    }
};

struct VerifySettings {
    size_t samples_per_level = 50000;  // surface samples for the distance measures
    bool progress = false;             // named phases on a terminal (base/progress.h)
};

// Throws Error if the file cannot be opened as a CATP dataset at all; everything else is reported.
VerifyReport verify_catp(const std::string& path, const Mesh* original, const VerifySettings& settings);

}  // namespace catpaq
