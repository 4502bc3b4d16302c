#pragma once
// AQP tiles on the GPU (their patch levels' textures), and the renderer.
//
// PatchTextureStore keeps the textures of each resident (tile, level) node, a pair per patch:
// samples as RGBA16UI (local x, y, z on the quantization grid and the octahedral normal code:
// 8 bytes per sample) and, with colours, RGBA8 (4 bytes per sample). Budget policy as CATP's FragmentStore
// (client/node_renderer.h): pinned nodes and nodes used in the current frame are never evicted,
// the others go least recently used first while the store is over its budget.
//
// AqpRenderer draws a cut's patches from one template grid per level (an index buffer over
// size x size virtual vertices, uploaded once): the vertex shader (shaders/aqp.vert) fetches its
// sample by gl_VertexID and snaps edge samples to the edge's drawn level, the coarser of the two
// patches sharing it (aqp_client/stitch.h), so there is no per-frame geometry: per patch, a few
// uniforms and one draw call. Shading is CATP's fragment shader (shaders/catp.frag).
//
// Everything here needs a current GL context (client/gl_context.h).
#include <array>
#include <cstdint>
#include <functional>
#include <list>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "aqp/format.h"
#include "client/camera.h"
#include "client/gl_program.h"
#include "client/gpu_lru_store.h"
#include "client/node_renderer.h"

namespace catpaq {

struct GpuPatch {
    uint32_t patch = 0;
    int level = 0;
    unsigned samples = 0, colors = 0;  // textures (colors 0 without colours)
};

// A resident tile: its patches' textures.
struct GpuTile {
    std::vector<GpuPatch> patches;
    uint64_t bytes = 0;
};

// The resident tiles' textures under the shared GPU store policy (client/gpu_lru_store.h).
class PatchTextureStore : public GpuLruStore<uint64_t, GpuTile> {
public:
    PatchTextureStore() : GpuLruStore(destroy) {}  // textures are deleted with the store (the context must still be current)

    // Uploads a decoded tile under its node key aqp_node_key(tile, level) (replacing an earlier
    // upload). Throws Error for grids that do not fit `meta` (the tile's patches and level,
    // sample counts, colours), leaving the store unchanged. Counts as used this frame; then
    // evicts down to the budget.
    void upload(uint64_t key, const std::vector<aqp::PatchGrid>& grids, const aqp::AqpMeta& meta);

private:
    static void destroy(GpuTile& gpu);
};

// One tile to draw.
struct AqpDrawItem {
    uint64_t key = 0;  // aqp_node_key(tile, level)
};

class AqpRenderer {
public:
    AqpRenderer(PatchTextureStore& store, const aqp::AqpMeta& meta);  // compiles the program; throws Error
    ~AqpRenderer();
    AqpRenderer(const AqpRenderer&) = delete;
    AqpRenderer& operator=(const AqpRenderer&) = delete;

    // Draws the resident items into the bound draw framebuffer (viewport camera.width x
    // camera.height), every edge at the coarser of the two drawn levels sharing it; marks them
    // used. Items not resident are skipped and counted in `missing` (their neighbours then draw
    // their shared edges at their own levels). Clip planes are fitted to the dataset's bounds
    // when the camera has none.
    RenderStats render(const Camera& camera, const std::vector<AqpDrawItem>& items, const RenderSettings& settings);

    const GlProgram& program() const { return program_; }
    // GPU bytes of the template grids built so far (index buffers; one per level drawn).
    uint64_t template_bytes() const { return template_bytes_; }

private:
    struct Template {
        unsigned vao = 0, ibo = 0;
        uint32_t index_count = 0;
        bool index32 = false;
    };
    const Template& grid_template(int level);  // built on first use

    PatchTextureStore& store_;
    const aqp::AqpMeta& meta_;
    GlProgram program_;
    struct Uniforms {
        int samples = -1, colors = -1, has_colors = -1, default_color = -1, level = -1, edge_level = -1,
            patch_offset = -1, step = -1, mvp = -1, flat_mode = -1, flat_color = -1, light = -1, ambient = -1;
    } u_;
    std::vector<Template> templates_;  // by level
    uint64_t template_bytes_ = 0;
    std::vector<int> drawn_level_;     // per patch, this frame (-1: not drawn)
    std::vector<const GpuPatch*> drawn_;  // this frame's patches
};

// The AQP shaders (shaders/aqp.vert and CATP's shaders/catp.frag) with the current context's
// preamble (shader_preamble).
std::string aqp_vertex_shader(bool gles);
std::string aqp_fragment_shader(bool gles);

class DatasetFormat;
// AQP's NodeRenderer for an opened AQP dataset (an AqpFormat, aqp_client/aqp_format.h): a
// PatchTextureStore and an AqpRenderer. Throws Error if `format` is not AQP or the program does
// not build.
std::unique_ptr<NodeRenderer> create_aqp_renderer(const DatasetFormat& format);

}  // namespace catpaq
