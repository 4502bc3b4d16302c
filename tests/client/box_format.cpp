#include "box_format.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "base/bytes.h"
#include "base/error.h"
#include "common_codec/archive.h"

namespace catpaq::test {

namespace {

constexpr char kMagic[8] = {'B', 'O', 'X', 'M', 'E', 'T', 'A', '1'};

uint64_t cell_key(int level, uint64_t x, uint64_t y) { return uint64_t(level) << 56 | y << 28 | x; }

double cell_error(double size, int level, int grid) { return size / double(uint64_t(1) << level) / grid / 2; }

}  // namespace

void write_box_dataset(const std::string& path, const BoxDatasetSettings& s) {
    ArchiveWriter writer(path, ArchiveKind::Points);
    for (int level = 0; level < s.levels; ++level) {
        const uint64_t cells = uint64_t(1) << level;
        const double side = s.size / double(cells);
        for (uint64_t y = 0; y < cells; ++y) {
            for (uint64_t x = 0; x < cells; ++x) {
                ByteWriter w;
                const uint32_t triangles = uint32_t(2 * s.grid * s.grid);
                w.u32(triangles);
                const double step = side / s.grid;
                for (int j = 0; j < s.grid; ++j) {
                    for (int i = 0; i < s.grid; ++i) {
                        const double x0 = double(x) * side + i * step, y0 = double(y) * side + j * step;
                        const double quad[4][2] = {{x0, y0}, {x0 + step, y0}, {x0 + step, y0 + step}, {x0, y0 + step}};
                        for (int corner : {0, 1, 2, 0, 2, 3}) {
                            w.f32(float(quad[corner][0]));
                            w.f32(float(quad[corner][1]));
                            w.f32(0.0f);
                        }
                    }
                }
                ArchiveEntry entry;
                entry.key = cell_key(level, x, y);
                entry.level = uint16_t(level);
                entry.count = triangles;
                entry.error = float(cell_error(s.size, level, s.grid));
                writer.add_node(entry, w.bytes().data(), w.bytes().size());
            }
        }
    }
    ByteWriter meta;
    for (char c : kMagic) meta.u8(uint8_t(c));
    meta.f64(s.size);
    meta.u32(uint32_t(s.levels));
    meta.u32(uint32_t(s.grid));
    writer.finish(meta.bytes());
}

BoxFormat::BoxFormat(const DatasetPrefix& prefix) {
    ByteReader r(prefix.meta.data(), prefix.meta.size());
    const uint8_t* magic = r.take(sizeof kMagic);
    if (!magic || std::memcmp(magic, kMagic, sizeof kMagic) != 0) fail("'%s' is not a box dataset", prefix.source.c_str());
    size_ = r.f64();
    levels_ = int(r.u32());
    grid_ = int(r.u32());
    if (!r.ok() || !(size_ > 0) || levels_ < 1 || levels_ > 12 || grid_ < 1)
        fail("'%s': bad box metadata", prefix.source.c_str());
    for (size_t e = 0; e < prefix.entries.size(); ++e) {
        const ArchiveEntry& entry = prefix.entries[e];
        const int level = int(entry.key >> 56);
        const uint64_t x = entry.key & ((uint64_t(1) << 28) - 1), y = (entry.key >> 28) & ((uint64_t(1) << 28) - 1);
        const double side = size_ / double(uint64_t(1) << level);
        Aabb box;
        box.extend(std::array<double, 3>{double(x) * side, double(y) * side, 0.0});
        box.extend(std::array<double, 3>{double(x + 1) * side, double(y + 1) * side, 0.0});
        uint32_t n = hierarchy_.add_node(entry.key, entry.level, entry.error, box, true);
        HierarchyNode& node = hierarchy_.mutable_node(n);
        node.entry = uint32_t(e);
        node.payload_offset = entry.offset;
        node.payload_bytes = entry.size;
        node.checksum = entry.checksum;
        node.primitives = entry.count;
    }
    for (uint32_t n = 0; n < hierarchy_.size(); ++n) {
        HierarchyNode& node = hierarchy_.mutable_node(n);
        const int level = int(node.key >> 56);
        HierarchyPart part;
        part.primitives = node.primitives;
        if (level > 0) {
            const uint64_t x = node.key & ((uint64_t(1) << 28) - 1), y = (node.key >> 28) & ((uint64_t(1) << 28) - 1);
            part.parent = hierarchy_.find(cell_key(level - 1, x / 2, y / 2));
            if (part.parent == kNoNode) fail("'%s': cell %llu has no parent", prefix.source.c_str(), (unsigned long long)node.key);
            hierarchy_.add_parent(n, part.parent);
        }
        node.parts.push_back(part);
    }
    hierarchy_.finalize();
}

std::string BoxFormat::decode(uint32_t node, const uint8_t* data, size_t size, std::shared_ptr<const DecodedNode>& out) const {
    ByteReader r(data, size);
    const uint32_t triangles = r.u32();
    if (!r.ok() || r.remaining() != uint64_t(triangles) * 36) return "bad box payload";
    if (triangles != hierarchy_.node(node).primitives) return "triangle count differs from the index";
    auto decoded = std::make_shared<BoxNode>();
    decoded->corners.resize(size_t(triangles) * 9);
    for (float& f : decoded->corners) f = r.f32();
    for (size_t i = 0; i < decoded->corners.size(); i += 3)
        decoded->data_bounds.extend(std::array<double, 3>{decoded->corners[i], decoded->corners[i + 1], decoded->corners[i + 2]});
    decoded->bytes.cpu = decoded->corners.size() * sizeof(float);
    decoded->bytes.gpu = decoded->corners.size() * sizeof(float);
    decoded->part_primitives = {triangles};
    out = std::move(decoded);
    return "";
}

std::optional<double> BoxFormat::data_distance(uint32_t, const DecodedNode& decoded, const std::array<double, 3>& eye) const {
    if (decoded.data_bounds.empty()) return std::nullopt;
    return decoded.data_bounds.distance_to(eye);
}

DrawnGeometry BoxFormat::drawn_geometry(const std::vector<DecodedPart>& parts, const std::array<double, 3>& eye) const {
    DrawnGeometry g;
    g.origin = eye;
    for (const DecodedPart& p : parts) {
        const auto& box = dynamic_cast<const BoxNode&>(*p.decoded);
        for (size_t i = 0; i < box.corners.size(); i += 3) {
            g.mesh.indices.push_back(uint32_t(g.mesh.positions.size()));
            g.mesh.positions.push_back({box.corners[i] - eye[0], box.corners[i + 1] - eye[1], box.corners[i + 2] - eye[2]});
        }
    }
    return g;
}

Aabb BoxFormat::world_bounds() const {
    Aabb b;
    b.extend(std::array<double, 3>{0, 0, 0});
    b.extend(std::array<double, 3>{size_, size_, 0});
    return b;
}

FormatSummary BoxFormat::summary() const {
    FormatSummary s;
    s.node_noun = "cells";
    s.primitive_noun = "triangles";
    s.lines.emplace_back("square", strprintf("%g wide, %d levels", size_, levels_));
    return s;
}

FormatModule box_format_module() {
    FormatModule m;
    m.kind = ArchiveKind::Points;
    m.open = [](const DatasetPrefix& prefix) { return std::make_unique<BoxFormat>(prefix); };
    return m;
}

}  // namespace catpaq::test
