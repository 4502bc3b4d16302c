#pragma once
// CATP fragments on the GPU, and the renderer.
//
// FragmentStore keeps one VAO per (diamond, slot) fragment: the 64-bit vertices uploaded as they
// are (8 bytes per vertex, one uvec2 attribute) plus 16-bit indices (32-bit when the fragment has
// 65536 vertices or more). It counts GPU bytes and enforces a budget by evicting the least
// recently used fragments, never a pinned one nor one used in the current frame.
// The float comparison path (upload_float) stores the same fragments decoded on the CPU:
// 3 floats position + 3 floats normal + 4 bytes colour = 28 bytes per vertex.
//
// CatpRenderer draws a list of (diamond, slot) items, one draw call per fragment, with the
// fragment's canonical tetrahedron corners as uniforms; the vertex shader (shaders/catp.vert)
// decodes positions relative to a per-frame integer anchor near the camera.
//
// Both are CATP's GPU side behind the format seam: create_catp_renderer() wraps them as the
// NodeRenderer (client/node_renderer.h) the streaming session drives.
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

#include <glm/glm.hpp>

#include "catp/format.h"
#include "client/camera.h"
#include "client/gl_program.h"
#include "client/gpu_lru_store.h"
#include "client/node_renderer.h"
#include "common_codec/fragment_codec.h"

namespace catpaq {

// The CATP shaders (shaders/, embedded at build time), each with the preamble of the current
// context (shader_preamble, client/gl_program.h).
enum class CatpShader {
    PackedVertex,  // shaders/catp_decode.glsl + shaders/catp.vert: decodes the 64-bit vertex
    FloatVertex,   // shaders/float.vert: the float comparison path
    Fragment,      // shaders/catp.frag: Lambert + ambient, or flat colour
};
std::string catp_shader_source(CatpShader kind, bool gles);

struct DrawItem {
    uint64_t diamond_key = 0;  // DiamondId bits
    int slot = 0;              // 0..7
    bool operator==(const DrawItem& o) const { return diamond_key == o.diamond_key && slot == o.slot; }
};

enum class VertexFormat : uint8_t { Packed, Float };

constexpr uint32_t kPackedVertexBytes = 8;
constexpr uint32_t kFloatVertexBytes = 28;

// A resident fragment.
struct GpuFragment {
    VertexFormat format = VertexFormat::Packed;
    unsigned vao = 0, vbo = 0, ibo = 0;
    bool index32 = false;      // 32-bit indices (else 16-bit)
    uint32_t vertex_count = 0;
    uint32_t index_count = 0;  // 3 per triangle
    uint64_t bytes = 0;        // vertex + index buffer bytes
    std::array<LatticePoint, 4> corners{};  // canonical corners of the slot's tetrahedron
};

class FragmentStore {
public:
    FragmentStore() = default;  // GL objects are deleted with the store (the context must still be current)

    // Uploads (replacing any previous upload of the same item) slot `slot` of diamond
    // `diamond_key`. The fragment is validated first: the diamond and slot must exist, indices
    // be in range and positions valid for the fragment's layout; throws Error otherwise, leaving
    // the store unchanged. The new fragment counts as used this frame. Then evicts down to the
    // budget (see evict_to_budget).
    void upload(uint64_t diamond_key, int slot, const FragmentMesh& fragment);
    // The float comparison path: decodes on the CPU (decode_packed_vertex, positions relative to
    // the dataset origin in world units) and uploads 28 bytes per vertex.
    void upload_float(uint64_t diamond_key, int slot, const FragmentMesh& fragment, const CatpMeta& meta);

    bool resident(uint64_t diamond_key, int slot) const { return store_.resident(Key{diamond_key, slot}); }
    const GpuFragment* find(uint64_t diamond_key, int slot) const { return store_.find(Key{diamond_key, slot}); }
    // false if it was not resident
    bool release(uint64_t diamond_key, int slot) { return store_.release(Key{diamond_key, slot}); }
    void clear() { store_.clear(); }

    uint64_t gpu_bytes() const { return store_.gpu_bytes(); }
    size_t size() const { return store_.size(); }

    // GPU memory budget in bytes (0: unlimited). Setting it evicts at once.
    void set_budget(uint64_t bytes) { store_.set_budget(bytes); }
    uint64_t budget() const { return store_.budget(); }
    bool over_budget() const { return store_.over_budget(); }

