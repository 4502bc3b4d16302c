#include "client/cut_engine.h"

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>

#include "base/error.h"

namespace catpaq {

// ---------------------------------------------------------------------------------------------
// ViewParams

double ViewParams::k() const {
    if (pixels_per_unit > 0) return pixels_per_unit;
    assert(viewport_height > 0 && fov_y_radians > 0 && fov_y_radians < M_PI);
    if (!(viewport_height > 0 && fov_y_radians > 0 && fov_y_radians < M_PI)) return 1.0;
    return viewport_height / (2.0 * std::tan(fov_y_radians / 2.0));
}

namespace {

using Vec3 = std::array<double, 3>;

Vec3 sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Vec3 cross(const Vec3& a, const Vec3& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
Vec3 scale(const Vec3& a, double s) { return {a[0] * s, a[1] * s, a[2] * s}; }
Vec3 add(const Vec3& a, const Vec3& b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
Vec3 normalize(const Vec3& a) {
    double l = std::sqrt(dot(a, a));
    return l > 0 ? scale(a, 1.0 / l) : a;
}

std::array<double, 4> normalized_plane(std::array<double, 4> p) {
    double l = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    if (l > 0)
        for (double& v : p) v /= l;
    return p;
}

std::array<double, 4> plane_through(const Vec3& normal, const Vec3& point) {
    return normalized_plane({normal[0], normal[1], normal[2], -dot(normal, point)});
}

}  // namespace

std::array<std::array<double, 4>, 6> ViewParams::planes_from_view_projection(const std::array<double, 16>& m) {
    auto row = [&](int i) { return std::array<double, 4>{m[i], m[4 + i], m[8 + i], m[12 + i]}; };
    std::array<double, 4> r0 = row(0), r1 = row(1), r2 = row(2), r3 = row(3);
    std::array<std::array<double, 4>, 6> out;
    for (int j = 0; j < 4; ++j) {
        out[0][j] = r3[j] + r0[j];
        out[1][j] = r3[j] - r0[j];
        out[2][j] = r3[j] + r1[j];
        out[3][j] = r3[j] - r1[j];
        out[4][j] = r3[j] + r2[j];
        out[5][j] = r3[j] - r2[j];
    }
    for (auto& p : out) p = normalized_plane(p);
    return out;
}

ViewParams ViewParams::look_at(const std::array<double, 3>& eye, const std::array<double, 3>& target,
                               const std::array<double, 3>& up, double fov_y_radians, int width, int height,
                               double near, double far) {
    ViewParams v;
    v.eye = eye;
    v.viewport_height = height;
    v.fov_y_radians = fov_y_radians;
    v.near = near;
    Vec3 f = normalize(sub(target, eye));
    Vec3 r = normalize(cross(f, up));
    Vec3 u = cross(r, f);
    double ty = std::tan(fov_y_radians / 2.0);
    double tx = ty * double(width) / double(height);
    v.planes[0] = plane_through(add(scale(f, tx), r), eye);   // left:  z tx + x >= 0
    v.planes[1] = plane_through(sub(scale(f, tx), r), eye);   // right: z tx - x >= 0
    v.planes[2] = plane_through(add(scale(f, ty), u), eye);   // bottom
    v.planes[3] = plane_through(sub(scale(f, ty), u), eye);   // top
    v.planes[4] = plane_through(f, add(eye, scale(f, near)));             // near
    v.planes[5] = plane_through(scale(f, -1.0), add(eye, scale(f, far)));  // far
    return v;
}

bool ViewParams::may_see(const Aabb& box, double grow) const {
    if (box.empty()) return false;
    if (!use_frustum) return true;
    for (const auto& p : planes) {
        double x = p[0] >= 0 ? box.max[0] + grow : box.min[0] - grow;
        double y = p[1] >= 0 ? box.max[1] + grow : box.min[1] - grow;
        double z = p[2] >= 0 ? box.max[2] + grow : box.min[2] - grow;
        if (p[0] * x + p[1] * y + p[2] * z + p[3] < 0) return false;
    }
    return true;
}

// ---------------------------------------------------------------------------------------------
// Draw counts and residency

PartDrawCounter::PartDrawCounter(const Hierarchy& hierarchy) {
    offsets_.resize(hierarchy.size() + 1);
    uint32_t total = 0;
    for (uint32_t n = 0; n < hierarchy.size(); ++n) {
        offsets_[n] = total;
        total += uint32_t(hierarchy.node(n).parts.size());
    }
    offsets_[hierarchy.size()] = total;
    counts_.resize(total);
    parents_.resize(total);
    for (uint32_t n = 0; n < hierarchy.size(); ++n) {
        const auto& parts = hierarchy.node(n).parts;
        for (size_t p = 0; p < parts.size(); ++p) {
            counts_[offsets_[n] + p] = parts[p].primitives;
            parents_[offsets_[n] + p] = parts[p].parent;
        }
    }
}

uint64_t PartDrawCounter::count(uint32_t node, const RefinedView& refined) const {
    uint64_t sum = 0;
    for (uint32_t p = offsets_[node], e = offsets_[node + 1]; p < e; ++p)
        if (refined(parents_[p])) sum += counts_[p];
    return sum;
}

bool ChangeLog::since(uint64_t& cursor, std::vector<uint32_t>& out) const {
    if (cursor > seq_ || seq_ - cursor > ring_.size()) {
        cursor = seq_;
        return false;
    }
    for (uint64_t i = cursor; i < seq_; ++i) out.push_back(ring_[size_t(i % ring_.size())]);
    cursor = seq_;
    return true;
}

void PartDrawCounter::set_counts(uint32_t node, const uint32_t* counts, size_t n) {
    assert(n == offsets_[node + 1] - offsets_[node]);
    size_t m = std::min<size_t>(n, offsets_[node + 1] - offsets_[node]);
    std::copy(counts, counts + m, counts_.begin() + offsets_[node]);
}

PartResidency::PartResidency(const Hierarchy& hierarchy)
    : hierarchy_(hierarchy),
      mask_(hierarchy.size(), 0),
      full_(hierarchy.size(), 0),
      whole_(hierarchy.size(), 0),
      part_off_(hierarchy.size() + 1, 0),
      bytes_(hierarchy.size()),
      data_(hierarchy.size()) {
    uint32_t total = 0;
    for (uint32_t n = 0; n < hierarchy.size(); ++n) {
        part_off_[n] = total;
        const size_t parts = hierarchy.node(n).parts.size();
        total += uint32_t(parts);
        full_[n] = parts >= 32 ? ~0u : (1u << parts) - 1u;
    }
    part_off_[hierarchy.size()] = total;
    part_bytes_.resize(total);
    part_data_.resize(total);
}

void PartResidency::set_node(uint32_t node, NodeBytes bytes, const Aabb& data) {
    if (!whole_[node]) ++count_;
    mask_[node] = full_[node];
    whole_[node] = 1;
    for (uint32_t i = part_off_[node]; i < part_off_[node + 1]; ++i) {
        part_bytes_[i] = {};
        part_data_[i] = Aabb{};
    }
    bytes_[node] = bytes;
    data_[node] = data;
}

void PartResidency::clear_node(uint32_t node) {
    if (whole_[node]) --count_;
    mask_[node] = 0;
    whole_[node] = 0;
    for (uint32_t i = part_off_[node]; i < part_off_[node + 1]; ++i) {
        part_bytes_[i] = {};
        part_data_[i] = Aabb{};
    }
    bytes_[node] = {};
    data_[node] = Aabb{};
}

void PartResidency::set_part(uint32_t node, size_t part, NodeBytes bytes, const Aabb& data) {
    assert(hierarchy_.node(node).fetch_parts && part < hierarchy_.node(node).parts.size());
    mask_[node] |= 1u << part;
    part_bytes_[part_off_[node] + part] = bytes;
    part_data_[part_off_[node] + part] = data;
    total(node);
}

void PartResidency::clear_part(uint32_t node, size_t part) {
    mask_[node] &= ~(1u << part);
    part_bytes_[part_off_[node] + part] = {};
    part_data_[part_off_[node] + part] = Aabb{};
    total(node);
}

// A node fetched by parts: its totals over the resident parts.
void PartResidency::total(uint32_t node) {
    const bool all = mask_[node] == full_[node];
    if (all != bool(whole_[node])) count_ += all ? 1 : size_t(-1);
    whole_[node] = all;
    NodeBytes b;
    Aabb box;
    for (uint32_t i = part_off_[node], k = 0; i < part_off_[node + 1]; ++i, ++k) {
        if (!((mask_[node] >> k) & 1u)) continue;
        b.gpu += part_bytes_[i].gpu;
        b.cpu += part_bytes_[i].cpu;
        box.extend(part_data_[i]);
    }
    bytes_[node] = b;
    data_[node] = box;
}

bool PartResidency::ready(uint32_t node, uint32_t parent) const {
    const HierarchyNode& n = hierarchy_.node(node);
    if (!n.fetch_parts || whole_[node]) return whole_[node] != 0;
    for (size_t k = 0; k < n.parts.size(); ++k)
        if (n.parts[k].parent == parent && !((mask_[node] >> k) & 1u)) return false;
    return true;
}

ResidencyTable::ResidencyTable(const Hierarchy& hierarchy, double bytes_per_primitive)
    : hierarchy_(hierarchy), bytes_per_primitive_(bytes_per_primitive), parts_(hierarchy), failed_(hierarchy.size(), 0) {}

NodeBytes ResidencyTable::bytes(uint32_t node) const {
    if (parts_.any(node)) return parts_.bytes(node);
    const HierarchyNode& n = hierarchy_.node(node);
    if (!n.has_data) return {};
    uint64_t estimate = uint64_t(std::ceil(double(n.primitives) * bytes_per_primitive_));
    return {estimate, estimate};
}

void ResidencyTable::set_resident(uint32_t node, NodeBytes bytes, const Aabb& data) {
    parts_.set_node(node, bytes, data);
    log_.add(node);
}

void ResidencyTable::set_evicted(uint32_t node) {
    parts_.clear_node(node);
    log_.add(node);
}

void ResidencyTable::set_part_resident(uint32_t node, size_t part, NodeBytes bytes, const Aabb& data) {
    parts_.set_part(node, part, bytes, data);
    log_.add(node);
}

void ResidencyTable::set_part_evicted(uint32_t node, size_t part) {
    parts_.clear_part(node, part);
    log_.add(node);
}

// ---------------------------------------------------------------------------------------------
// CutEngine: bookkeeping

void CutEngine::DenseSet::insert(uint32_t n) {
    if (pos[n] != kNoNode) return;
    pos[n] = uint32_t(items.size());
    items.push_back(n);
}

void CutEngine::DenseSet::erase(uint32_t n) {
    uint32_t i = pos[n];
    if (i == kNoNode) return;
    uint32_t last = items.back();
    items[i] = last;
    pos[last] = i;
    items.pop_back();
    pos[n] = kNoNode;
}

CutEngine::CutEngine(const Hierarchy& hierarchy, const DrawCounter& counter, CutBudgets budgets)
    : h_(hierarchy), counter_(counter), budgets_(budgets) {
    size_t n = h_.size();
    par_off_.resize(n + 1);
    ch_off_.resize(n + 1);
    box_off_.resize(n + 1);
    box_width_.resize(n);
    error_.resize(n);
    flags_.resize(n);
    level_.resize(n);
    for (uint32_t i = 0; i < n; ++i) {
        const HierarchyNode& node = h_.node(i);
        par_off_[i] = uint32_t(par_.size());
        par_.insert(par_.end(), node.parents.begin(), node.parents.end());
        ch_off_[i] = uint32_t(ch_.size());
        ch_.insert(ch_.end(), node.children.begin(), node.children.end());
        box_off_[i] = uint32_t(box_.size());
        Aabb all;
        for (const Aabb& b : h_.has_view_boxes() ? node.view_boxes : std::vector<Aabb>{node.bounds})
            if (!b.empty()) {
                box_.push_back({b.min[0], b.min[1], b.min[2], b.max[0], b.max[1], b.max[2]});
                all.extend(b);
            }
        box_width_[i] = all.empty() ? 0.0 : std::max({all.max[0] - all.min[0], all.max[1] - all.min[1], all.max[2] - all.min[2]});
        error_[i] = node.error;
        flags_[i] = uint8_t((node.has_data ? 1 : 0) | (node.leaf ? 2 : 0) | (node.has_data && node.fetch_parts ? 4 : 0));
        level_[i] = node.level;
    }
    par_off_[n] = uint32_t(par_.size());
    ch_off_[n] = uint32_t(ch_.size());
    box_off_[n] = uint32_t(box_.size());
    units_from_edges_ = uint32_t(par_.size());
    unit_node_.resize(par_.size() + n);
    unit_parent_.resize(par_.size() + n);
    for (uint32_t i = 0; i < n; ++i) {
        for (uint32_t e = par_off_[i]; e < par_off_[i + 1]; ++e) {
            unit_node_[e] = i;
            unit_parent_[e] = par_[e];
        }
        unit_node_[units_from_edges_ + i] = i;
        unit_parent_[units_from_edges_ + i] = kNoNode;
    }
    reset();
}

void CutEngine::reset() {
    size_t n = h_.size();
    refined_.assign(n, 0);
    refined_parents_.assign(n, 0);
    refined_children_.assign(n, 0);
    active_.items.clear();
    active_.pos.assign(n, kNoNode);
    frontier_.items.clear();
    frontier_.pos.assign(n, kNoNode);
    c_prim_.assign(n, 0);
    c_gpu_.assign(n, 0);
    c_cpu_.assign(n, 0);
    totals_ = {};
    refined_count_ = 0;
    proj_.assign(n, 0);
    keep_proj_.assign(n, 0);
    visible_.assign(n, 0);
    proj_frame_.assign(n, 0);
    mark_.assign(n, 0);
    stamp_ = 0;
    const size_t units = unit_node_.size();
    want_.assign(units, {});
    want_frame_.assign(units, 0);
    wanted_.clear();
    outstanding_.assign(units, 0);
    outstanding_list_.clear();
    // The roots are drawn; their counts are filled by the first update's recount.
    for (uint32_t r : h_.roots()) active_.insert(r);
    frame_ = {};
    full_refresh_ = true;
}

bool CutEngine::is_active(uint32_t n) const {
    return !refined_[n] && (par_off_[n] == par_off_[n + 1] || refined_parents_[n] > 0);
}

bool CutEngine::drawable(uint32_t n) const {
    if (!has_data(n)) return true;
    if (par_off_[n] == par_off_[n + 1]) return ready(n, kNoNode);
    for (uint32_t p : parents(n))
        if (refined_[p] && !ready(n, p)) return false;
    return true;
}

uint32_t CutEngine::unit_of(uint32_t n, uint32_t parent) const {
    if ((flags_[n] & 4) && parent != kNoNode)
        for (uint32_t e = par_off_[n]; e < par_off_[n + 1]; ++e)
            if (par_[e] == parent) return e;
    return units_from_edges_ + n;
}

bool CutEngine::drawn(uint32_t node) const { return active_.contains(node); }

namespace {

// ViewParams::may_see on a compact box (min xyz, max xyz); the box is never empty here.
inline bool box_visible(const ViewParams& v, const std::array<double, 6>& b, double grow) {
    if (!v.use_frustum) return true;
    for (const auto& p : v.planes) {
        double x = p[0] >= 0 ? b[3] + grow : b[0] - grow;
        double y = p[1] >= 0 ? b[4] + grow : b[1] - grow;
        double z = p[2] >= 0 ? b[5] + grow : b[2] - grow;
        if (p[0] * x + p[1] * y + p[2] * z + p[3] < 0) return false;
    }
    return true;
}

inline double box_distance(const std::array<double, 6>& b, const std::array<double, 3>& e) {
    double d2 = 0;
    for (int i = 0; i < 3; ++i) {
        double d = e[i] < b[i] ? b[i] - e[i] : (e[i] > b[i + 3] ? e[i] - b[i + 3] : 0.0);
        d2 += d * d;
    }
    return std::sqrt(d2);
}

}  // namespace

double projected_error_px(double error, double distance, double k) {
    if (!(error > 0)) return 0;
    return error < distance ? k * std::asin(error / distance) : k * M_PI;
}

double CutEngine::proj(uint32_t n) {
    if (proj_frame_[n] == frame_number_) return proj_[n];
    proj_frame_[n] = frame_number_;
    // The nearest box in the frustum sets the projected error; the nearest within the grown
    // frustum (visibility hysteresis) the one coarsening decisions keep. No box: nothing to see.
    constexpr double kFar = std::numeric_limits<double>::infinity();
    double nearest = kFar, nearest_kept = kFar;
    for (uint32_t b = box_off_[n]; b < box_off_[n + 1]; ++b) {
        const std::array<double, 6>& box = box_[b];
        const double distance = box_distance(box, view_.eye);
        if (distance >= nearest) continue;  // improves neither (nearest_kept <= nearest)
        if (box_visible(view_, box, 0)) {
            nearest = distance;
            nearest_kept = std::min(nearest_kept, distance);
        } else if (distance < nearest_kept && view_.frustum_margin > 0 &&
                   box_visible(view_, box, view_.frustum_margin * distance)) {
            nearest_kept = distance;
        }
    }
    double wide = box_width_[n];
    // Where the residency knows the box of the node's decoded data, it is another lower bound of
    // the distance to the geometry (and of what can be seen).
    if (nearest_kept < kFar && has_data(n) && residency_)
        if (const Aabb* data = residency_->data_bounds(n)) {
            const std::array<double, 6> box = {data->min[0], data->min[1], data->min[2], data->max[0], data->max[1], data->max[2]};
            const double distance = box_distance(box, view_.eye);
            if (!box_visible(view_, box, 0)) nearest = kFar;
            if (!(view_.frustum_margin > 0 ? box_visible(view_, box, view_.frustum_margin * distance) : box_visible(view_, box, 0)))
                nearest_kept = kFar;
            nearest = nearest < kFar ? std::max(nearest, distance) : kFar;
            nearest_kept = nearest_kept < kFar ? std::max(nearest_kept, distance) : kFar;
            wide = std::max({box[3] - box[0], box[4] - box[1], box[5] - box[2]});
        }
    // Up close the box says little (the eye may be inside it, far from any triangle).
    if (has_data(n) && residency_ && nearest_kept < wide) {
        const double triangles = residency_->data_distance(n, view_.eye);
        if (nearest < kFar) nearest = std::max(nearest, triangles);
        nearest_kept = std::max(nearest_kept, triangles);
    }
    visible_[n] = nearest < kFar;
    proj_[n] = nearest < kFar ? projected_error_px(error_[n], nearest, k_) : 0.0;
    keep_proj_[n] = nearest_kept < kFar ? projected_error_px(error_[n], nearest_kept, k_) : 0.0;
    return proj_[n];
}

double CutEngine::keep_proj(uint32_t n) {
    proj(n);
    return keep_proj_[n];
}

bool CutEngine::in_view(uint32_t n) {
    proj(n);
    return visible_[n] != 0;
}

double CutEngine::projected_error(uint32_t node) const {
    if (frame_number_ == 0) return 0;
    if (proj_frame_[node] == frame_number_) return proj_[node];
    double nearest = std::numeric_limits<double>::infinity();
    for (uint32_t b = box_off_[node]; b < box_off_[node + 1]; ++b)
        if (box_visible(view_, box_[b], 0)) nearest = std::min(nearest, box_distance(box_[b], view_.eye));
    return std::isfinite(nearest) ? projected_error_px(error_[node], nearest, view_.k()) : 0.0;
}

void CutEngine::recount(uint32_t n) {
    bool act = is_active(n), fr = is_frontier(n);
    uint64_t p = 0, g = 0, c = 0;
    if (act) p = counter_.count(n, RefinedView{refined_.data()});
    if (has_data(n) && (act || fr)) {
        NodeBytes b = residency_->bytes(n);
        if (act) g = b.gpu;
        c = b.cpu;
    }
    totals_.primitives += p - c_prim_[n];
    totals_.gpu += g - c_gpu_[n];
    totals_.cpu += c - c_cpu_[n];
    c_prim_[n] = p;
    c_gpu_[n] = g;
    c_cpu_[n] = c;
    if (act) active_.insert(n);
    else active_.erase(n);
    if (fr) frontier_.insert(n);
    else frontier_.erase(n);
}

void CutEngine::set_refined(uint32_t n, bool on, std::vector<Op>* log) {
    assert(bool(refined_[n]) != on);
    refined_[n] = on;
    refined_count_ += on ? 1 : size_t(-1);
    for (uint32_t c : children(n)) refined_parents_[c] += on ? 1u : uint32_t(-1);
    for (uint32_t p : parents(n)) refined_children_[p] += on ? 1u : uint32_t(-1);
    recount(n);
    for (uint32_t c : children(n)) recount(c);
    for (uint32_t p : parents(n)) recount(p);
    if (log) log->push_back({n, on});
}

void CutEngine::revert(std::vector<Op>& log, size_t to) {
    while (log.size() > to) {
        Op op = log.back();
        log.pop_back();
        set_refined(op.node, !op.refine, nullptr);
    }
}

bool CutEngine::fits(const Totals& before) const {
    // A resource may stay above its budget only if it did not grow (budgets lowered, or a cut
    // that cannot be coarsened further): never make an excess appear or grow.
    auto ok = [](uint64_t now, uint64_t was, uint64_t budget) { return now <= budget || now <= was; };
    return ok(totals_.primitives, before.primitives, budgets_.max_primitives) &&
           ok(totals_.gpu, before.gpu, budgets_.max_gpu_bytes) && ok(totals_.cpu, before.cpu, budgets_.max_cpu_bytes);
}

bool CutEngine::exceeds() const {
    return totals_.primitives > budgets_.max_primitives || totals_.gpu > budgets_.max_gpu_bytes ||
           totals_.cpu > budgets_.max_cpu_bytes;
}

void CutEngine::closure(uint32_t n, std::vector<uint32_t>& out) {
    out.clear();
    if (++stamp_ == 0) {
        std::fill(mark_.begin(), mark_.end(), 0);
        stamp_ = 1;
    }
    add_closure(n, out);
}

void CutEngine::add_closure(uint32_t n, std::vector<uint32_t>& out) {
    // Parents first (iterative depth-first), so applying `out` in order keeps R closed.
    std::vector<uint32_t>& stack = stack_;
    stack.clear();
    stack.push_back(n);
    while (!stack.empty()) {
        uint32_t d = stack.back();
        if (mark_[d] == stamp_) {
            stack.pop_back();
            continue;
        }
        bool ready = true;
        for (uint32_t p : parents(d))
            if (!refined_[p] && mark_[p] != stamp_) {
                stack.push_back(p);
                ready = false;
            }
        if (ready) {
            mark_[d] = stamp_;
            out.push_back(d);
            stack.pop_back();
        }
    }
}

void CutEngine::want(uint32_t n, uint32_t parent, RequestReason reason, double priority) {
    const uint32_t u = unit_of(n, parent);
    if (want_frame_[u] != frame_number_) {
        want_frame_[u] = frame_number_;
        want_[u] = {reason, priority};
        wanted_.push_back(u);
        return;
    }
    Want& w = want_[u];
    if (reason < w.reason || (reason == w.reason && priority > w.priority)) w = {reason, priority};
}

void CutEngine::want_drawable(uint32_t n, RequestReason reason, double priority) {
    if (par_off_[n] == par_off_[n + 1]) {
        if (!ready(n, kNoNode)) want(n, kNoNode, reason, priority);
        return;
    }
    for (uint32_t p : parents(n))
        if (refined_[p] && !ready(n, p)) want(n, p, reason, priority);
}

// ---------------------------------------------------------------------------------------------
// CutEngine: the frame

void CutEngine::coarsen_phase() {
    double threshold = view_.tolerance_px * view_.hysteresis;
    std::vector<uint32_t> work = frontier_.items;
    std::vector<Op> log;
    for (size_t i = 0; i < work.size(); ++i) {
        uint32_t n = work[i];
        if (!is_frontier(n)) continue;
        // A virtual node is in R only for its refined children's sake: once it has none, it goes.
        double e = has_data(n) ? keep_proj(n) : 0.0;
        if (e >= threshold) continue;
        if (!try_coarsen(n, log)) continue;
        for (uint32_t p : parents(n))
            if (is_frontier(p)) work.push_back(p);
    }
}

// Coarsens frontier node n if its data is resident (it is drawn again) and the budgets still
// hold; a node that is not resident is requested instead (only if the viewer can see it).
bool CutEngine::try_coarsen(uint32_t n, std::vector<Op>& log) {
    if (!drawable(n)) {  // its parents are all refined: it would draw every part
        if (in_view(n)) want_drawable(n, RequestReason::Coarsen, proj(n));
        return false;
    }
    Totals before = totals_;
    log.clear();
    set_refined(n, false, &log);
    if (!fits(before)) {
        revert(log, 0);
        return false;
    }
    frame_.stats.coarsenings++;
    return true;
}

void CutEngine::enforce_budgets() {
    if (!exceeds()) return;
    using Entry = std::pair<double, uint32_t>;
    std::vector<Entry> heap;
    for (uint32_t n : frontier_.items) heap.push_back({keep_proj(n), n});
    auto cmp = [](const Entry& a, const Entry& b) { return a.first > b.first; };  // min-heap
    std::make_heap(heap.begin(), heap.end(), cmp);
    std::vector<Op> log;
    while (exceeds() && !heap.empty()) {
        std::pop_heap(heap.begin(), heap.end(), cmp);
        uint32_t n = heap.back().second;
        heap.pop_back();
        if (!is_frontier(n)) continue;
        if (!try_coarsen(n, log)) continue;
        for (uint32_t p : parents(n))
            if (is_frontier(p)) {
                heap.push_back({keep_proj(p), p});
                std::push_heap(heap.begin(), heap.end(), cmp);
            }
    }
}

// Coarsens frontier nodes with projected error below `limit`, lowest first, until the totals
// fit the budgets again (relative to `before`). Every change is appended to `log`; the caller
// reverts on failure. Returns whether the totals fit.
bool CutEngine::make_room(double limit, std::vector<Op>& log, const Totals& before) {
    using Entry = std::pair<double, uint32_t>;
    auto cmp = [](const Entry& a, const Entry& b) { return a.first > b.first; };
    if (!room_heap_built_) {
        room_heap_.clear();
        for (uint32_t n : frontier_.items) room_heap_.push_back({keep_proj(n), n});
        std::make_heap(room_heap_.begin(), room_heap_.end(), cmp);
        room_heap_built_ = true;
    }
    std::vector<Entry> popped;
    bool ok = false;
    while (!room_heap_.empty() && room_heap_.front().first < limit) {
        std::pop_heap(room_heap_.begin(), room_heap_.end(), cmp);
        Entry top = room_heap_.back();
        room_heap_.pop_back();
        popped.push_back(top);
        uint32_t f = top.second;
        if (!is_frontier(f) || !drawable(f)) continue;
        Totals b = totals_;
        size_t mark = log.size();
        set_refined(f, false, &log);
        // A coarsening that makes an exceeded resource grow does not help.
        bool helps = !((totals_.primitives > budgets_.max_primitives && totals_.primitives > b.primitives) ||
                       (totals_.gpu > budgets_.max_gpu_bytes && totals_.gpu > b.gpu) ||
                       (totals_.cpu > budgets_.max_cpu_bytes && totals_.cpu > b.cpu));
        if (!helps) {
            revert(log, mark);
            continue;
        }
        for (uint32_t p : parents(f))
            if (is_frontier(p)) {
                room_heap_.push_back({keep_proj(p), p});
                std::push_heap(room_heap_.begin(), room_heap_.end(), cmp);
            }
        if (fits(before)) {
            ok = true;
            break;
        }
    }
    // Entries are validated when popped, so putting every popped one back is always safe: the
    // caller may revert, and skipped nodes (not resident) stay candidates.
    for (const Entry& e : popped) {
        room_heap_.push_back(e);
        std::push_heap(room_heap_.begin(), room_heap_.end(), cmp);
    }
    return ok;
}

void CutEngine::refine_phase() {
    struct Candidate {
        double e;
        uint16_t level;
        uint32_t n;
    };
    auto less = [](const Candidate& a, const Candidate& b) {
        if (a.e != b.e) return a.e < b.e;
        if (a.level != b.level) return a.level > b.level;
        return a.n > b.n;
    };
    double tol = view_.tolerance_px;
    // A hierarchy whose nodes decode against their parents is never skipped through: a skipped
    // node would not be decoded, and its children could not be (HierarchyNode::decode_parent).
    const double skip_limit = view_.skip_factor > 1 && !h_.decodes_against_parents() ? tol * view_.skip_factor : tol;
    std::vector<Candidate> heap;
    // Virtual nodes draw nothing: refining one for its own sake gains nothing, so they are
    // refined only as ancestors a refinement needs (closure).
    for (uint32_t n : active_.items) {
        if (leaf(n) || !has_data(n)) continue;
        double e = proj(n);
        if (e > tol) heap.push_back({e, level_[n], n});
    }
    std::make_heap(heap.begin(), heap.end(), less);
    std::vector<uint32_t> closure_set;
    std::vector<std::pair<uint32_t, uint32_t>> missing;  // (child, the refined parent it needs data for)
    std::vector<Op> log;
    while (!heap.empty()) {
        std::pop_heap(heap.begin(), heap.end(), less);
        Candidate cand = heap.back();
        heap.pop_back();
        uint32_t n = cand.n;
        if (!is_active(n)) continue;
        // The nodes to refine: n and its closure, and with skipping, missing children close to
        // the tolerance (refined at once instead of fetched) with theirs; `missing` gets the
        // children that would be drawn without data. A failed node among them means the skip
        // would wait forever: then n takes one level, as without skipping.
        auto plan = [&](double limit) {
            closure(n, closure_set);
            missing.clear();
            // The set grows while it is scanned: skipped children join it with their closures.
            // Each refined node s needs, of each child c that will be drawn, what c draws under s
            // (what c draws under parents refined earlier is resident: c was drawn).
            for (size_t i = 0; i < closure_set.size(); ++i) {
                const uint32_t s = closure_set[i];
                for (uint32_t c : children(s)) {
                    if (mark_[c] == stamp_ || ready(c, s)) continue;
                    const double e = leaf(c) ? 0.0 : proj(c);
                    if (e > tol && e <= limit)
                        add_closure(c, closure_set);
                    else
                        missing.push_back({c, s});
                }
            }
            // A missing child that joined the set later (a parent of a skipped node) is refined, not drawn.
            missing.erase(std::remove_if(missing.begin(), missing.end(), [&](const auto& m) { return mark_[m.first] == stamp_; }),
                          missing.end());
        };
        plan(skip_limit);
        if (skip_limit > tol &&
            std::any_of(missing.begin(), missing.end(), [&](const auto& m) { return residency_->failed(m.first); }))
            plan(tol);
        bool capped = uint64_t(frame_.stats.refinements) + closure_set.size() > budgets_.max_refinements;
        Totals before = totals_;
        log.clear();
        for (uint32_t s : closure_set) set_refined(s, true, &log);
        bool ok = fits(before);
        if (!ok) ok = make_room(cand.e * view_.hysteresis, log, before);
        if (!ok || !missing.empty() || capped) {
            if (!ok) {  // which budgets the refinement would have passed
                frame_.stats.budgets_binding |= uint8_t((totals_.primitives > budgets_.max_primitives ? kPrimitiveBudget : 0) |
                                                        (totals_.gpu > budgets_.max_gpu_bytes ? kGpuBudget : 0) |
                                                        (totals_.cpu > budgets_.max_cpu_bytes ? kCpuBudget : 0));
            }
            revert(log, 0);
            if (!ok) {
                frame_.stats.budget_blocked++;
            } else if (!missing.empty()) {
                frame_.stats.waiting++;
                for (const auto& [c, s] : missing) {
                    // A child decodable only with its parent's data waits for that parent (wanted
                    // itself while drawn without data); asking for it now would be refused.
                    const uint32_t decode_parent = h_.node(c).decode_parent;
                    if (decode_parent != kNoNode && !residency_->resident(decode_parent)) continue;
                    want(c, s, RequestReason::Refine, cand.e);
                }
            } else {
                frame_.stats.capped++;
            }
            continue;
        }
        for (const Op& op : log) {
            if (op.refine) frame_.stats.refinements++;
            else frame_.stats.coarsenings++;
        }
        for (uint32_t s : closure_set)
            for (uint32_t c : children(s)) {
                if (leaf(c) || !has_data(c) || !is_active(c)) continue;
                double e = proj(c);
                if (e > tol) {
                    heap.push_back({e, level_[c], c});
                    std::push_heap(heap.begin(), heap.end(), less);
                }
            }
    }
}

void CutEngine::emit_requests() {
    CutFrameStats& st = frame_.stats;
    // A hole is a drawn node without its data in the view: one outside the view draws nothing
    // on screen either way, so it neither waits for data nor leaves the error unbounded (AQP
    // has a root per patch: those behind the eye of a close view would otherwise never settle).
    for (uint32_t n : active_.items) {
        if (drawable(n) || !in_view(n)) continue;
        st.holes++;
        want_drawable(n, RequestReason::Drawn, proj(n));
    }
    // The request of a unit: the node, and the parent whose parts it names (kNoNode: the whole
    // node, or a root's parts).
    auto request_of = [&](uint32_t u, RequestReason reason, double priority) {
        const HierarchyNode& node = h_.node(unit_node_[u]);
        return CutRequest{unit_node_[u], node.key, node.level, reason, priority, unit_parent_[u]};
    };
    // Retire finished and stale requests.
    size_t kept = 0;
    for (uint32_t u : outstanding_list_) {
        if (unit_ready(u)) {
            outstanding_[u] = 0;
            continue;
        }
        if (want_frame_[u] != frame_number_) {
            outstanding_[u] = 0;
            frame_.cancelled.push_back(request_of(u, RequestReason::Refine, 0));
            continue;
        }
        outstanding_list_[kept++] = u;
    }
    outstanding_list_.resize(kept);
    std::sort(wanted_.begin(), wanted_.end(), [&](uint32_t a, uint32_t b) {
        const Want& wa = want_[a];
        const Want& wb = want_[b];
        if (wa.reason != wb.reason) return wa.reason < wb.reason;
        if (wa.priority != wb.priority) return wa.priority > wb.priority;
        const HierarchyNode& na = h_.node(unit_node_[a]);
        const HierarchyNode& nb = h_.node(unit_node_[b]);
        if (na.level != nb.level) return na.level < nb.level;
        if (na.key != nb.key) return na.key < nb.key;
        return a < b;
    });
    for (uint32_t u : wanted_) {
        const CutRequest r = request_of(u, want_[u].reason, want_[u].priority);
        if (outstanding_[u]) {
            frame_.requests.push_back(r);
            continue;
        }
        if (st.new_requests >= budgets_.max_new_requests || outstanding_list_.size() >= budgets_.max_outstanding_requests)
            continue;
        outstanding_[u] = 1;
        outstanding_list_.push_back(u);
        st.new_requests++;
        frame_.requests.push_back(r);
    }
}

const CutFrame& CutEngine::update(const ViewParams& view, const Residency& residency) {
    auto start = std::chrono::steady_clock::now();
    view_ = view;
    residency_ = &residency;
    k_ = view.k();
    ++frame_number_;
    frame_.requests.clear();
    frame_.cancelled.clear();
    frame_.drawn.clear();
    frame_.stats = {};
    frame_.stats.frame = frame_number_;
    wanted_.clear();
    room_heap_built_ = false;

    // 1. Residency and exact counts may have changed: recount what changed in the cut (all of
    //    it when the residency cannot tell). Memberships do not change here.
    changed_.clear();
    if (&residency != last_residency_) full_refresh_ = true;
    last_residency_ = &residency;
    if (!residency.changes_since(residency_cursor_, changed_)) full_refresh_ = true;
    if (full_refresh_) {
        for (size_t i = 0; i < active_.items.size(); ++i) recount(active_.items[i]);
        for (size_t i = 0; i < frontier_.items.size(); ++i) recount(frontier_.items[i]);
        full_refresh_ = false;
    } else {
        for (uint32_t n : changed_)
            if (n < refined_.size() && (active_.contains(n) || frontier_.contains(n))) recount(n);
    }

    coarsen_phase();     // 2.
    enforce_budgets();   // 3.
    refine_phase();      // 4.
    emit_requests();     // 5.

    CutFrameStats& st = frame_.stats;
    st.primitives = totals_.primitives;
    st.gpu_bytes = totals_.gpu;
    st.cpu_bytes = totals_.cpu;
    st.drawn_nodes = active_.items.size();
    st.frontier_nodes = frontier_.items.size();
    st.refined_nodes = refined_count_;
    double certified = 0;
    for (uint32_t n : active_.items) {
        if (!has_data(n)) continue;
        double e = proj(n);
        certified = std::max(certified, e);
        st.leaves_over_tolerance += leaf(n) && e > view_.tolerance_px;
    }
    st.certified_error_px = certified;
    st.over_budget = exceeds();
    frame_.drawn = active_.items;
    residency_ = nullptr;
    st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return frame_;
}

std::vector<uint32_t> CutEngine::refined_nodes() const {
    std::vector<uint32_t> out;
    for (uint32_t n = 0; n < refined_.size(); ++n)
        if (refined_[n]) out.push_back(n);
    return out;
}

std::vector<uint32_t> CutEngine::pinned() const {
    std::vector<uint32_t> out;
    for (uint32_t n : active_.items)
        if (has_data(n)) out.push_back(n);
    for (uint32_t n : frontier_.items)
        if (has_data(n)) out.push_back(n);
    return out;
}

std::string CutEngine::check(const Residency& residency) const {
    size_t n = h_.size();
    Totals t;
    size_t active = 0, frontier = 0;
    for (uint32_t i = 0; i < n; ++i) {
        const HierarchyNode& node = h_.node(i);
        uint32_t rp = 0, rc = 0;
        for (uint32_t p : node.parents) rp += refined_[p];
        for (uint32_t c : node.children) rc += refined_[c];
        if (rp != refined_parents_[i] || rc != refined_children_[i])
            return strprintf("node %u: refined neighbour counts are stale", i);
        if (refined_[i] && rp != node.parents.size())
            return strprintf("node %u is refined but not all its parents are: R is not closed", i);
        bool act = !refined_[i] && (node.parents.empty() || rp > 0);
        bool fr = refined_[i] && rc == 0;
        if (act != active_.contains(i)) return strprintf("node %u: drawn set is stale", i);
        if (fr != frontier_.contains(i)) return strprintf("node %u: frontier set is stale", i);
        active += act;
        frontier += fr;
        if (act) t.primitives += counter_.count(i, RefinedView{refined_.data()});
        if (node.has_data && (act || fr)) {
            NodeBytes b = residency.bytes(i);
            if (act) t.gpu += b.gpu;
            t.cpu += b.cpu;
        }
        if (active_.contains(i) && active_.items[active_.pos[i]] != i) return "drawn set index is broken";
        if (frontier_.contains(i) && frontier_.items[frontier_.pos[i]] != i) return "frontier set index is broken";
    }
    if (active != active_.items.size() || frontier != frontier_.items.size()) return "set sizes are stale";
    if (t.primitives != totals_.primitives) return strprintf("primitives %llu, counted %llu", (unsigned long long)t.primitives, (unsigned long long)totals_.primitives);
    if (t.gpu != totals_.gpu) return strprintf("gpu bytes %llu, counted %llu", (unsigned long long)t.gpu, (unsigned long long)totals_.gpu);
    if (t.cpu != totals_.cpu) return strprintf("cpu bytes %llu, counted %llu", (unsigned long long)t.cpu, (unsigned long long)totals_.cpu);
    return {};
}

}  // namespace catpaq
