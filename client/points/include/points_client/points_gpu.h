#pragma once
// Point splats on the GPU, and the renderer: the point format's NodeRenderer
// (client/node_renderer.h).
//
// SplatStore keeps one vertex buffer per node: its packed splats as they are
// (points_client/splat_layout.h, 8 or 6 bytes per point, one attribute of 16-bit halves), with the
// node's decode constants. Its policy is CATP's FragmentStore's (catp_client/catp_gpu.h): pinned
// nodes and nodes used in the current frame are never evicted, the others go least recently
// used first once the store is over its byte budget, and every eviction is reported.
//
// PointsRenderer draws a list of nodes, one GL_POINTS draw call per node, each splat a point
// sprite sized by its projected radius, shaped by RenderSettings::splats (shaders/points.vert,
// points_round.frag, points_oriented.frag). Positions reach the GPU relative to the eye (the node
// origin minus the eye in double on the CPU).
//
// Limits of point sprites: GL may discard a point whose centre is outside the view, which would
// leave gaps along the image border (llvmpipe keeps them: PointSprites.CoverTheImageBorderUpClose
// passes), and sprites are at most the GL's largest point size, so extreme close-ups of coarse
// splats may show gaps.
//
// Everything here needs a current GL context (client/gl_context.h).
#include <cstdint>
#include <functional>
#include <list>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "client/gl_program.h"
#include "client/gpu_lru_store.h"
#include "client/node_renderer.h"
#include "points/format.h"
#include "points_client/splat_layout.h"

namespace catpaq {

// The point shaders (shaders/, embedded at build time) with the context's preamble.
enum class PointsShader { Vertex, Round, Oriented };
std::string points_shader_source(PointsShader kind, bool gles);

// A resident node.
struct GpuSplats {
    unsigned vao = 0, vbo = 0;
    uint32_t count = 0;
    uint64_t bytes = 0;  // vertex buffer bytes
    std::array<double, 3> origin{};
    std::array<float, 3> step{};
    float radius_base = 0, radius_log2_step = 0;
    int radius_bits = 5;
    bool has_normals = false, has_colors = false;
};

class SplatStore : public GpuLruStore<uint64_t, GpuSplats> {
public:
    SplatStore() : GpuLruStore(destroy) {}  // GL objects are deleted with the store (the context must still be current)

    // Uploads (replacing an earlier upload of) node `key`'s splats; it counts as used this
    // frame. Throws Error for splats that are inconsistent (word count) or that the GPU refuses
    // (out of memory), leaving the store as it was. Then evicts down to the budget.
    void upload(uint64_t key, const PackedSplats& splats);

private:
    static void destroy(GpuSplats& gpu);
};

// The point format's NodeRenderer: a SplatStore and the two splat programs. Parts are nodes
// (part id 0).
class PointsRenderer : public WholeNodeRenderer<SplatStore> {
public:
    // Splats are drawn at their radius: the converter's radii cover the sampled surface
    // (points/builder.h; a uniformly random 200k-point sphere shows no hole, points_gl_tests).
    //
    // Compiles the programs; throws Error with the compiler's log.
    explicit PointsRenderer(const PointsMeta& meta);
    ~PointsRenderer() override;

    void upload(const HierarchyNode& node, const DecodedNode& decoded) override;
    // RenderStats: draws = nodes drawn, vertices = splats drawn, triangles 0.
    RenderStats draw(const Camera& camera, const std::vector<DrawnPart>& parts, const RenderSettings& settings) override;

    const SplatStore& store() const { return store_; }

private:
    struct Uniforms {
        int node_offset = -1, node_step = -1, radius_base = -1, radius_log2_step = -1, radius_bits = -1, has_normals = -1;
        int has_colors = -1;
        int default_color = -1, modelview = -1, projection = -1, pixels_per_unit = -1, max_point_size = -1, oriented = -1;
        int flat_mode = -1, flat_color = -1, light_eye = -1, ambient = -1;
        int viewport = -1, projection_scale = -1, depth_coefficients = -1;
    };
    PointsMeta meta_;
    GlProgram round_, oriented_;
    Uniforms round_u_, oriented_u_;
    float max_point_size_ = 1;
};

class DatasetFormat;
// The NodeRenderer for an opened point dataset (a PointsFormat); throws Error if `format` is not
// one or the programs do not build.
std::unique_ptr<NodeRenderer> create_points_renderer(const DatasetFormat& format);

}  // namespace catpaq
