#include "client/cache.h"

namespace catpaq {

uint64_t decoded_bytes(const DiamondFragments& fragments) {
    uint64_t total = sizeof(DiamondFragments);
    for (int s = 0; s < 8; ++s) {
        const FragmentMesh& f = fragments.slots[s];
        total += f.vertices.capacity() * sizeof(PackedVertex) + f.indices.capacity() * sizeof(uint32_t);
    }
    return total;
}

NodeBytes catp_node_bytes(const DiamondFragments& fragments) {
    NodeBytes b;
    for (int s = 0; s < 8; ++s) {
        const FragmentMesh& f = fragments.slots[s];
        b.gpu += f.vertices.size() * sizeof(PackedVertex) + f.indices.size() * sizeof(uint32_t);
    }
    b.cpu = decoded_bytes(fragments);
    return b;
}

std::vector<uint32_t> catp_part_counts(const HierarchyNode& node, const DiamondFragments& fragments) {
    std::vector<uint32_t> out;
    out.reserve(node.parts.size());
    for (const HierarchyPart& part : node.parts)
        out.push_back(part.id < 8 ? uint32_t(fragments.slots[part.id].triangle_count()) : 0u);
    return out;
}

CatpNodeStore::CatpNodeStore(const Hierarchy& hierarchy, uint64_t fragment_budget_bytes, uint64_t compressed_budget_bytes)
    : hierarchy_(hierarchy),
      counter_(hierarchy),
      fragments_(fragment_budget_bytes),
      bytes_(hierarchy.size()),
      resident_(hierarchy.size(), 0) {
    if (compressed_budget_bytes) compressed_ = std::make_unique<CompressedCache>(compressed_budget_bytes);
    fragments_.on_evict([this](uint64_t key, const std::shared_ptr<const DiamondFragments>&, uint64_t) {
        resident_[key] = 0;
        bytes_[key] = {};
        log_.add(uint32_t(key));
    });
}

bool CatpNodeStore::resident(uint32_t node) const { return resident_[node] != 0; }

NodeBytes CatpNodeStore::bytes(uint32_t node) const {
    if (resident_[node]) return bytes_[node];
    const HierarchyNode& n = hierarchy_.node(node);
    if (!n.has_data) return {};
    // Estimate before decoding: about 0.6 vertices (8 bytes) and 12 index bytes per triangle.
    uint64_t gpu = uint64_t(n.primitives) * 17;
    return {gpu, gpu + sizeof(DiamondFragments)};
}

bool CatpNodeStore::add(uint32_t node, std::shared_ptr<const DiamondFragments> fragments,
                        std::shared_ptr<const std::vector<uint8_t>> compressed) {
    const HierarchyNode& n = hierarchy_.node(node);
    std::vector<uint32_t> counts = catp_part_counts(n, *fragments);
    counter_.set_counts(node, counts.data(), counts.size());
    if (compressed_ && compressed) compressed_->insert(node, compressed, compressed->size());
    NodeBytes b = catp_node_bytes(*fragments);
    if (!fragments_.insert(node, std::move(fragments), b.cpu)) return false;
    resident_[node] = 1;
    bytes_[node] = b;
    log_.add(node);
    return true;
}

std::shared_ptr<const DiamondFragments> CatpNodeStore::fragments(uint32_t node) {
    const auto* f = fragments_.get(node);
    return f ? *f : nullptr;
}

std::shared_ptr<const std::vector<uint8_t>> CatpNodeStore::compressed(uint32_t node) {
    if (!compressed_) return nullptr;
    const auto* c = compressed_->get(node);
    return c ? *c : nullptr;
}

void CatpNodeStore::pin(const std::vector<uint32_t>& nodes) {
    std::vector<uint64_t> keys(nodes.begin(), nodes.end());
    fragments_.set_pinned(keys);
    if (compressed_) compressed_->set_pinned(keys);
}

}  // namespace catpaq