    // Pinned fragments are never evicted (pins nest: pin twice, unpin twice).
    void pin(uint64_t diamond_key, int slot) { store_.pin(Key{diamond_key, slot}); }
    void unpin(uint64_t diamond_key, int slot) { store_.unpin(Key{diamond_key, slot}); }
    void unpin_all() { store_.unpin_all(); }

    // Frames: fragments marked used in the current frame are never evicted; marks of earlier
    // frames only order the eviction (least recently used first).
    void begin_frame() { store_.begin_frame(); }
    uint64_t frame() const { return store_.frame(); }
    void mark_used(uint64_t diamond_key, int slot) { store_.mark_used(Key{diamond_key, slot}); }  // no-op if not resident

    // Evicts least recently used fragments that are neither pinned nor used this frame until
    // gpu_bytes() <= budget(); returns how many were evicted. May stay over budget.
    size_t evict_to_budget() { return store_.evict_to_budget(); }
    // Called for every evicted fragment (not for release() or clear()). The callback may release
    // other fragments (the session drops a node's other slots with it).
    void set_eviction_callback(std::function<void(uint64_t diamond_key, int slot)> callback);

private:
    struct Key {
        uint64_t diamond;
        int slot;
        bool operator==(const Key& o) const { return diamond == o.diamond && slot == o.slot; }
    };
    struct KeyHash {
        size_t operator()(const Key& k) const { return size_t((k.diamond * 8 + uint64_t(k.slot)) * 0x9E3779B97F4A7C15ull >> 7); }
    };
    static void destroy(GpuFragment& gpu);

    // The policy every format's store shares (client/gpu_lru_store.h).
    GpuLruStore<Key, GpuFragment, KeyHash> store_{destroy};
};

// The per-frame transform the renderer uses: the integer lattice anchor nearest the eye
// (clamped to the lattice cube), the shader uniforms derived from it, and the matrices.
struct FrameTransform {
    LatticePoint anchor{};       // A
    glm::dvec3 anchor_world{};   // origin + A * cell
    float scale = 0;             // float(cell / grid)
    glm::mat4 mvp_packed{1.0f};  // projection * view_relative(anchor_world)
    glm::mat4 mvp_float{1.0f};   // projection * view_relative(origin)
    VertexDecodeParams decode;   // the dataset's layout, scale and default colour (offsets unset)

    // The vertex shader's inputs for a tetrahedron with canonical corners `corners`.
    VertexDecodeParams params(const std::array<LatticePoint, 4>& corners) const;
};
// The camera must have clip planes (Camera::fit_clip_planes).
FrameTransform frame_transform(const Camera& camera, const CatpMeta& meta);

class CatpRenderer {
public:
    explicit CatpRenderer(FragmentStore& store);  // compiles the programs; throws Error
    ~CatpRenderer();
    CatpRenderer(const CatpRenderer&) = delete;
    CatpRenderer& operator=(const CatpRenderer&) = delete;

    // Draws the resident items into the bound draw framebuffer, viewport camera.width x
    // camera.height, one draw call per fragment; marks each drawn item used in the store's
    // current frame. Items that are not resident are skipped and counted in `missing`. If the
    // camera has no clip planes they are fitted to the dataset's bounds.
    RenderStats render(const Camera& camera, const CatpMeta& meta, const std::vector<DrawItem>& items,
                       const RenderSettings& settings);

    const GlProgram& packed_program() const { return packed_; }
    const GlProgram& float_program() const { return float_; }

private:
    struct Uniforms {
        int corners = -1, layout = -1, grid = -1, scale = -1, default_color = -1, mvp = -1;
        int flat_mode = -1, flat_color = -1, light = -1, ambient = -1;
    };
    void set_shading(const GlProgram& program, const Uniforms& u, const RenderSettings& settings,
                     const glm::vec3& light) const;

    FragmentStore& store_;
    GlProgram packed_, float_;
    Uniforms packed_u_, float_u_;
};

class DatasetFormat;
// CATP's NodeRenderer for an opened CATP dataset (a CatpFormat, catp_client/catp_format.h): a
// FragmentStore and a CatpRenderer. Throws Error if `format` is not CATP or the programs do not
// build.
std::unique_ptr<NodeRenderer> create_catp_renderer(const DatasetFormat& format);

}  // namespace catpaq
