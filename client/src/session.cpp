#include "client/session.h"

#include <algorithm>

#include "base/error.h"
#include "base/sysinfo.h"

namespace catpaq {

StreamingSession::StreamingSession(const std::string& location, const SessionSettings& settings)
    : settings_(settings) {
    std::unique_ptr<NodeSource> source = open_node_source(location, settings.http);
    std::vector<uint8_t> prefix = fetch_prefix(*source);
    prefix_bytes_ = prefix.size();
    index_ = std::make_unique<CatpIndex>(CatpIndex::from_prefix(prefix.data(), prefix.size(), location));
    hierarchy_ = build_catp_hierarchy(*index_);
    counter_ = std::make_unique<PartDrawCounter>(hierarchy_);
    residency_ = std::make_unique<ResidencyTable>(hierarchy_);
    engine_ = std::make_unique<CutEngine>(hierarchy_, *counter_, settings.budgets);
    FetcherSettings fetcher_settings = settings.fetcher;
    fetcher_settings.layout = index_->meta().layout;
    fetcher_ = std::make_unique<Fetcher>(std::move(source), fetcher_settings);
    store_.set_budget(settings.gpu_cache_bytes);
    store_.set_eviction_callback([this](uint64_t key, int) {
        uint32_t node = hierarchy_.find(key);
        if (node != kNoNode) evict(node);
    });
    renderer_ = std::make_unique<CatpRenderer>(store_);
    compressed_ = std::make_unique<CompressedCache>(settings.compressed_cache_bytes);
}

StreamingSession::~StreamingSession() {
    store_.set_eviction_callback(nullptr);
}

void StreamingSession::evict(uint32_t node) {
    if (!residency_->resident(node)) return;
    residency_->set_evicted(node);
    decoded_.erase(node);
    const HierarchyNode& n = hierarchy_.node(node);
    for (const HierarchyPart& part : n.parts)
        if (store_.resident(n.key, part.id)) store_.release(n.key, part.id);
}

void StreamingSession::integrate(std::vector<FetchedNode>& arrived) {
    for (FetchedNode& f : arrived) {
        supplied_.erase(f.key);
        if (!f.ok || !f.fragments || f.node == kNoNode) continue;  // failed: retried if still wanted
        const HierarchyNode& n = hierarchy_.node(f.node);
        if (f.compressed) compressed_->insert(n.key, f.compressed, f.compressed->size());
        NodeBytes bytes;
        std::vector<uint32_t> counts;
        for (const HierarchyPart& part : n.parts) {
            const FragmentMesh& fragment = f.fragments->slots[part.id];
            counts.push_back(uint32_t(fragment.triangle_count()));
            bytes.cpu += fragment.vertices.size() * sizeof(PackedVertex) + fragment.indices.size() * 4;
            if (fragment.indices.empty()) continue;
            store_.upload(n.key, part.id, fragment);
            bytes.gpu += fragment.vertices.size() * sizeof(PackedVertex) +
                         fragment.indices.size() * (fragment.vertices.size() < 65536 ? 2 : 4);
        }
        counter_->set_counts(f.node, counts.data(), counts.size());
        residency_->set_resident(f.node, bytes);
        decoded_[f.node] = f.fragments;
    }
}

SessionFrameStats StreamingSession::step(const Camera& camera) {
    std::vector<FetchedNode> arrived;
    fetcher_->poll(arrived);
    integrate(arrived);

    Camera cam = camera;
    if (!cam.has_clip_planes()) {
        const CatpMeta& m = index_->meta();
        cam.fit_clip_planes({m.bounds_min[0], m.bounds_min[1], m.bounds_min[2]},
                            {m.bounds_max[0], m.bounds_max[1], m.bounds_max[2]});
    }
    ViewParams view = ViewParams::look_at({camera.eye.x, camera.eye.y, camera.eye.z},
                                          {camera.target.x, camera.target.y, camera.target.z},
                                          {camera.up.x, camera.up.y, camera.up.z}, camera.fov_y_degrees * 3.14159265358979323846 / 180.0,
                                          camera.width, camera.height, cam.near_plane, cam.far_plane);
    view.tolerance_px = settings_.tolerance_px;
    view.skip_factor = settings_.skip_factor;
    const CutFrame& frame = engine_->update(view, *residency_);

    std::vector<FetchRequest> wanted;
    wanted.reserve(frame.requests.size());
    for (const CutRequest& r : frame.requests) {
        const HierarchyNode& n = hierarchy_.node(r.node);
        if (supplied_.count(n.key)) continue;
        if (const auto* bytes = compressed_->get(n.key)) {  // evicted earlier: decode again, no fetch
            fetcher_->supply(FetchRequest::of(n), *bytes);
            supplied_.insert(n.key);
            continue;
        }
        wanted.push_back(FetchRequest::of(n));
    }
    fetcher_->request(wanted);

    // Keep the cut's fragments on the GPU; evict least recently used others past the budget.
    store_.begin_frame();
    store_.unpin_all();
    for (uint32_t node : engine_->pinned()) {
        const HierarchyNode& n = hierarchy_.node(node);
        for (const HierarchyPart& part : n.parts)
            if (store_.resident(n.key, part.id)) store_.pin(n.key, part.id);
    }
    items_.clear();
    for (uint32_t node : engine_->drawn_nodes()) {
        const HierarchyNode& n = hierarchy_.node(node);
        if (!n.has_data) continue;
        for (const HierarchyPart& part : n.parts) {
            bool parent_refined = part.parent == kNoNode || engine_->refined(part.parent);
            if (parent_refined && store_.resident(n.key, part.id)) {
                items_.push_back({n.key, part.id});
                store_.mark_used(n.key, part.id);
            }
        }
    }
    store_.evict_to_budget();

    FetcherStats fs = fetcher_->stats();
    SessionFrameStats s;
    s.triangles = frame.stats.primitives;
    s.drawn_nodes = frame.stats.drawn_nodes;
    s.refined_nodes = frame.stats.refined_nodes;
    s.fragments = items_.size();
    s.bytes_fetched = prefix_bytes_ + fs.bytes_fetched;
    s.requests = fs.transfers;
    s.pending = frame.requests.size();
    s.gpu_bytes = store_.gpu_bytes();
    s.cpu_bytes = frame.stats.cpu_bytes + compressed_->bytes();
    s.cut_ms = frame.stats.seconds * 1000.0;
    s.certified_error_px = frame.stats.certified_error_px;
    s.holes = frame.stats.holes;
    converged_ = frame.requests.empty() && frame.stats.holes == 0 && frame.stats.refinements == 0 &&
                 frame.stats.coarsenings == 0 && fetcher_->idle() && arrived.empty();
    return s;
}

RenderStats StreamingSession::draw(const Camera& camera, const RenderSettings& render) {
    return renderer_->render(camera, index_->meta(), items_, render);
}

const DiamondFragments* StreamingSession::fragments(uint64_t key) const {
    uint32_t node = hierarchy_.find(key);
    auto it = decoded_.find(node);
    return it == decoded_.end() ? nullptr : it->second.get();
}

}  // namespace catpaq
