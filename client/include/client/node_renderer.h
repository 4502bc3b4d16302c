#pragma once
// The GPU side of a dataset format (client/format.h), as the streaming session drives it: a store
// of the parts of decoded nodes in GPU buffers under a byte budget, and the renderer that draws a
// cut's parts. Parts are named by node key and part id (HierarchyPart::id), so the session needs
// nothing of the format to drive it.
//
// The store's policy, the same for every format: parts pinned (the cut) or used in the current
// frame are never evicted; the others go least recently used first once the store is over its
// budget, and each eviction is reported, so the session drops the node from its residency.
//
// Everything here needs a current GL context (client/gl_context.h).
#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include "client/camera.h"

namespace catpaq {

struct HierarchyNode;
class DecodedNode;

// One part of a node, as drawn.
struct DrawnPart {
    uint64_t key = 0;  // node key (CATP: DiamondId bits)
    uint8_t part = 0;  // HierarchyPart::id (CATP: the slot)
    bool operator==(const DrawnPart& o) const { return key == o.key && part == o.part; }
};

// How point formats draw a splat (formats of triangles ignore it).
enum class SplatShape : uint8_t {
    Round,     // screen-aligned discs sized by the projected radius, at the centre's depth (fast)
    Oriented,  // ellipses: the splat's disc in its tangent plane, ray-cast per pixel with its depth
};

struct RenderSettings {
    std::array<float, 4> background{1.0f, 1.0f, 1.0f, 1.0f};
    // World-space direction towards the light; all zero: a headlight (from the eye).
    std::array<float, 3> light_direction{0.0f, 0.0f, 0.0f};
    float ambient = 0.25f;
    bool flat = false;                                // one flat colour, no lighting
    std::array<float, 3> flat_color{0.0f, 0.0f, 0.0f};
    bool wireframe = false;                           // polygon mode lines (desktop GL only)
    bool cull_back_faces = false;
    bool clear = true;                                // clear colour and depth first
    SplatShape splats = SplatShape::Round;            // point formats only
};

struct RenderStats {
    size_t draws = 0;
    size_t triangles = 0;
    size_t vertices = 0;
    size_t points = 0;   // point primitives (splats) drawn; 0 for the mesh formats
    size_t missing = 0;  // items that were not resident (skipped)
};

// The GL state every format's draw starts from: the camera's viewport, the clear `settings` asks
// for, depth test (less, written), no blending; for triangles also back-face culling and
// wireframe as asked (points: no culling). Needs a current GL context.
void begin_draw(const Camera& camera, const RenderSettings& settings, bool triangles);

class NodeRenderer {
public:
    virtual ~NodeRenderer() = default;

    // Uploads the parts of a decoded node that hold geometry (replacing earlier uploads of them);
    // they count as used this frame. Throws Error for data the GPU cannot take (then the store
    // keeps what it had for the failing part).
    virtual void upload(const HierarchyNode& node, const DecodedNode& decoded) = 0;
    virtual bool resident(uint64_t key, uint8_t part) const = 0;
    virtual void release(uint64_t key, uint8_t part) = 0;

    // Per frame: begin_frame(), then unpin_all() and pin() the cut's parts, mark_used() the drawn
    // ones, evict_to_budget().
    virtual void begin_frame() = 0;
    virtual void unpin_all() = 0;
    virtual void pin(uint64_t key, uint8_t part) = 0;
    virtual void mark_used(uint64_t key, uint8_t part) = 0;
    // Evicts least recently used parts, neither pinned nor used this frame, while over the
    // budget; returns how many. May stay over budget.
    virtual size_t evict_to_budget() = 0;
    virtual void set_budget(uint64_t bytes) = 0;  // 0: unlimited
    virtual uint64_t gpu_bytes() const = 0;
    // Called for every part evicted by the budget (not for release()).
    virtual void set_eviction_callback(std::function<void(uint64_t key, uint8_t part)> callback) = 0;

    // Draws the resident parts into the bound draw framebuffer (viewport camera.width x
    // camera.height); parts that are not resident are skipped and counted in `missing`. Clip
    // planes are fitted to the dataset's bounds when the camera has none.
    virtual RenderStats draw(const Camera& camera, const std::vector<DrawnPart>& parts, const RenderSettings& settings) = 0;
};

}  // namespace catpaq
