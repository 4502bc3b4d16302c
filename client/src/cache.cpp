#include "client/cache.h"

namespace catpaq {

NodeStore::NodeStore(const Hierarchy& hierarchy, uint64_t decoded_budget_bytes, uint64_t compressed_budget_bytes,
                     double bytes_per_primitive)
    : hierarchy_(hierarchy),
      bytes_per_primitive_(bytes_per_primitive),
      counter_(hierarchy),
      decoded_(decoded_budget_bytes),
      bytes_(hierarchy.size()),
      data_bounds_(hierarchy.size()),
      resident_(hierarchy.size(), 0) {
    if (compressed_budget_bytes) compressed_ = std::make_unique<CompressedCache>(compressed_budget_bytes);
    decoded_.on_evict([this](uint64_t key, const std::shared_ptr<const DecodedNode>&, uint64_t) {
        resident_[key] = 0;
        bytes_[key] = {};
        data_bounds_[key] = {};
        log_.add(uint32_t(key));
    });
}

bool NodeStore::resident(uint32_t node) const { return resident_[node] != 0; }

NodeBytes NodeStore::bytes(uint32_t node) const {
    if (resident_[node]) return bytes_[node];
    const HierarchyNode& n = hierarchy_.node(node);
    if (!n.has_data) return {};
    uint64_t estimate = uint64_t(double(n.primitives) * bytes_per_primitive_);
    return {estimate, estimate};
}

const Aabb* NodeStore::data_bounds(uint32_t node) const {
    return resident_[node] && !data_bounds_[node].empty() ? &data_bounds_[node] : nullptr;
}

bool NodeStore::add(uint32_t node, std::shared_ptr<const DecodedNode> decoded,
                    std::shared_ptr<const std::vector<uint8_t>> compressed) {
    const std::vector<uint32_t>& counts = decoded->part_primitives;
    counter_.set_counts(node, counts.data(), counts.size());
    if (compressed_ && compressed) compressed_->insert(node, compressed, compressed->size());
    NodeBytes b = decoded->bytes;
    Aabb box = decoded->data_bounds;
    if (!decoded_.insert(node, std::move(decoded), b.cpu)) return false;
    resident_[node] = 1;
    bytes_[node] = b;
    data_bounds_[node] = box;
    log_.add(node);
    return true;
}

std::shared_ptr<const DecodedNode> NodeStore::decoded(uint32_t node) {
    const auto* d = decoded_.get(node);
    return d ? *d : nullptr;
}

std::shared_ptr<const std::vector<uint8_t>> NodeStore::compressed(uint32_t node) {
    if (!compressed_) return nullptr;
    const auto* c = compressed_->get(node);
    return c ? *c : nullptr;
}

void NodeStore::pin(const std::vector<uint32_t>& nodes) {
    std::vector<uint64_t> keys(nodes.begin(), nodes.end());
    decoded_.set_pinned(keys);
    if (compressed_) compressed_->set_pinned(keys);
}

}  // namespace catpaq
