#include "catp/dataset.h"

#include "base/error.h"

namespace catpaq {

CatpIndex::CatpIndex(const ArchiveHeader& header, std::vector<uint8_t> meta, std::vector<ArchiveEntry> entries,
                     const std::string& source)
    : header_(header), entries_(std::move(entries)) {
    if (header.kind != ArchiveKind::Catp)
        fail("'%s' is a %s dataset, not CATP", source.c_str(), archive_kind_name(header.kind));
    std::string problem = decode_catp_meta(meta.data(), meta.size(), meta_, &entries_);
    if (!problem.empty()) fail("'%s': %s", source.c_str(), problem.c_str());
    by_key_.reserve(entries_.size() * 2);
    for (size_t i = 0; i < entries_.size(); ++i) {
        const ArchiveEntry& e = entries_[i];
        DiamondId id{e.key};
        if (!is_valid_diamond_centre(id.centre()) || diamond_level(id) != e.level)
            fail("'%s': index entry %zu is not a valid diamond", source.c_str(), i);
        by_key_[e.key] = i;
    }
    if (meta_.slot_bytes.empty()) return;
    // The slot table must describe every entry's framing exactly (catp/format.h).
    slot_offsets_.assign(entries_.size(), {});
    slot_sizes_.assign(entries_.size(), {});
    size_t next = 0;
    for (size_t i = 0; i < entries_.size(); ++i) {
        const ArchiveEntry& e = entries_[i];
        uint64_t before = 0;
        int earlier = 0;
        for (int s = 0; s < 8; ++s) {
            if (!(e.flags & (1u << s))) continue;
            if (next == meta_.slot_bytes.size()) fail("'%s': the slot table is shorter than the index", source.c_str());
            const uint32_t n = meta_.slot_bytes[next++];
            slot_offsets_[i][size_t(s)] = e.offset + diamond_slot_offset(before, earlier);
            slot_sizes_[i][size_t(s)] = n;
            before += n;
            ++earlier;
        }
        if (diamond_slot_offset(before, earlier - 1) != e.size)
            fail("'%s': the slot table does not match the size of index entry %zu", source.c_str(), i);
    }
    if (next != meta_.slot_bytes.size()) fail("'%s': the slot table is longer than the index", source.c_str());
}

bool CatpIndex::slot_range(size_t entry_index, int slot, uint64_t& offset, uint32_t& size) const {
    if (slot_offsets_.empty() || entry_index >= entries_.size() || slot < 0 || slot > 7 ||
        !(entries_[entry_index].flags & (1u << slot)))
        return false;
    offset = slot_offsets_[entry_index][size_t(slot)];
    size = slot_sizes_[entry_index][size_t(slot)];
    return true;
}

CatpIndex CatpIndex::from_prefix(const uint8_t* data, size_t size, const std::string& source) {
    ArchiveHeader header;
    std::string problem = parse_archive_header(data, size, header);
    if (problem.empty() && size < header.index_offset + header.index_size) problem = "prefix is truncated";
    std::vector<ArchiveEntry> entries;
    if (problem.empty()) problem = parse_archive_index(header, data + header.index_offset, header.index_size, entries);
    if (!problem.empty()) fail("'%s': %s", source.c_str(), problem.c_str());
    std::vector<uint8_t> meta(data + header.meta_offset, data + header.meta_offset + header.meta_size);
    return CatpIndex(header, std::move(meta), std::move(entries), source);
}

const ArchiveEntry* CatpIndex::find(DiamondId id) const {
    auto it = by_key_.find(id.bits);
    return it == by_key_.end() ? nullptr : &entries_[it->second];
}

void CatpIndex::lattice_to_world(const double lattice[3], double world[3]) const {
    for (int i = 0; i < 3; ++i) world[i] = meta_.origin[i] + lattice[i] * meta_.cell;
}

CatpFile::CatpFile(const std::string& path) : archive_(new ArchiveReader(path)) {
    index_.reset(new CatpIndex(archive_->header(), archive_->meta(), archive_->entries(), path));
}

DiamondFragments CatpFile::decode(const ArchiveEntry& entry) const {
    std::string error;
    const uint8_t* bytes = archive_->node(index_->entry_index(&entry), &error);
    if (!bytes) fail("%s", error.c_str());
    DiamondFragments out;
    std::string problem = decode_diamond_node(bytes, entry.size, index_->meta().layout, out);
    if (!problem.empty()) fail("diamond %llu: %s", (unsigned long long)entry.key, problem.c_str());
    return out;
}

bool decode_fragment_integer_positions(const FragmentMesh& fragment, const DiamondInfo& diamond, int slot,
                                       std::vector<std::array<int64_t, 3>>& out) {
    Tetrahedron t = canonical_tetrahedron(diamond_tetrahedron(diamond, slot));
    std::array<LatticePoint, 4> c = {t[0], t[1], t[2], t[3]};
    out.clear();
    out.reserve(fragment.vertices.size());
    for (const PackedVertex& v : fragment.vertices) {
        BaryWeights w;
        if (!vertex_weights(v, fragment.layout, w)) return false;
        out.push_back(bary_integer_sum(w, c));
    }
    return true;
}

VertexDecodeParams slot_decode_params(const CatpMeta& meta, const DiamondInfo& diamond, int slot,
                                      const LatticePoint& anchor, double cell_in_frame) {
    Tetrahedron t = canonical_tetrahedron(diamond_tetrahedron(diamond, slot));
    VertexDecodeParams p;
    for (int i = 0; i < 4; ++i)
        for (int k = 0; k < 3; ++k) p.offsets[size_t(i)][size_t(k)] = t[size_t(i)][size_t(k)] - anchor[size_t(k)];
    p.layout = meta.layout;
    p.scale = float(cell_in_frame / meta.layout.grid);
    for (int k = 0; k < 3; ++k) p.default_color[size_t(k)] = float((meta.default_rgb >> (8 * k)) & 0xff) / 255.0f;
    return p;
}

bool decode_fragment_positions(const FragmentMesh& fragment, const VertexDecodeParams& params,
                               std::vector<float>& positions_out) {
    for (const PackedVertex& v : fragment.vertices) {
        DecodedVertex d;
        if (!decode_packed_vertex(v, params, d)) return false;
        positions_out.insert(positions_out.end(), d.position, d.position + 3);
    }
    return true;
}

}  // namespace catpaq
