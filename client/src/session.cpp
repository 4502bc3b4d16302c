#include "client/session.h"

#include <algorithm>
#include <cmath>

#include "base/error.h"
#include "base/sysinfo.h"
#include "catp/dataset.h"
#include "catp/distance.h"
#include "common_codec/barycentric.h"

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
    residency_->set_distance_function([this](uint32_t node, const std::array<double, 3>& eye) { return data_distance(node, eye); });
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
    distances_.erase(node);
    const HierarchyNode& n = hierarchy_.node(node);
    for (const HierarchyPart& part : n.parts)
        if (store_.resident(n.key, part.id)) store_.release(n.key, part.id);
}

std::vector<const char*> session_limit_names(uint8_t limits) {
    std::vector<const char*> out;
    const std::pair<SessionLimit, const char*> names[] = {
        {kLimitFinestLevel, "finest_level"}, {kLimitTriangles, "triangle_budget"}, {kLimitGpuBytes, "gpu_budget"},
        {kLimitCpuBytes, "cpu_budget"},      {kLimitFailedNode, "failed_node"},    {kLimitPending, "pending"}};
    for (auto [bit, name] : names)
        if (limits & bit) out.push_back(name);
    return out;
}

// The box of a node's decoded vertices (world): where its geometry really is, for the cut
// engine's projected errors (the hierarchy's box also covers the descendants).
Aabb StreamingSession::data_bounds(const HierarchyNode& node, const DiamondFragments& fragments) const {
    const CatpMeta& meta = index_->meta();
    Aabb box;
    std::vector<std::array<int64_t, 3>> exact;
    DiamondInfo info = diamond_info(DiamondId{node.key});
    for (const HierarchyPart& part : node.parts) {
        const FragmentMesh& fragment = fragments.slots[part.id];
        if (fragment.indices.empty() || !decode_fragment_integer_positions(fragment, info, int(part.id), exact)) continue;
        for (const auto& p : exact) {
            std::array<double, 3> world;
            for (int k = 0; k < 3; ++k) world[k] = meta.origin[k] + double(p[k]) / meta.layout.grid * meta.cell;
            box.extend(world);
        }
    }
    if (box.empty()) return box;
    // Rounding: a hair larger, never smaller, than the decoded positions.
    double slack = meta.cell * 1e-6;
    for (int k = 0; k < 3; ++k) {
        box.min[k] -= slack + std::abs(box.min[k]) * 1e-12;
        box.max[k] += slack + std::abs(box.max[k]) * 1e-12;
    }
    return box;
}

// The distance from the eye to the triangles of a resident node (all its parts: a superset of
// what it draws), measured on the CPU from the decoded vertices. Distances are 1-Lipschitz in
// the eye, so an earlier measure minus how far the eye moved since is still a lower bound; the
// triangles are measured again only when the eye moved more than a tenth of that distance.
double StreamingSession::data_distance(uint32_t node, const std::array<double, 3>& eye) {
    auto moved = [&](const std::array<double, 3>& from) {
        return std::sqrt((eye[0] - from[0]) * (eye[0] - from[0]) + (eye[1] - from[1]) * (eye[1] - from[1]) +
                         (eye[2] - from[2]) * (eye[2] - from[2]));
    };
    auto cached = distances_.find(node);
    if (cached != distances_.end() && moved(cached->second.eye) <= 0.1 * cached->second.distance)
        return cached->second.distance - moved(cached->second.eye);
    auto it = decoded_.find(node);
    if (it == decoded_.end()) return 0;
    const HierarchyNode& n = hierarchy_.node(node);
    const CatpMeta& meta = index_->meta();
    DiamondInfo info = diamond_info(DiamondId{n.key});
    std::vector<std::array<int64_t, 3>> exact;
    std::vector<std::array<double, 3>> world;
    double best2 = INFINITY;
    for (const HierarchyPart& part : n.parts) {
        const FragmentMesh& fragment = it->second->slots[part.id];
        if (fragment.indices.empty() || !decode_fragment_integer_positions(fragment, info, int(part.id), exact)) continue;
        world.resize(exact.size());
        for (size_t v = 0; v < exact.size(); ++v)
            for (int k = 0; k < 3; ++k) world[v][k] = meta.origin[k] + double(exact[v][k]) / meta.layout.grid * meta.cell;
        for (size_t t = 0; t + 2 < fragment.indices.size(); t += 3)
            best2 = std::min(best2, point_triangle_distance2(eye, world[fragment.indices[t]], world[fragment.indices[t + 1]],
                                                             world[fragment.indices[t + 2]]));
    }
    if (!std::isfinite(best2)) return 0;
    // Decoding rounds: a hair less than measured, never more.
    double distance = std::max(0.0, std::sqrt(best2) * (1 - 1e-9) - meta.cell * 1e-6);
    distances_[node] = {eye, distance};
    return distance;
}

void StreamingSession::integrate(std::vector<FetchedNode>& arrived) {
    for (FetchedNode& f : arrived) {
        supplied_.erase(f.key);
        if (!f.ok || !f.fragments || f.node == kNoNode) {
            // Failed every attempt: recorded once (the fetcher retries it later if still wanted).
            if (!f.ok && f.node != kNoNode) residency_->set_failed(f.node, true);
            if (!f.ok && f.node != kNoNode && failed_keys_.insert(f.key).second) {
                std::string error = f.error, prefix = "node " + std::to_string(f.key) + ": ";
                if (error.rfind(prefix, 0) == 0) error.erase(0, prefix.size());  // the key is said once
                failures_.push_back({f.key, hierarchy_.node(f.node).level, error});
            }
            continue;
        }
        failed_keys_.erase(f.key);
        residency_->set_failed(f.node, false);
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
        residency_->set_resident(f.node, bytes, data_bounds(n, *f.fragments));
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
    s.arrived = arrived.size();
    s.cut_changes = frame.stats.refinements + frame.stats.coarsenings;
    s.failed_nodes = failures_.size();
    settled_ = frame.requests.empty() && frame.stats.holes == 0 && frame.stats.refinements == 0 &&
               frame.stats.coarsenings == 0 && fetcher_->idle() && arrived.empty();
    s.settled = settled_;
    s.tolerance_met = s.holes == 0 && s.certified_error_px <= settings_.tolerance_px;
    if (!s.tolerance_met) s.limits = limits(frame, s);
    return s;
}

// What keeps the error above the tolerance: the finest level, budgets, failed nodes, or data
// still on its way (any mix; see SessionLimit).
uint8_t StreamingSession::limits(const CutFrame& frame, const SessionFrameStats& s) const {
    uint8_t out = 0;
    const CutFrameStats& c = frame.stats;
    if (c.leaves_over_tolerance) out |= kLimitFinestLevel;
    if (c.budgets_binding & kPrimitiveBudget) out |= kLimitTriangles;
    if (c.budgets_binding & kGpuBudget) out |= kLimitGpuBytes;
    if (c.budgets_binding & kCpuBudget) out |= kLimitCpuBytes;
    bool failed = false, waiting = false;
    for (const CutRequest& r : frame.requests) (failed_keys_.count(r.key) ? failed : waiting) = true;
    if (failed) out |= kLimitFailedNode;
    if (waiting || c.capped || (!s.settled && !failed)) out |= kLimitPending;
    return out;
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
