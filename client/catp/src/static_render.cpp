// Rendering a cut of a local CATP file offscreen.
#include "catp_client/static_render.h"

#include "base/error.h"

namespace catpaq {

StaticRenderer::StaticRenderer(const CatpFile& file, int samples) : file_(file), samples_(samples), renderer_(store_) {}

StaticRenderer::~StaticRenderer() = default;

std::vector<DrawItem> StaticRenderer::draw_items(const RefinedSet& refined) const {
    std::vector<DrawItem> items;
    for (const DrawnSlot& d : drawn_slots(file_.index(), refined)) items.push_back({d.entry->key, d.slot});
    return items;
}

void StaticRenderer::upload(const std::vector<DrawItem>& items) {
    // Group the missing slots by diamond so each node is decoded once.
    size_t i = 0;
    while (i < items.size()) {
        uint64_t key = items[i].diamond_key;
        std::vector<int> slots;
        for (; i < items.size() && items[i].diamond_key == key; ++i)
            if (!store_.resident(key, items[i].slot)) slots.push_back(items[i].slot);
        if (slots.empty()) continue;
        const ArchiveEntry* entry = file_.index().find(DiamondId{key});
        if (!entry) fail("diamond %llu is not in the dataset", (unsigned long long)key);
        DiamondFragments fragments = file_.decode(*entry);
        for (int slot : slots) {
            if (!(fragments.slot_mask & (1u << slot)))
                fail("diamond %llu has no fragment in slot %d", (unsigned long long)key, slot);
            store_.upload(key, slot, fragments.slots[size_t(slot)]);
        }
    }
}

std::vector<uint8_t> StaticRenderer::render_items(const std::vector<DrawItem>& items, const Camera& camera,
                                                  const RenderSettings& settings, RenderStats* stats) {
    std::string problem = camera.problem();
    if (!problem.empty()) fail("camera: %s", problem.c_str());
    upload(items);
    if (!framebuffer_ || framebuffer_->width() != camera.width || framebuffer_->height() != camera.height)
        framebuffer_ = std::make_unique<Framebuffer>(camera.width, camera.height, samples_);
    framebuffer_->bind();
    store_.begin_frame();
    RenderStats s = renderer_.render(camera, file_.index().meta(), items, settings);
    if (stats) *stats = s;
    return framebuffer_->read_pixels();
}

std::vector<uint8_t> StaticRenderer::render(const RefinedSet& refined, const Camera& camera, const RenderSettings& settings,
                                            RenderStats* stats) {
    return render_items(draw_items(refined), camera, settings, stats);
}

std::vector<uint8_t> render_cut(const CatpFile& file, const RefinedSet& refined, const Camera& camera,
                                const RenderSettings& settings, RenderStats* stats) {
    StaticRenderer renderer(file);
    return renderer.render(refined, camera, settings, stats);
}

RefinedSet finest_cut(const CatpIndex& index) {
    RefinedSet refined;
    for (const ArchiveEntry& e : index.entries())
        if (!(e.flags & kCatpLeafFlag)) refined.refine(DiamondId{e.key});
    return refined;
}

}  // namespace catpaq
