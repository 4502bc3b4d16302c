#include "client/session.h"

#include <algorithm>
#include <cmath>

#include "base/error.h"
#include "base/sysinfo.h"
#include "client/builtin_formats.h"

namespace catpaq {

StreamingSession::StreamingSession(const std::string& location, const SessionSettings& settings)
    : settings_(settings) {
    std::unique_ptr<NodeSource> source = open_node_source(location, settings.http);
    std::vector<uint8_t> prefix_bytes = fetch_prefix(*source);
    prefix_bytes_ = prefix_bytes.size();
    DatasetPrefix prefix = DatasetPrefix::parse(prefix_bytes.data(), prefix_bytes.size(), location);
    first_nodes_offset_ = prefix.header.index_offset + prefix.header.index_size;
    if (prefix_bytes.size() > first_nodes_offset_)
        first_nodes_.assign(prefix_bytes.begin() + ptrdiff_t(first_nodes_offset_), prefix_bytes.end());
    const FormatModule& module = (settings.formats ? *settings.formats : builtin_formats()).module_for(prefix);
    format_ = module.open(prefix);
    const Hierarchy& hierarchy = format_->hierarchy();
    counter_ = std::make_unique<PartDrawCounter>(hierarchy);
    residency_ = std::make_unique<ResidencyTable>(hierarchy);
    residency_->set_distance_function([this](uint32_t node, const std::array<double, 3>& eye) { return data_distance(node, eye); });
    engine_ = std::make_unique<CutEngine>(hierarchy, *counter_, settings.budgets);
    FetcherSettings fetcher_settings = settings.fetcher;
    fetcher_settings.decode = format_decoder(*format_);
    fetcher_ = std::make_unique<Fetcher>(std::move(source), fetcher_settings);
    renderer_ = module.create_renderer(*format_);
    renderer_->set_budget(settings.gpu_cache_bytes);
    renderer_->set_eviction_callback([this](uint64_t key, uint8_t part_id) {
        uint32_t node = format_->hierarchy().find(key);
        if (node == kNoNode) return;
        auto it = decoded_.find(node);
        if (it == decoded_.end() || it->second.whole) {
            evict(node);
            return;
        }
        const std::vector<HierarchyPart>& parts = format_->hierarchy().node(node).parts;
        for (size_t i = 0; i < parts.size(); ++i)
            if (parts[i].id == part_id) evict_part(node, i);
    });
    compressed_ = std::make_unique<CompressedCache>(settings.compressed_cache_bytes);
}

StreamingSession::~StreamingSession() {
    if (renderer_) renderer_->set_eviction_callback(nullptr);
}

void StreamingSession::evict(uint32_t node) {
    if (!residency_->any_resident(node)) return;
    residency_->set_evicted(node);
    decoded_.erase(node);
    distances_.erase(node);
    const HierarchyNode& n = hierarchy().node(node);
    for (const HierarchyPart& part : n.parts)
        if (renderer_->resident(n.key, part.id)) renderer_->release(n.key, part.id);
}

// One part of a node fetched by parts (the others stay).
void StreamingSession::evict_part(uint32_t node, size_t part) {
    if (!residency_->part_resident(node, part)) return;
    residency_->set_part_evicted(node, part);
    distances_.erase(node);
    auto it = decoded_.find(node);
    if (it != decoded_.end() && part < it->second.parts.size()) {
        it->second.parts[part].reset();
        if (!residency_->any_resident(node)) decoded_.erase(it);
    }
    const HierarchyNode& n = hierarchy().node(node);
    if (renderer_->resident(n.key, n.parts[part].id)) renderer_->release(n.key, n.parts[part].id);
}

const DecodedNode* StreamingSession::decoded_part(uint32_t node, size_t part) const {
    auto it = decoded_.find(node);
    if (it == decoded_.end()) return nullptr;
    if (it->second.whole) return it->second.whole.get();
    return part < it->second.parts.size() ? it->second.parts[part].get() : nullptr;
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

// A lower bound of the distance from the eye to a resident node's geometry, measured by its
// format (DatasetFormat::data_distance). Distances are 1-Lipschitz in the eye, so an earlier
// measure minus how far the eye moved since is still a lower bound; the node is measured again
// only when the eye moved more than a tenth of that distance.
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
    // The nearest of its resident parts' geometry (or of the whole node's).
    std::optional<double> distance;
    auto measure = [&](const DecodedNode& d) {
        std::optional<double> m = format_->data_distance(node, d, eye);
        if (m && (!distance || *m < *distance)) distance = m;
    };
    if (it->second.whole) measure(*it->second.whole);
    for (const auto& part : it->second.parts)
        if (part) measure(*part);
    if (!distance) return 0;
    distances_[node] = {eye, *distance};
    return *distance;
}

void StreamingSession::integrate(std::vector<FetchedNode>& arrived) {
    for (FetchedNode& f : arrived) {
        supplied_.erase(f.id);
        from_first_request_.erase(f.id);
        if (!f.ok || !f.decoded || f.node == kNoNode) {
            // Failed every attempt: recorded once (the fetcher retries it later if still wanted).
            if (!f.ok && f.node != kNoNode) residency_->set_failed(f.node, true);
            if (!f.ok && f.node != kNoNode && failed_keys_.insert(f.key).second) {
                std::string error = f.error, prefix = "node " + std::to_string(f.key) + ": ";
                if (error.rfind(prefix, 0) == 0) error.erase(0, prefix.size());  // the key is said once
                failures_.push_back({f.key, hierarchy().node(f.node).level, error});
            }
            continue;
        }
        failed_keys_.erase(f.key);
        residency_->set_failed(f.node, false);
        const HierarchyNode& n = hierarchy().node(f.node);
        if (f.compressed) compressed_->insert(f.id, f.compressed, f.compressed->size());
        const DecodedNode& decoded = *f.decoded;
        if (f.part == kWholeNode) {
            renderer_->upload(n, decoded);
            counter_->set_counts(f.node, decoded.part_primitives.data(), decoded.part_primitives.size());
            residency_->set_resident(f.node, decoded.bytes, decoded.data_bounds);
            decoded_[f.node] = NodeData{f.decoded, {}};
            continue;
        }
        if (f.part >= n.parts.size() || decoded.part_primitives.size() != n.parts.size()) continue;
        NodeData& data = decoded_[f.node];
        if (data.whole) continue;  // the whole node arrived meanwhile
        renderer_->upload(n, decoded);
        counter_->set_part_count(f.node, f.part, decoded.part_primitives[f.part]);
        residency_->set_part_resident(f.node, f.part, decoded.bytes, decoded.data_bounds);
        data.parts.resize(n.parts.size());
        data.parts[f.part] = f.decoded;
        distances_.erase(f.node);
    }
}

SessionFrameStats StreamingSession::step(const Camera& camera) {
    std::vector<FetchedNode> arrived;
    fetcher_->poll(arrived);
    integrate(arrived);

    Camera cam = camera;
    if (!cam.has_clip_planes()) {
        const Aabb bounds = format_->world_bounds();
        cam.fit_clip_planes({bounds.min[0], bounds.min[1], bounds.min[2]}, {bounds.max[0], bounds.max[1], bounds.max[2]});
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
    const Hierarchy& h = hierarchy();
    auto want = [&](const FetchRequest& fetch) {
        if (supplied_.count(fetch.id)) {
            // Bytes of the first request stay wanted while they are decoded: if they are bad, the
            // fetcher fetches the node instead (a supplied node nobody wants is dropped).
            if (from_first_request_.count(fetch.id)) wanted.push_back(fetch);
            return;
        }
        if (const auto* bytes = compressed_->get(fetch.id)) {  // evicted earlier: decode again, no fetch
            fetcher_->supply(fetch, *bytes);
            supplied_.insert(fetch.id);
            return;
        }
        // Brought by the first request: decoded from those bytes (checked as a transfer's are).
        if (fetch.offset >= first_nodes_offset_ && fetch.offset - first_nodes_offset_ + fetch.size <= first_nodes_.size()) {
            const auto begin = first_nodes_.begin() + ptrdiff_t(fetch.offset - first_nodes_offset_);
            fetcher_->supply(fetch, std::make_shared<const std::vector<uint8_t>>(begin, begin + ptrdiff_t(fetch.size)));
            supplied_.insert(fetch.id);
            from_first_request_.insert(fetch.id);
        }
        wanted.push_back(fetch);
    };
    for (const CutRequest& r : frame.requests) {
        const HierarchyNode& n = h.node(r.node);
        if (n.decode_parent != kNoNode) {
            // Decodable only with its parent's decoded data: wanted while the parent is resident
            // (always, in practice: the engine refines from drawn nodes and never skips levels
            // in such a hierarchy); else it waits, never decoded wrongly.
            auto parent = decoded_.find(n.decode_parent);
            if (parent == decoded_.end() || !parent->second.whole) continue;
            FetchRequest fetch = FetchRequest::of(n);
            fetch.decode_parent = parent->second.whole;
            want(fetch);
            continue;
        }
        if (!n.fetch_parts || !settings_.fetch_parts) {
            want(FetchRequest::of(n));
            continue;
        }
        // The parts the request's parent creates (a root's: those of no parent).
        for (size_t i = 0; i < n.parts.size(); ++i)
            if (n.parts[i].parent == r.parent && !residency_->part_resident(r.node, i)) want(FetchRequest::of_part(n, i));
    }
    fetcher_->request(wanted);

    // Keep the cut's parts on the GPU; evict least recently used others past the budget.
    renderer_->begin_frame();
    renderer_->unpin_all();
    for (uint32_t node : engine_->pinned()) {
        const HierarchyNode& n = h.node(node);
        for (const HierarchyPart& part : n.parts)
            if (renderer_->resident(n.key, part.id)) renderer_->pin(n.key, part.id);
    }
    items_.clear();
    for (uint32_t node : engine_->drawn_nodes()) {
        const HierarchyNode& n = h.node(node);
        if (!n.has_data) continue;
        for (const HierarchyPart& part : n.parts) {
            bool parent_refined = part.parent == kNoNode || engine_->refined(part.parent);
            if (parent_refined && renderer_->resident(n.key, part.id)) {
                items_.push_back({n.key, part.id});
                renderer_->mark_used(n.key, part.id);
            }
        }
    }
    renderer_->evict_to_budget();

    FetcherStats fs = fetcher_->stats();
    SessionFrameStats s;
    s.triangles = frame.stats.primitives;
    s.drawn_nodes = frame.stats.drawn_nodes;
    s.refined_nodes = frame.stats.refined_nodes;
    s.fragments = items_.size();
    s.bytes_fetched = prefix_bytes_ + fs.bytes_fetched;
    s.requests = fs.transfers;
    s.pending = frame.requests.size();
    s.gpu_bytes = renderer_->gpu_bytes();
    s.cpu_bytes = frame.stats.cpu_bytes + compressed_->bytes() + first_nodes_.size();
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
    return renderer_->draw(camera, items_, render);
}

const DecodedNode* StreamingSession::decoded(uint64_t key, uint8_t part) const {
    const uint32_t node = hierarchy().find(key);
    if (node == kNoNode) return nullptr;
    const std::vector<HierarchyPart>& parts = hierarchy().node(node).parts;
    for (size_t i = 0; i < parts.size(); ++i)
        if (parts[i].id == part) return decoded_part(node, i);
    return nullptr;
}

DrawnGeometry StreamingSession::drawn_geometry(const std::array<double, 3>& eye) const {
    std::vector<DecodedPart> parts;
    parts.reserve(items_.size());
    for (const DrawnPart& item : items_)
        if (const DecodedNode* d = decoded(item.key, item.part)) parts.push_back({hierarchy().find(item.key), d, item.part});
    return format_->drawn_geometry(parts, eye);
}

}  // namespace catpaq
