#include "catp/format.h"

#include <cmath>
#include <cstring>

#include "base/bytes.h"
#include "base/error.h"
#include "common_codec/deflate.h"

namespace catpaq {

namespace {

// Version 4's slot table, before deflating: the sizes as four byte planes (low bytes first).
// Sizes vary from fragment to fragment with no order to exploit; the planes deflate to 13% less
// than the varints did (10M scan: 13,676 sizes), and leaving each entry's last slot out
// removes a fifth of them (3,062 of 13,676).
std::vector<uint8_t> size_planes(const std::vector<uint32_t>& sizes) {
    std::vector<uint8_t> planes(4 * sizes.size());
    for (size_t i = 0; i < sizes.size(); ++i)
        for (int b = 0; b < 4; ++b) planes[b * sizes.size() + i] = uint8_t(sizes[i] >> (8 * b));
    return planes;
}

// The number of slots of an index entry: its slot mask's bits.
int entry_slots(const ArchiveEntry& e) { return __builtin_popcount(e.flags & 0xffu); }

}  // namespace

std::vector<uint8_t> encode_catp_meta(const CatpMeta& m, const std::vector<ArchiveEntry>& entries, uint32_t version) {
    if (version < 1 || version > kCatpMetaVersion) fail("cannot write CATP metadata version %u", version);
    if (version < 3 && !m.slot_bytes.empty()) fail("CATP metadata version %u has no slot table", version);
    ByteWriter w;
    w.raw("CATPMETA", 8);
    w.u32(version);
    w.u32(m.lattice_bits);
    for (double v : m.origin) w.f64(v);
    w.f64(m.cell);
    w.u32(m.leaf_level);
    w.u32(m.flags);
    w.u64(m.input_vertices);
    w.u64(m.input_triangles);
    for (double v : m.bounds_min) w.f64(v);
    for (double v : m.bounds_max) w.f64(v);
    w.u32(m.default_rgb);
    if (version < 2) return std::move(w.bytes());
    w.u8(uint8_t(m.layout.kind));
    w.u8(uint8_t(m.up));
    w.u16(uint16_t(m.layout.grid));
    w.f64(m.precision);
    w.f64(m.mean_edge);
    if (version == 3) {
        w.u32(uint32_t(m.slot_bytes.size()));
        for (uint32_t n : m.slot_bytes) w.varint(n);
    } else if (version >= 4) {
        if (m.slot_bytes.empty()) {
            w.u32(0);
            return std::move(w.bytes());
        }
        std::vector<uint32_t> stored;
        size_t next = 0;
        for (const ArchiveEntry& e : entries) {
            const size_t k = size_t(entry_slots(e));
            uint64_t total = 0;
            for (size_t s = 0; s < k && next + s < m.slot_bytes.size(); ++s) total += m.slot_bytes[next + s];
            if (next + k > m.slot_bytes.size() || (k > 0 && diamond_slot_offset(total, int(k) - 1) != e.size))
                fail("cannot write CATP metadata: the slot table does not match the index at entry %llu",
                     (unsigned long long)e.key);
            for (size_t s = 0; s + 1 < k; ++s) stored.push_back(m.slot_bytes[next + s]);
            next += k;
        }
        if (next != m.slot_bytes.size()) fail("cannot write CATP metadata: the slot table is longer than the index");
        w.u32(uint32_t(entries.size()));
        w.u32(uint32_t(stored.size()));
        const std::vector<uint8_t> packed = deflate_bytes(size_planes(stored));
        w.raw(packed.data(), packed.size());
    }
    return std::move(w.bytes());
}

std::string decode_catp_meta(const uint8_t* data, size_t size, CatpMeta& m, const std::vector<ArchiveEntry>* entries) {
    if (size < 8 || std::memcmp(data, "CATPMETA", 8) != 0) return "not CATP metadata";
    ByteReader r(data + 8, size - 8);
    uint32_t version = r.u32();
    if (!r.ok()) return "CATP metadata truncated";
    if (version < 1 || version > kCatpMetaVersion)
        return strprintf("unsupported CATP metadata version %u (this build reads 1 to %u)", version, kCatpMetaVersion);
    m.lattice_bits = r.u32();
    for (double& v : m.origin) v = r.f64();
    m.cell = r.f64();
    m.leaf_level = r.u32();
    m.flags = r.u32();
    m.input_vertices = r.u64();
    m.input_triangles = r.u64();
    for (double& v : m.bounds_min) v = r.f64();
    for (double& v : m.bounds_max) v = r.f64();
    m.default_rgb = r.u32();
    m.layout = VertexLayout{};
    m.up = UpAxis::Unknown;
    m.precision = m.mean_edge = 0;
    if (version >= 2) {
        m.layout.kind = VertexLayoutKind(r.u8());
        m.up = UpAxis(r.u8());
        m.layout.grid = r.u16();
        m.precision = r.f64();
        m.mean_edge = r.f64();
    }
    m.slot_bytes.clear();
    if (version >= 4) {
        const uint32_t covered = r.u32();
        if (!r.ok()) return "CATP metadata truncated";
        if (covered != 0) {
            const uint32_t n = r.u32();
            // A size is four bytes inflated.
            if (!r.ok() || !deflate_can_hold(uint64_t(n) * 4, r.remaining()))
                return "CATP metadata has a truncated slot table";
            std::vector<uint8_t> planes;
            if (!inflate_bytes(r.cursor(), r.remaining(), size_t(n) * 4, planes) || planes.size() != size_t(n) * 4)
                return "CATP metadata's slot table is not a valid deflate stream of the expected size";
            r.take(r.remaining());
            if (entries) {
                if (entries->size() != covered) return "CATP metadata's slot table covers another index";
                size_t next = 0;
                for (const ArchiveEntry& e : *entries) {
                    const int k = entry_slots(e);
                    uint64_t before = 0;
                    for (int s = 0; s + 1 < k; ++s) {
                        if (next == n) return "CATP metadata's slot table is shorter than the index";
                        uint32_t v = 0;
                        for (int b = 0; b < 4; ++b) v |= uint32_t(planes[size_t(b) * n + next]) << (8 * b);
                        m.slot_bytes.push_back(v);
                        before += v;
                        ++next;
                    }
                    if (k == 0) continue;
                    const uint64_t start = diamond_slot_offset(before, k - 1);
                    if (start > e.size) return "CATP metadata's slot table does not match an index entry's size";
                    m.slot_bytes.push_back(uint32_t(e.size - start));
                }
                if (next != n) return "CATP metadata's slot table is longer than the index";
            }
        }
    } else if (version >= 3) {
        const uint32_t n = r.u32();
        // Each size takes at least one byte: a count beyond the bytes left is corrupt (and must
        // not reserve memory).
        if (!r.ok() || n > r.remaining()) return "CATP metadata has a truncated slot table";
        m.slot_bytes.resize(n);
        for (uint32_t& v : m.slot_bytes) {
            const uint64_t x = r.varint();
            if (x > UINT32_MAX) return "CATP metadata has an invalid slot size";
            v = uint32_t(x);
        }
    }
    if (!r.ok()) return "CATP metadata truncated";
    if (!m.layout.valid())
        return strprintf("CATP metadata names an invalid vertex layout (%u, grid %d)", unsigned(m.layout.kind), m.layout.grid);
    if (uint8_t(m.up) > uint8_t(UpAxis::NegZ)) return "CATP metadata has an invalid up axis";
    if (!(m.precision >= 0) || !std::isfinite(m.precision) || !(m.mean_edge >= 0) || !std::isfinite(m.mean_edge))
        return "CATP metadata has an invalid precision or mean edge";
    if (m.lattice_bits != uint32_t(kLatticeBits))
        return strprintf("CATP lattice of %u bits is not supported (this build uses %d)", m.lattice_bits, kLatticeBits);
    if (!(m.cell > 0) || !std::isfinite(m.cell)) return "CATP metadata has an invalid cell size";
    for (double v : m.origin)
        if (!std::isfinite(v)) return "CATP metadata has an invalid origin";
    if (m.leaf_level > uint32_t(kMaxLevel)) return "CATP metadata has an invalid leaf level";
    return "";
}

std::vector<uint8_t> encode_diamond_node(const DiamondFragments& f, std::vector<uint32_t>* slot_bytes) {
    std::vector<uint8_t> out;
    if (slot_bytes) slot_bytes->clear();
    out.push_back(f.slot_mask);
    for (int s = 0; s < 8; ++s) {
        if (!(f.slot_mask & (1 << s))) continue;
        size_t at = out.size();
        out.resize(at + 4);
        size_t n = fragment_encode(f.slots[s], out);
        for (int i = 0; i < 4; ++i) out[at + i] = uint8_t(n >> (8 * i));
        if (slot_bytes) slot_bytes->push_back(uint32_t(n));
    }
    return out;
}

std::string split_diamond_node(const uint8_t* data, size_t size, DiamondNodeSlots& out) {
    ByteReader r(data, size);
    out = {};
    out.slot_mask = r.u8();
    if (!r.ok()) return "empty diamond node";
    for (int s = 0; s < 8; ++s) {
        if (!(out.slot_mask & (1 << s))) continue;
        out.size[s] = r.u32();
        out.fragment[s] = r.take(out.size[s]);
        if (!out.fragment[s]) return strprintf("diamond node truncated in slot %d", s);
    }
    if (r.remaining() != 0) return "trailing bytes after the diamond's fragments";
    return "";
}

std::string decode_diamond_node(const uint8_t* data, size_t size, const std::optional<VertexLayout>& layout,
                                DiamondFragments& out) {
    DiamondNodeSlots node;
    if (std::string e = split_diamond_node(data, size, node); !e.empty()) return e;
    out.slot_mask = node.slot_mask;
    for (int s = 0; s < 8; ++s) {
        out.slots[s].vertices.clear();
        out.slots[s].indices.clear();
        if (!(out.slot_mask & (1 << s))) continue;
        FragmentStatus status = fragment_decode(node.fragment[s], node.size[s], out.slots[s]);
        if (status != FragmentStatus::Ok)
            return strprintf("slot %d: fragment %s", s, fragment_status_name(status));
        if (layout && out.slots[s].layout != *layout)
            return strprintf("slot %d: fragment in the %s layout with grid %d, the dataset's is %s with grid %d", s,
                             out.slots[s].layout.name(), out.slots[s].layout.grid, layout->name(), layout->grid);
    }
    return "";
}

}  // namespace catpaq
