// AQP metadata and node payloads (aqp/format.h).
#include "aqp/format.h"

#include <cassert>
#include <cmath>
#include <cstring>

#include "aqp/png_codec.h"
#include "base/bytes.h"
#include "base/error.h"

namespace catpaq::aqp {

std::vector<uint8_t> encode_aqp_meta(const AqpMeta& m) {
    ByteWriter w;
    w.raw("AQPMETA\0", 8);
    w.u32(kAqpMetaVersion);
    w.u32(m.patch_level);
    w.u32(uint32_t(m.patches.size()));
    w.u32(m.base_vertices);
    w.u32(m.base_triangles);
    w.u32(m.border_edges);
    w.u32(m.flags);
    for (double v : m.origin) w.f64(v);
    w.f64(m.step);
    for (double v : m.bounds_min) w.f64(v);
    for (double v : m.bounds_max) w.f64(v);
    w.u64(m.input_vertices);
    w.u64(m.input_triangles);
    w.f64(m.precision);
    w.f64(m.mean_edge);
    w.u32(m.atlas_columns);
    for (const AqpPatchInfo& p : m.patches) {
        for (uint32_t c : p.corner) w.u32(c);
        for (const PatchLink& l : p.link) {
            w.u32(l.patch);
            w.u8(l.edge);
            w.u8(l.reversed ? 1 : 0);
        }
        for (uint32_t o : p.origin) w.u32(o);
        for (uint16_t e : p.extent) w.u16(e);
    }
    return std::move(w.bytes());
}

std::string decode_aqp_meta(const uint8_t* data, size_t size, AqpMeta& m) {
    if (size < 8 || std::memcmp(data, "AQPMETA\0", 8) != 0) return "not AQP metadata";
    ByteReader r(data + 8, size - 8);
    const uint32_t version = r.u32();
    if (!r.ok()) return "AQP metadata truncated";
    if (version != kAqpMetaVersion)
        return strprintf("unsupported AQP metadata version %u (this build reads %u)", version, kAqpMetaVersion);
    m.patch_level = r.u32();
    const uint32_t patch_count = r.u32();
    m.base_vertices = r.u32();
    m.base_triangles = r.u32();
    m.border_edges = r.u32();
    m.flags = r.u32();
    for (double& v : m.origin) v = r.f64();
    m.step = r.f64();
    for (double& v : m.bounds_min) v = r.f64();
    for (double& v : m.bounds_max) v = r.f64();
    m.input_vertices = r.u64();
    m.input_triangles = r.u64();
    m.precision = r.f64();
    m.mean_edge = r.f64();
    m.atlas_columns = r.u32();
    if (!r.ok()) return "AQP metadata truncated";
    constexpr size_t kPatchBytes = 16 + 4 * 6 + 12 + 6;
    if (r.remaining() != size_t(patch_count) * kPatchBytes)
        return strprintf("AQP metadata holds %zu bytes of patches, %u patches need %zu", r.remaining(), patch_count,
                         size_t(patch_count) * kPatchBytes);
    if (m.patch_level > uint32_t(kMaxPatchLevel)) return strprintf("AQP patch level %u is above %d", m.patch_level, kMaxPatchLevel);
    if (patch_count == 0) return "AQP metadata has no patches";
    if (!(m.step > 0) || !std::isfinite(m.step)) return "AQP metadata has an invalid quantization step";
    for (int i = 0; i < 3; ++i)
        if (!std::isfinite(m.origin[i]) || !std::isfinite(m.bounds_min[i]) || !std::isfinite(m.bounds_max[i]))
            return "AQP metadata has a non-finite origin or bound";
    if (!(m.precision >= 0) || !std::isfinite(m.precision) || !(m.mean_edge >= 0) || !std::isfinite(m.mean_edge))
        return "AQP metadata has an invalid precision or mean edge";
    if (m.atlas_columns == 0 || m.atlas_columns > patch_count) return "AQP metadata has an invalid atlas width";
    const uint64_t quad_vertices = uint64_t(m.base_vertices) + m.base_triangles + m.border_edges;
    m.patches.assign(patch_count, {});
    for (AqpPatchInfo& p : m.patches) {
        for (uint32_t& c : p.corner) c = r.u32();
        for (PatchLink& l : p.link) {
            l.patch = r.u32();
            l.edge = r.u8();
            uint8_t reversed = r.u8();
            if (reversed > 1 || l.edge > 3) return "AQP metadata has an invalid patch link";
            l.reversed = reversed != 0;
        }
        for (uint32_t& o : p.origin) o = r.u32();
        for (uint16_t& e : p.extent) e = r.u16();
        for (uint32_t c : p.corner)
            if (c >= quad_vertices) return "AQP metadata has a patch corner out of range";
    }
    for (uint32_t p = 0; p < patch_count; ++p)
        for (uint8_t e = 0; e < 4; ++e) {
            const PatchLink& l = m.patches[p].link[e];
            if (l.patch == kNone) continue;
            if (l.patch >= patch_count) return "AQP metadata links to a patch out of range";
            const PatchLink& back = m.patches[l.patch].link[l.edge];
            if (back.patch != p || back.edge != e || back.reversed != l.reversed)
                return strprintf("AQP metadata: patch %u edge %u links to a patch that does not link back", p, e);
        }
    return "";
}

namespace {

void append_png(std::vector<uint8_t>& out, const PngImage& image, int compression) {
    std::vector<uint8_t> png = png_encode(image, compression);
    const uint32_t n = uint32_t(png.size());
    for (int i = 0; i < 4; ++i) out.push_back(uint8_t(n >> (8 * i)));
    out.insert(out.end(), png.begin(), png.end());
}

PngImage image_of(const PatchGrid& g, int channels, int bit_depth) {
    PngImage im;
    im.width = im.height = g.size;
    im.channels = channels;
    im.bit_depth = bit_depth;
    im.values.reserve(im.value_count());
    return im;
}

}  // namespace

std::vector<uint8_t> encode_patch_node(const PatchGrid& g, bool colors, int compression) {
    const size_t n = size_t(g.size) * g.size;
    assert(g.size == (1 << g.level) + 1 && g.position.size() == n && g.normal.size() == n);
    assert(!colors || g.color.size() == n);
    std::vector<uint8_t> out;
    ByteWriter header;
    header.u32(g.patch);
    header.u8(uint8_t(g.level));
    header.u8(colors ? 1 : 0);
    header.u16(0);
    out = std::move(header.bytes());
    PngImage positions = image_of(g, 3, 16);
    for (const auto& p : g.position) positions.values.insert(positions.values.end(), p.begin(), p.end());
    append_png(out, positions, compression);
    PngImage normals = image_of(g, 2, 8);
    for (uint16_t code : g.normal) {
        normals.values.push_back(code & 0xff);
        normals.values.push_back(code >> 8);
    }
    append_png(out, normals, compression);
    if (colors) {
        PngImage rgb = image_of(g, 3, 8);
        for (const Rgb8& c : g.color) rgb.values.insert(rgb.values.end(), c.begin(), c.end());
        append_png(out, rgb, compression);
    }
    return out;
}

std::string decode_patch_node(const uint8_t* data, size_t size, uint32_t patch, int level, bool colors, PatchGrid& out) {
    if (level < 0 || level > kMaxPatchLevel) return strprintf("patch level %d out of range", level);
    ByteReader r(data, size);
    const uint32_t stored_patch = r.u32();
    const int stored_level = r.u8();
    const uint8_t flags = r.u8();
    const uint16_t reserved = r.u16();
    if (!r.ok()) return "AQP node truncated in its header";
    if (stored_patch != patch || stored_level != level)
        return strprintf("AQP node holds patch %u level %d, expected patch %u level %d", stored_patch, stored_level, patch, level);
    if (flags != (colors ? 1 : 0) || reserved != 0) return "AQP node has unexpected flags";
    out.patch = patch;
    out.level = level;
    out.size = (1 << level) + 1;
    const size_t n = size_t(out.size) * out.size;
    PngImage image;
    auto next_png = [&](int channels, int depth, const char* what) -> std::string {
        const uint32_t bytes = r.u32();
        const uint8_t* p = r.take(bytes);
        if (!p) return strprintf("AQP node truncated in its %s image", what);
        std::string e = png_decode(p, bytes, out.size, out.size, channels, depth, image);
        return e.empty() ? e : strprintf("%s image: %s", what, e.c_str());
    };
    if (std::string e = next_png(3, 16, "position"); !e.empty()) return e;
    out.position.resize(n);
    for (size_t i = 0; i < n; ++i) out.position[i] = {image.values[3 * i], image.values[3 * i + 1], image.values[3 * i + 2]};
    if (std::string e = next_png(2, 8, "normal"); !e.empty()) return e;
    out.normal.resize(n);
    for (size_t i = 0; i < n; ++i) out.normal[i] = uint16_t(image.values[2 * i] | (image.values[2 * i + 1] << 8));
    out.color.clear();
    if (colors) {
        if (std::string e = next_png(3, 8, "colour"); !e.empty()) return e;
        out.color.resize(n);
        for (size_t i = 0; i < n; ++i)
            out.color[i] = {uint8_t(image.values[3 * i]), uint8_t(image.values[3 * i + 1]), uint8_t(image.values[3 * i + 2])};
    }
    if (r.remaining() != 0) return "trailing bytes after the AQP node's images";
    return "";
}

}  // namespace catpaq::aqp
