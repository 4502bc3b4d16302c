#pragma once
// Rendering a local CATP file: a given conforming cut (catp/cut.h RefinedSet) from a given
// camera into an RGBA8 buffer, offscreen. Used by the tests and benchmarks; the streaming
// session drives FragmentStore/CatpRenderer through CATP's NodeRenderer (create_catp_renderer)
// instead. Needs a current GL context (client/gl_context.h: HeadlessGlContext).
#include <cstdint>
#include <memory>
#include <unordered_map>
#include <vector>

#include "catp/cut.h"
#include "catp/dataset.h"
#include "catp_client/catp_gpu.h"
#include "client/camera.h"
#include "client/gl_context.h"

namespace catpaq {

// Keeps the fragments it uploaded between renders, so rendering many cuts or viewpoints of
// one file uploads each fragment once (the store has no budget unless you set one).
class StaticRenderer {
public:
    explicit StaticRenderer(const CatpFile& file, int samples = 0);  // samples: MSAA (0 = off)
    ~StaticRenderer();

    // The (diamond, slot) items cut `refined` draws (catp/cut.h drawn_slots).
    std::vector<DrawItem> draw_items(const RefinedSet& refined) const;
    // Uploads what the items need (decoding nodes from the file; throws Error on corrupt data).
    void upload(const std::vector<DrawItem>& items);
    // Renders cut `refined` into camera.width x camera.height RGBA8, rows top-down.
    std::vector<uint8_t> render(const RefinedSet& refined, const Camera& camera, const RenderSettings& settings,
                                RenderStats* stats = nullptr);
    // Renders explicit items (uploading them first).
    std::vector<uint8_t> render_items(const std::vector<DrawItem>& items, const Camera& camera,
                                      const RenderSettings& settings, RenderStats* stats = nullptr);

    FragmentStore& store() { return store_; }
    CatpRenderer& renderer() { return renderer_; }
    const CatpFile& file() const { return file_; }

private:
    const CatpFile& file_;
    int samples_;
    FragmentStore store_;
    CatpRenderer renderer_;
    std::unique_ptr<Framebuffer> framebuffer_;
};

// One-shot: renders cut `refined` of `file` from `camera` (a GL context must be current).
std::vector<uint8_t> render_cut(const CatpFile& file, const RefinedSet& refined, const Camera& camera,
                                const RenderSettings& settings, RenderStats* stats = nullptr);

// The refined set of the finest cut: every diamond of the index that is not a leaf.
RefinedSet finest_cut(const CatpIndex& index);

}  // namespace catpaq
