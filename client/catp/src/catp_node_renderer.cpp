// CATP's NodeRenderer: the FragmentStore and CatpRenderer behind the interface the streaming
// session drives (client/node_renderer.h). A node's parts are its slots.
#include <memory>

#include "base/error.h"
#include "catp_client/catp_format.h"
#include "catp_client/catp_gpu.h"
#include "client/hierarchy.h"

namespace catpaq {

namespace {

class CatpNodeRenderer : public NodeRenderer {
public:
    explicit CatpNodeRenderer(const CatpMeta& meta) : meta_(meta), renderer_(store_) {}

    void upload(const HierarchyNode& node, const DecodedNode& decoded) override {
        const DiamondFragments& fragments = catp_fragments(decoded);
        for (const HierarchyPart& part : node.parts) {
            const FragmentMesh& fragment = fragments.slots[part.id];
            if (fragment.indices.empty()) continue;
            store_.upload(node.key, part.id, fragment);
        }
    }
    bool resident(uint64_t key, uint8_t part) const override { return store_.resident(key, part); }
    void release(uint64_t key, uint8_t part) override { store_.release(key, part); }
    void begin_frame() override { store_.begin_frame(); }
    void unpin_all() override { store_.unpin_all(); }
    void pin(uint64_t key, uint8_t part) override { store_.pin(key, part); }
    void mark_used(uint64_t key, uint8_t part) override { store_.mark_used(key, part); }
    size_t evict_to_budget() override { return store_.evict_to_budget(); }
    void set_budget(uint64_t bytes) override { store_.set_budget(bytes); }
    uint64_t gpu_bytes() const override { return store_.gpu_bytes(); }
    void set_eviction_callback(std::function<void(uint64_t key, uint8_t part)> callback) override {
        if (!callback) {
            store_.set_eviction_callback(nullptr);
            return;
        }
        store_.set_eviction_callback([callback = std::move(callback)](uint64_t key, int slot) { callback(key, uint8_t(slot)); });
    }
    RenderStats draw(const Camera& camera, const std::vector<DrawnPart>& parts, const RenderSettings& settings) override {
        items_.clear();
        items_.reserve(parts.size());
        for (const DrawnPart& p : parts) items_.push_back({p.key, int(p.part)});
        return renderer_.render(camera, meta_, items_, settings);
    }

private:
    CatpMeta meta_;
    FragmentStore store_;
    CatpRenderer renderer_;  // after store_: it draws from it
    std::vector<DrawItem> items_;
};

}  // namespace

std::unique_ptr<NodeRenderer> create_catp_renderer(const DatasetFormat& format) {
    const auto* catp = dynamic_cast<const CatpFormat*>(&format);
    if (!catp) fail("the CATP renderer needs a CATP dataset");
    return std::make_unique<CatpNodeRenderer>(catp->meta());
}

}  // namespace catpaq
