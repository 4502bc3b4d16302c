#pragma once
// The AQP converter: a mesh in, an AQP dataset (aqp/format.h) out.
//
// 1. Clean the input to an oriented two-manifold (aqp/clean.h), reporting what was removed.
// 2. Simplify it to a base domain and parameterize it over the domain (aqp/domain.h).
// 3. Lay out the quad patches (aqp/quad_layout.h) and choose the finest level k.
// 4. Resample: every sample of every patch at level k is evaluated once, as a shared number
//    (SampleNumbering), at its domain point's surface point (aqp/surface_map.h): position,
//    normal, colour. Patches sharing a corner or an edge copy the same values.
// 5. Quantize: positions to a dataset-wide grid of step `step` (each patch stores 16-bit offsets
//    from its own origin on that grid, so shared samples decode to the same bits everywhere),
//    normals to 8+8-bit octahedral codes, colours to 8-bit RGB.
// 6. Measure each node's error (the largest distance between the level's triangulated surface
//    and the input surface at corresponding points; see measure_errors in build.cpp), monotone
//    up the levels.
// 7. Order the patches along a Morton curve, group each level's consecutive patches into tiles
//    of at least `tile_samples` stored samples (tile_shifts), encode every (tile, level) node as
//    one PNG image and write the archive atomically.
//
// Memory is proportional to the input (in core: peak 42 MiB for the bunny's 75k triangles, 322 MiB
// for a 1M-triangle scan); all cores are used for the smoothing, the resampling, the errors and
// the PNG encoding. The simplification is sequential.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "aqp/clean.h"
#include "aqp/domain.h"
#include "mesh/mesh.h"
#include "mesh/precision.h"

namespace catpaq::aqp {

struct AqpBuildOptions {
    // Finest level k (patches of (2^k + 1)^2 samples), 1 to kMaxPatchLevel; -1 chooses it from
    // `samples_per_patch`, or when that is 0 so that the samples are about twice the input's
    // vertices.
    int patch_level = -1;
    size_t samples_per_patch = 0;
    size_t domain_triangles = 0;  // base triangles; 0: default_domain_triangles
    int smoothing_sweeps = 4;     // parameter smoothing (DomainOptions)
    double min_component_area_fraction = 1e-3;  // CleanOptions
    Precision precision;  // the quantization's largest distance from a sample's true position
    int png_compression = 6;      // zlib level of the node images (9: 4% smaller, encoding 7.6x slower on a 1M scan)
    // Each level's tiles hold 4^s consecutive patches, s the largest keeping a tile's stored
    // samples within this many (0: one patch per node). Coarse levels then cost one image for
    // many patches, not one each (tile_shifts). 512 by measurement: cold starts of the report's
    // six views of a 2M-triangle scan-like mesh fetched 4-49% fewer bytes than without tiles in
    // 3-48 requests instead of 155-919; 2048 and 8192 took fewer requests still but fetched up to
    // 1.4x and 2x the bytes on close views (a refinement refines a whole tile), 256 about as 512.
    size_t tile_samples = 512;
    // Refuse to start when the estimated working memory exceeds this many bytes (0: no limit).
    uint64_t memory_budget = 0;
    // How far the input mesh may be from the surface it stands for (model units), added to every
    // node's error so the bounds hold against that surface: for an out-of-core reduction's mesh
    // the largest distance of an input vertex to it (aqp/reduce.h), 0 for an input converted as
    // it is.
    double input_error = 0;
    uint32_t up_axis = 0;         // stored for viewers (AqpMeta::up_axis numbering; 0: unknown)
    unsigned threads = 0;         // 0: all cores
    bool progress = true;         // named phases on a terminal
};

// Per level 0..k, the tile shift (AqpMeta::tile_shift) for `patches` patches: the largest s
// whose 4^s patches store at most `tile_samples` samples at that level (a finer level stores
// only the samples its coarser one lacks; 0 when one patch stores more), no more than holds
// every patch; 0 everywhere when tile_samples is 0. Non-increasing with the level, as tiles
// must nest.
std::vector<uint8_t> tile_shifts(int finest_level, size_t patches, size_t tile_samples);

struct AqpLevelStats {
    int level = 0;
    size_t nodes = 0;
    size_t samples = 0;    // in all its nodes, shared samples counted in every patch
    uint64_t bytes = 0;    // node payloads
    double max_error = 0;  // largest node bound, world units
    double mean_error = 0;
};

struct AqpBuildReport {
    CleanReport clean;
    DomainReport domain;  // with the parameterization's check and distortion
    size_t patches = 0;
    int patch_level = 0;
    size_t samples = 0;         // distinct samples at the finest level
    double step = 0;            // quantization step, world units
    double precision = 0;       // reached: the quantization's largest distance, world units
    double precision_asked = 0;
    double mean_edge = 0;
    double diagonal = 0;        // of the input's bounds
    uint64_t file_bytes = 0, payload_bytes = 0;
    double bits_per_sample = 0;  // payload bits over distinct finest samples
    size_t location_misses = 0;  // samples placed on the nearest image (see SurfaceMap)
    // Finest-level grid triangles left without area by quantization (geometry thinner than the
    // step: they draw as lines or points; the bounds still hold, measured on decoded positions).
    size_t collapsed_triangles = 0;
    std::vector<AqpLevelStats> levels;  // coarse to fine
    std::vector<std::string> warnings;
    uint64_t memory_estimate = 0, peak_rss = 0;
    double seconds = 0, seconds_clean = 0, seconds_parameterize = 0, seconds_resample = 0, seconds_errors = 0,
           seconds_encode = 0;
};

// Peak resident memory of converting a mesh of this many triangles (the mesh read included): AQP
// converts in core.
uint64_t aqp_memory_estimate(uint64_t input_triangles);

// Throws Error, naming the estimate and what to do instead, when that estimate exceeds a non-zero
// `budget` (convert reduces a PLY above the budget out of core first, aqp/reduce.h).
void check_aqp_memory_budget(uint64_t input_triangles, uint64_t budget);

// Converts `input` into an AQP dataset at `out_path`. Throws Error with a clear message for what
// it refuses: an invalid or empty mesh, nothing left after cleaning, a non-orientable surface, a
// domain that cannot be reached, a parameterization that is not bijective, a memory estimate
// above the budget. Nothing is left at `out_path` on failure.
void build_aqp_dataset(const Mesh& input, const std::string& out_path, const AqpBuildOptions& options,
                       AqpBuildReport* report = nullptr);

}  // namespace catpaq::aqp
