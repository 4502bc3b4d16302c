// AQP metadata and node payloads (aqp/format.h).
#include "aqp/format.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>
#include <tuple>
#include <unordered_map>
#include <utility>

#include "aqp/png_codec.h"
#include "base/bytes.h"
#include "base/error.h"
#include "common_codec/deflate.h"

namespace catpaq::aqp {

namespace {

// The most bytes a version-5 patch table inflates to: every field a varint of at most 5 bytes
// (an extent at most 3).
size_t max_patch_table_bytes(size_t patches) { return patches * (7 * 5 + 3 * 3); }

// Version 5's patch table before deflate: every field a varint, column by column (corner 0 of
// every patch, then corner 1, ..., origin x, y, z, extent x, y, z), corners and origins as
// zigzag differences from the previous patch's. Patches follow a Morton curve, so consecutive
// ones share corners and lie close: the differences are small and alike, which deflate then
// takes further. Links are left out (derive_patch_links finds them from the corners).
std::vector<uint8_t> patch_table(const std::vector<AqpPatchInfo>& patches) {
    ByteWriter w;
    // One column: a field of every patch as zigzag differences from the previous patch's.
    auto differences = [&](auto field) {
        int64_t previous = 0;
        for (const AqpPatchInfo& p : patches) w.varint(zigzag64(int64_t(field(p)) - std::exchange(previous, field(p))));
    };
    for (size_t c = 0; c < 4; ++c) differences([c](const AqpPatchInfo& p) { return p.corner[c]; });
    for (size_t a = 0; a < 3; ++a) differences([a](const AqpPatchInfo& p) { return p.origin[a]; });
    for (size_t a = 0; a < 3; ++a)
        for (const AqpPatchInfo& p : patches) w.varint(p.extent[a]);
    return std::move(w.bytes());
}

// The inverse of patch_table for `patches` (sized); an empty string, or what is wrong.
std::string read_patch_table(const uint8_t* data, size_t size, std::vector<AqpPatchInfo>& patches) {
    ByteReader r(data, size);
    // One column of differences (patch_table) into a u32 field of every patch; false when a value
    // leaves u32.
    auto differences = [&](auto field) {
        int64_t value = 0;
        for (AqpPatchInfo& p : patches) {
            value += unzigzag64(r.varint());
            if (value < 0 || value > int64_t(UINT32_MAX)) return false;
            field(p) = uint32_t(value);
        }
        return true;
    };
    for (size_t c = 0; c < 4; ++c)
        if (!differences([c](AqpPatchInfo& p) -> uint32_t& { return p.corner[c]; })) return "AQP metadata has a patch corner out of range";
    for (size_t a = 0; a < 3; ++a)
        if (!differences([a](AqpPatchInfo& p) -> uint32_t& { return p.origin[a]; })) return "AQP metadata has a patch origin out of range";
    for (int a = 0; a < 3; ++a)
        for (AqpPatchInfo& p : patches) {
            const uint64_t e = r.varint();
            if (e > UINT16_MAX) return "AQP metadata has a patch extent out of range";
            p.extent[a] = uint16_t(e);
        }
    if (!r.ok()) return "AQP metadata's patch table is truncated";
    if (r.remaining() != 0) return "AQP metadata's patch table has bytes left over";
    return "";
}

void write_patch_records(ByteWriter& w, const std::vector<AqpPatchInfo>& patches) {
    for (const AqpPatchInfo& p : patches) {
        for (uint32_t c : p.corner) w.u32(c);
        for (const PatchLink& l : p.link) {
            w.u32(l.patch);
            w.u8(l.edge);
            w.u8(l.reversed ? 1 : 0);
        }
        for (uint32_t o : p.origin) w.u32(o);
        for (uint16_t e : p.extent) w.u16(e);
    }
}

}  // namespace

std::string derive_patch_links(std::vector<AqpPatchInfo>& patches) {
    // Every patch edge as (smaller corner, larger corner, patch, edge), sorted: the edges between
    // the same two quad vertices end up next to each other.
    struct EdgeUse {
        uint32_t lo, hi, patch;
        uint8_t edge;
    };
    std::vector<EdgeUse> uses;
    uses.reserve(patches.size() * 4);
    for (uint32_t p = 0; p < patches.size(); ++p)
        for (uint8_t e = 0; e < 4; ++e) {
            const uint32_t a = patches[p].corner[e], b = patches[p].corner[(e + 1) % 4];
            if (a == b) return strprintf("AQP metadata: patch %u has a repeated corner", p);
            uses.push_back({std::min(a, b), std::max(a, b), p, e});
            patches[p].link[e] = PatchLink{};
        }
    std::sort(uses.begin(), uses.end(), [](const EdgeUse& x, const EdgeUse& y) {
        return std::tie(x.lo, x.hi, x.patch, x.edge) < std::tie(y.lo, y.hi, y.patch, y.edge);
    });
    for (size_t i = 0; i < uses.size();) {
        size_t j = i + 1;
        while (j < uses.size() && uses[j].lo == uses[i].lo && uses[j].hi == uses[i].hi) ++j;
        if (j - i > 2)
            return strprintf("AQP metadata: the edge between quad vertices %u and %u belongs to %zu patch edges (at most 2)",
                             uses[i].lo, uses[i].hi, j - i);
        if (j - i == 2) {
            const EdgeUse &x = uses[i], &y = uses[i + 1];
            const bool reversed = patches[x.patch].corner[x.edge] != patches[y.patch].corner[y.edge];
            patches[x.patch].link[x.edge] = {y.patch, y.edge, reversed};
            patches[y.patch].link[y.edge] = {x.patch, x.edge, reversed};
        }
        i = j;
    }
    return "";
}

std::vector<uint8_t> encode_aqp_meta(const AqpMeta& m, uint32_t version) {
    if (version < 4 || version > kAqpMetaVersion) fail("cannot write AQP metadata version %u", version);
    ByteWriter w;
    w.raw("AQPMETA\0", 8);
    w.u32(version);
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
    w.u32(m.up_axis);
    for (uint32_t l = 0; l <= m.patch_level; ++l) w.u8(l < m.tile_shift.size() ? m.tile_shift[l] : 0);  // none: one patch per tile
    if (version == 4) {
        write_patch_records(w, m.patches);
        return std::move(w.bytes());
    }
    // Version 5 stores no links: a reader derives them, so they must be what the corners say.
    std::vector<AqpPatchInfo> derived = m.patches;
    if (std::string e = derive_patch_links(derived); !e.empty()) fail("cannot write AQP metadata: %s", e.c_str());
    for (size_t p = 0; p < derived.size(); ++p)
        for (int e = 0; e < 4; ++e) {
            const PatchLink &a = derived[p].link[size_t(e)], &b = m.patches[p].link[size_t(e)];
            if (a.patch != b.patch || a.edge != b.edge || a.reversed != b.reversed)
                fail("cannot write AQP metadata: patch %zu edge %d links other than its corners say", p, e);
        }
    const std::vector<uint8_t> packed = deflate_bytes(patch_table(m.patches));
    w.raw(packed.data(), packed.size());
    return std::move(w.bytes());
}

std::string decode_aqp_meta(const uint8_t* data, size_t size, AqpMeta& m) {
    if (size < 8 || std::memcmp(data, "AQPMETA\0", 8) != 0) return "not AQP metadata";
    ByteReader r(data + 8, size - 8);
    const uint32_t version = r.u32();
    if (!r.ok()) return "AQP metadata truncated";
    if (version < 1 || version > kAqpMetaVersion)
        return strprintf("unsupported AQP metadata version %u (this build reads 1 to %u)", version, kAqpMetaVersion);
    m.version = version;
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
    m.up_axis = version >= 2 ? r.u32() : 0;
    if (!r.ok()) return "AQP metadata truncated";
    if (m.up_axis > 6) return strprintf("AQP metadata has an invalid up axis %u", m.up_axis);
    if (m.patch_level > uint32_t(kMaxPatchLevel)) return strprintf("AQP patch level %u is above %d", m.patch_level, kMaxPatchLevel);
    m.tile_shift.clear();
    if (version >= 4) {
        for (uint32_t l = 0; l <= m.patch_level; ++l) m.tile_shift.push_back(r.u8());
        if (!r.ok()) return "AQP metadata truncated";
        for (uint32_t l = 0; l <= m.patch_level; ++l)
            if (m.tile_shift[l] > kMaxTileShift || (l > 0 && m.tile_shift[l] > m.tile_shift[l - 1]))
                return strprintf("AQP metadata has an invalid tile shift %u at level %u (tiles must nest)", m.tile_shift[l], l);
        // One patch per tile everywhere is how older versions read.
        if (std::all_of(m.tile_shift.begin(), m.tile_shift.end(), [](uint8_t x) { return x == 0; })) m.tile_shift.clear();
    }
    if (patch_count == 0) return "AQP metadata has no patches";
    constexpr size_t kPatchBytes = 16 + 4 * 6 + 12 + 6;  // a version 1-4 patch record
    if (version <= 4 && r.remaining() != size_t(patch_count) * kPatchBytes)
        return strprintf("AQP metadata holds %zu bytes of patches, %u patches need %zu", r.remaining(), patch_count,
                         size_t(patch_count) * kPatchBytes);
    if (!(m.step > 0) || !std::isfinite(m.step)) return "AQP metadata has an invalid quantization step";
    for (int i = 0; i < 3; ++i)
        if (!std::isfinite(m.origin[i]) || !std::isfinite(m.bounds_min[i]) || !std::isfinite(m.bounds_max[i]))
            return "AQP metadata has a non-finite origin or bound";
    if (!(m.precision >= 0) || !std::isfinite(m.precision) || !(m.mean_edge >= 0) || !std::isfinite(m.mean_edge))
        return "AQP metadata has an invalid precision or mean edge";
    if (m.atlas_columns == 0 || m.atlas_columns > patch_count) return "AQP metadata has an invalid atlas width";
    const uint64_t quad_vertices = uint64_t(m.base_vertices) + m.base_triangles + m.border_edges;
    // Version 5: the patch table, deflated; a patch count no table could hold is refused before
    // anything is allocated for it (a patch's varints are at least ten bytes).
    if (version >= 5 && !deflate_can_hold(uint64_t(patch_count) * 10, r.remaining()))
        return strprintf("AQP metadata's patch table is too short for %u patches", patch_count);
    m.patches.assign(patch_count, {});
    if (version >= 5) {
        std::vector<uint8_t> table;
        if (!inflate_bytes(r.cursor(), r.remaining(), max_patch_table_bytes(patch_count), table))
            return "AQP metadata's patch table is not a valid deflate stream of the expected size";
        if (std::string e = read_patch_table(table.data(), table.size(), m.patches); !e.empty()) return e;
        for (const AqpPatchInfo& p : m.patches)
            for (uint32_t c : p.corner)
                if (c >= quad_vertices) return "AQP metadata has a patch corner out of range";
        return derive_patch_links(m.patches);
    }
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

// Channel c of sample s: 0-2 position, 3-4 normal bytes, 5-7 colour (0 without colours).
int channel_value(const PatchGrid& g, size_t s, int c) {
    if (c < 3) return g.position[s][c];
    if (c < 5) return c == 3 ? g.normal[s] & 0xff : g.normal[s] >> 8;
    return g.color.empty() ? 0 : g.color[s][c - 5];
}

int channel_bits(int c) { return c < 3 ? 16 : 8; }

// x modulo 2^bits as a signed value, zigzag coded (0, -1, 1, -2, ... -> 0, 1, 2, 3, ...).
uint32_t zigzag(int x, int bits) {
    const int mod = 1 << bits;
    x &= mod - 1;
    if (x >= mod / 2) x -= mod;
    return x >= 0 ? uint32_t(2 * x) : uint32_t(-2 * x - 1);
}

int unzigzag(uint32_t z) { return (z & 1) ? -int(z >> 1) - 1 : int(z >> 1); }

}  // namespace

int predict_from_coarser(const PatchGrid& c, int channel, int i, int j) {
    const int ci = i / 2, cj = j / 2;
    auto at = [&](int x, int y) { return channel_value(c, c.index(x, y), channel); };
    if (i % 2 == 0 && j % 2 == 0) return at(ci, cj);
    if (j % 2 == 0) return (at(ci, cj) + at(ci + 1, cj)) >> 1;
    if (i % 2 == 0) return (at(ci, cj) + at(ci, cj + 1)) >> 1;
    return (at(ci, cj) + at(ci + 1, cj + 1)) >> 1;
}

namespace {

constexpr int kChannels = 8;  // x y z (16 bits), normal u v, red green blue (8 bits)

int channel_count(const NodeLayout& layout) { return layout.colors ? 8 : 5; }

// The values a node stores, channel-major (value[c * n*n + sample]): the samples' own values at
// level 0, else their zigzag-coded differences from the prediction by `coarser`.
std::vector<uint32_t> node_values(const PatchGrid& g, const PatchGrid* coarser, int channels) {
    const size_t n = g.position.size();
    std::vector<uint32_t> v(size_t(channels) * n);
    for (int j = 0; j < g.size; ++j)
        for (int i = 0; i < g.size; ++i) {
            const size_t s = g.index(i, j);
            for (int c = 0; c < channels; ++c) {
                const int value = channel_value(g, s, c);
                v[size_t(c) * n + s] =
                    coarser ? zigzag(value - predict_from_coarser(*coarser, c, i, j), channel_bits(c)) : uint32_t(value);
            }
        }
    return v;
}

// The samples a version-3 plane holds, in grid order: all of them at level 0; at a finer level
// only those the coarser level does not have (not both coordinates even): the others' deltas are
// 0 by construction (levels nest), so a decoder knows them without storing them.
std::vector<uint32_t> stored_samples(int side, bool delta) {
    std::vector<uint32_t> out;
    for (int j = 0; j < side; ++j)
        for (int i = 0; i < side; ++i)
            if (!delta || i % 2 || j % 2) out.push_back(uint32_t(j * side + i));
    return out;
}

// Versions 3-4: one byte plane per 8-bit channel and two (high, low) per 16-bit one, one plane
// per row of an 8-bit grey image, the tile's patches side by side in each row. Planes keep alike
// bytes together: a position's high byte is nearly always 0 in a delta level, and deflate sees
// long runs of it instead of every sixth byte. A whole plane per row (not n rows of n) because
// libpng's cost is per row: with 17-byte rows, decoding took longer than the RGB16 layout's.
// Writes patch `q` of a tile whose rows are `width` bytes (`values`: node_values of its grid).
void put_byte_planes(const std::vector<uint32_t>& v, int side, int channels, const std::vector<uint32_t>& stored, size_t q,
                     PngImage& im) {
    const size_t n = size_t(side) * side, m = stored.size(), width = size_t(im.width);
    size_t row = 0;
    for (int c = 0; c < channels; ++c) {
        const uint32_t* values = &v[size_t(c) * n];
        uint16_t* out = &im.values[row * width + q * m];
        if (channel_bits(c) == 16) {
            for (size_t k = 0; k < m; ++k) out[k] = uint16_t(values[stored[k]] >> 8);
            out += width;
            for (size_t k = 0; k < m; ++k) out[k] = uint16_t(values[stored[k]] & 0xff);
            row += 2;
        } else {
            for (size_t k = 0; k < m; ++k) out[k] = uint16_t(values[stored[k]]);
            row += 1;
        }
    }
}

// Planes per sample: two per 16-bit channel, one per 8-bit one.
int plane_count(int channels) { return channels + 3; }

// A level-0 grid's samples in grid order, (0,0), (1,0), (0,1), (1,1), are corners 0, 1, 3, 2.
constexpr int kCornerOfSample[4] = {0, 1, 3, 2};

// A level-0 tile's samples with shared corners (version 5): walking its patches in order, each
// patch's four samples in grid order, the (patch, sample) where each quad vertex first appears,
// and for every (patch, sample) the index of its quad vertex's stored sample. A patch's own
// corners are distinct, so a tile of one stores its four samples as versions 3-4 do. A stored
// position is local to the patch it is stored for; another patch showing it moves it by the
// difference of their origins (the world grid position is the same: the converter computes each
// sample once). Why: a quad vertex is a corner of 3 to about 8 patches, and byte planes keep
// deflate from finding the repeats; on the 2M-triangle scan-like mesh level 0 went from 42,759
// to 17,917 bytes.
struct SharedCorners {
    std::vector<std::pair<uint32_t, int>> stored;  // (patch in the tile, sample)
    std::vector<std::array<uint32_t, 4>> index;    // per patch and sample: position in `stored`
};

SharedCorners shared_corners(const TilePatches& patches) {
    SharedCorners out;
    std::unordered_map<uint32_t, uint32_t> at;
    for (uint32_t q = 0; q < patches.size(); ++q) {
        std::array<uint32_t, 4>& index = out.index.emplace_back();
        for (int s = 0; s < 4; ++s) {
            auto [it, first] = at.emplace(patches[q].corner[size_t(kCornerOfSample[s])], uint32_t(out.stored.size()));
            if (first) out.stored.emplace_back(q, s);
            index[size_t(s)] = it->second;
        }
    }
    return out;
}

// Moves the position of sample s in level-0 values (node_values: channels x 4) from the frame of
// patch `from` to that of patch `to`; false when it falls outside 16 bits there.
bool move_position(std::vector<uint32_t>& v, int s, const AqpPatchInfo& from, const AqpPatchInfo& to) {
    for (int a = 0; a < 3; ++a) {
        uint32_t& x = v[size_t(a) * 4 + size_t(s)];
        const int64_t moved = int64_t(x) + int64_t(from.origin[size_t(a)]) - int64_t(to.origin[size_t(a)]);
        if (moved < 0 || moved > 0xffff) return false;
        x = uint32_t(moved);
    }
    return true;
}

// Writes sample s of a level-0 grid's values (node_values) into column k of the byte planes.
void put_corner(const std::vector<uint32_t>& v, int channels, int s, size_t k, PngImage& im) {
    const size_t width = size_t(im.width);
    size_t row = 0;
    for (int c = 0; c < channels; ++c) {
        const uint32_t value = v[size_t(c) * 4 + size_t(s)];
        if (channel_bits(c) == 16) {
            im.values[row * width + k] = uint16_t(value >> 8);
            im.values[(row + 1) * width + k] = uint16_t(value & 0xff);
            row += 2;
        } else {
            im.values[row++ * width + k] = uint16_t(value);
        }
    }
}

// The inverse: column k of the byte planes into sample s of a level-0 grid's values.
void get_corner(const PngImage& im, int channels, size_t k, int s, std::vector<uint32_t>& v) {
    const size_t width = size_t(im.width);
    size_t row = 0;
    for (int c = 0; c < channels; ++c) {
        uint32_t& value = v[size_t(c) * 4 + size_t(s)];
        if (channel_bits(c) == 16) {
            value = uint32_t(im.values[row * width + k]) << 8 | im.values[(row + 1) * width + k];
            row += 2;
        } else {
            value = im.values[row++ * width + k];
        }
    }
}

// Versions 1-2: RGB 16-bit, positions on the left half, normals and colours on the right.
PngImage rgb16_pixels(const std::vector<uint32_t>& v, int side, int channels) {
    const size_t n = size_t(side) * side;
    auto at = [&](int c, size_t s) { return c < channels ? v[size_t(c) * n + s] : 0u; };
    PngImage im;
    im.width = 2 * side;
    im.height = side;
    im.channels = 3;
    im.bit_depth = 16;
    im.values.resize(im.value_count());
    for (int j = 0; j < side; ++j)
        for (int i = 0; i < side; ++i) {
            const size_t s = size_t(j) * side + i;
            uint16_t* left = &im.values[(size_t(j) * im.width + i) * 3];
            uint16_t* right = &im.values[(size_t(j) * im.width + side + i) * 3];
            for (int c = 0; c < 3; ++c) left[c] = uint16_t(at(c, s));
            right[0] = uint16_t(at(3, s) << 8 | at(4, s));
            right[1] = uint16_t(at(5, s) << 8 | at(6, s));
            right[2] = uint16_t(at(7, s) << 8);
        }
    return im;
}

// The inverse of put_byte_planes (patch q of the tile) / rgb16_pixels on a decoded image of the
// expected shape; an empty string, or what is wrong (bits outside the channels).
// (planes: `stored` as put_byte_planes had it; the samples left out stay 0).
std::string unpack_values(const PngImage& im, int side, int channels, bool planes, const std::vector<uint32_t>& stored,
                          size_t q, std::vector<uint32_t>& v) {
    const size_t n = size_t(side) * side;
    v.assign(size_t(channels) * n, 0);
    if (planes) {
        const size_t m = stored.size(), width = size_t(im.width);
        const uint16_t* byte = im.values.data() + q * m;
        for (int c = 0; c < channels; ++c) {
            uint32_t* values = &v[size_t(c) * n];
            if (channel_bits(c) == 16) {
                for (size_t k = 0; k < m; ++k) values[stored[k]] = uint32_t(byte[k]) << 8 | byte[width + k];
                byte += 2 * width;
            } else {
                for (size_t k = 0; k < m; ++k) values[stored[k]] = byte[k];
                byte += width;
            }
        }
        return "";
    }
    for (int j = 0; j < side; ++j)
        for (int i = 0; i < side; ++i) {
            const size_t s = size_t(j) * side + i;
            const uint16_t* left = &im.values[(size_t(j) * im.width + i) * 3];
            const uint16_t* right = &im.values[(size_t(j) * im.width + side + i) * 3];
            if ((right[2] & 0xff) != 0 || (channels < kChannels && (right[1] != 0 || right[2] != 0)))
                return strprintf("AQP node sample (%d, %d) has bits set outside its channels", i, j);
            const uint32_t all[kChannels] = {left[0], left[1], left[2], uint32_t(right[0] >> 8), uint32_t(right[0] & 0xff),
                                             uint32_t(right[1] >> 8), uint32_t(right[1] & 0xff), uint32_t(right[2] >> 8)};
            for (int c = 0; c < channels; ++c) v[size_t(c) * n + s] = all[c];
        }
    return "";
}

// Channel c of every sample of `g`, row-major.
void channel_plane(const PatchGrid& g, int c, std::vector<int>& out) {
    out.resize(g.position.size());
    for (size_t s = 0; s < out.size(); ++s) out[s] = channel_value(g, s, c);
}

// Turns a level's zigzag-coded deltas (side x side, row-major, in place) into values: adds
// predict_from_coarser's prediction from `coarse` (the channel at the level below, side / 2 + 1
// per row) modulo mask + 1. Even rows lie on a coarse row (even columns: the coarse sample, odd:
// the mean of its two neighbours on the row); odd rows between two (even columns: the mean of
// the samples above and below, odd: of the drawn diagonal's ends).
void add_prediction(const int* coarse, int side, uint32_t mask, uint32_t* values) {
    const int cs = side / 2 + 1;
    for (int j = 0; j < side; ++j) {
        const int* lo = coarse + size_t(j / 2) * cs;
        const int* hi = j % 2 ? lo + cs : lo;  // the coarse row above, for odd rows
        uint32_t* row = values + size_t(j) * side;
        for (int i = 0; i < side; ++i) {
            const int ci = i / 2;
            int prediction;
            if (j % 2 == 0) prediction = i % 2 == 0 ? lo[ci] : (lo[ci] + lo[ci + 1]) >> 1;
            else prediction = i % 2 == 0 ? (lo[ci] + hi[ci]) >> 1 : (lo[ci] + hi[ci + 1]) >> 1;
            row[i] = uint32_t(prediction + unzigzag(row[i])) & mask;
        }
    }
}

}  // namespace

namespace {

// A grid's stored values (node_values), after checking its shape and, in the byte-plane layout,
// that it nests in `coarser`: the samples a coarser level has are left out of its planes.
std::vector<uint32_t> checked_node_values(const PatchGrid& g, const PatchGrid* coarser, NodeLayout layout) {
    const size_t n = size_t(g.size) * g.size;
    assert(g.size == (1 << g.level) + 1 && g.position.size() == n && g.normal.size() == n);
    assert(!layout.colors || g.color.size() == n);
    assert((g.level == 0) == (coarser == nullptr));
    assert(!coarser || (coarser->size == g.size / 2 + 1 && coarser->patch == g.patch));
    const int channels = channel_count(layout);
    std::vector<uint32_t> values = node_values(g, coarser, channels);
    if (layout.byte_planes && coarser)
        for (int c = 0; c < channels; ++c)
            for (int j = 0; j < g.size; j += 2)
                for (int i = 0; i < g.size; i += 2)
                    if (values[size_t(c) * n + g.index(i, j)] != 0)
                        fail("patch %u level %d sample (%d, %d) is not its coarser level's sample: levels must nest",
                             g.patch, g.level, i, j);
    return values;
}

// The grid of `patch` at `level` from its stored values (unpack_values; in place) and its
// decoded coarser level (nullptr at level 0).
void values_to_grid(std::vector<uint32_t>& v, uint32_t patch, int level, bool colors, int channels, const PatchGrid* coarser,
                    PatchGrid& out) {
    const int side = (1 << level) + 1;
    out.patch = patch;
    out.level = level;
    out.size = side;
    const size_t n = size_t(side) * side;
    // Channel by channel: stored values become values in place (planar loops, a row of coarse
    // samples at a time, instead of predict_from_coarser's per-sample branches: the same sums).
    if (coarser) {
        std::vector<int> coarse;
        for (int c = 0; c < channels; ++c) {
            channel_plane(*coarser, c, coarse);
            add_prediction(coarse.data(), side, (1u << channel_bits(c)) - 1, &v[size_t(c) * n]);
        }
    }
    out.position.resize(n);
    out.normal.resize(n);
    out.color.assign(colors ? n : 0, Rgb8{0, 0, 0});
    const uint32_t *x = &v[0], *y = &v[n], *z = &v[2 * n], *nu = &v[3 * n], *nv = &v[4 * n];
    for (size_t s = 0; s < n; ++s) {
        out.position[s] = {uint16_t(x[s]), uint16_t(y[s]), uint16_t(z[s])};
        out.normal[s] = uint16_t(nu[s] | (nv[s] << 8));
    }
    if (colors) {
        const uint32_t *r = &v[5 * n], *g = &v[6 * n], *b = &v[7 * n];
        for (size_t s = 0; s < n; ++s) out.color[s] = {uint8_t(r[s]), uint8_t(g[s]), uint8_t(b[s])};
    }
}

// Whether `coarser` can be level - 1 of a patch in this layout.
bool usable_coarser(const PatchGrid* coarser, int level, bool colors) {
    const int side = (1 << level) + 1;
    return coarser && coarser->size == side / 2 + 1 && coarser->position.size() == size_t(coarser->size) * coarser->size &&
           coarser->normal.size() == coarser->position.size() &&
           coarser->color.size() == (colors ? coarser->position.size() : 0);
}

}  // namespace

std::vector<uint8_t> encode_tile_node(const std::vector<const PatchGrid*>& grids, const std::vector<const PatchGrid*>& coarser,
                                      bool colors, int compression, const TilePatches& patches) {
    assert(!grids.empty() && (coarser.empty() || coarser.size() == grids.size()));
    const NodeLayout layout{colors, true, !patches.empty()};
    const int side = grids[0]->size, channels = channel_count(layout);
    if (grids[0]->level == 0 && layout.shared_corners && grids.size() > 1) {
        assert(patches.size() == grids.size() && coarser.empty());
        const SharedCorners shared = shared_corners(patches);
        PngImage im{int(shared.stored.size()), plane_count(channels), 1, 8, {}};
        im.values.resize(im.value_count());
        std::vector<std::vector<uint32_t>> values(grids.size());
        for (size_t q = 0; q < grids.size(); ++q) values[q] = checked_node_values(*grids[q], nullptr, layout);
        for (size_t k = 0; k < shared.stored.size(); ++k) put_corner(values[shared.stored[k].first], channels, shared.stored[k].second, k, im);
        // Every patch showing a quad vertex must hold the same sample (the converter computes
        // each once): a difference could not be stored.
        for (size_t q = 0; q < grids.size(); ++q)
            for (int s = 0; s < 4; ++s) {
                const auto [first_q, first_s] = shared.stored[shared.index[q][size_t(s)]];
                std::vector<uint32_t> mine = values[q];
                const bool moved = move_position(mine, s, patches[q], patches[first_q]);
                bool same = moved;
                for (int c = 0; same && c < channels; ++c)
                    same = mine[size_t(c) * 4 + size_t(s)] == values[first_q][size_t(c) * 4 + size_t(first_s)];
                if (!same)
                    fail("patches %u and %u differ at their shared corner (quad vertex %u)", grids[q]->patch,
                         grids[first_q]->patch, patches[q].corner[size_t(kCornerOfSample[s])]);
            }
        return png_encode(im, compression, false);
    }
    const std::vector<uint32_t> stored = stored_samples(side, !coarser.empty());
    const size_t width = stored.size() * grids.size();
    if (width > size_t(1) << 30) fail("a tile of %zu patches at level %d is too wide for one image", grids.size(), grids[0]->level);
    PngImage im{int(width), plane_count(channels), 1, 8, {}};
    im.values.resize(im.value_count());
    for (size_t q = 0; q < grids.size(); ++q) {
        assert(grids[q]->size == side);
        const std::vector<uint32_t> values = checked_node_values(*grids[q], coarser.empty() ? nullptr : coarser[q], layout);
        put_byte_planes(values, side, channels, stored, q, im);
    }
    // No row filters: deltas are residuals already, and libpng's filter heuristic picks filters
    // that cost bytes (a 1M-triangle scan-like mesh's dataset 1.8% smaller, the bunny's 0.7%;
    // keeping the filters on level 0, which holds values, was slightly larger still).
    return png_encode(im, compression, false);
}

std::vector<uint8_t> encode_patch_node(const PatchGrid& g, const PatchGrid* coarser, NodeLayout layout, int compression) {
    if (layout.byte_planes) return encode_tile_node({&g}, coarser ? std::vector<const PatchGrid*>{coarser} : std::vector<const PatchGrid*>{},
                                                    layout.colors, compression);
    const std::vector<uint32_t> values = checked_node_values(g, coarser, layout);
    return png_encode(rgb16_pixels(values, g.size, channel_count(layout)), compression, false);
}

std::string decode_tile_node(const uint8_t* data, size_t size, uint32_t first_patch, uint32_t count, int level,
                             NodeLayout layout, const std::vector<const PatchGrid*>& coarser, std::vector<PatchGrid>& out,
                             const TilePatches& patches) {
    if (level < 0 || level > kMaxPatchLevel) return strprintf("patch level %d out of range", level);
    if (count == 0) return "a tile of no patches";
    if (!layout.byte_planes && count != 1) return "a node of this dataset's version holds one patch";
    const int side = (1 << level) + 1;
    const bool colors = layout.colors;
    if (level > 0 && coarser.size() != count)
        return strprintf("decoding level %d needs the tile's decoded level %d", level, level - 1);
    bool any = level == 0;
    for (size_t q = 0; level > 0 && q < count; ++q) {
        if (!coarser[q]) continue;
        if (!usable_coarser(coarser[q], level, colors) || coarser[q]->patch != first_patch + q)
            return strprintf("decoding patch %u at level %d needs its decoded level %d", first_patch + uint32_t(q), level,
                             level - 1);
        any = true;
    }
    if (!any) return "no patch of the tile asked for";
    const int channels = channel_count(layout);
    // (A tile of one patch stores its four samples either way.)
    if (level == 0 && layout.byte_planes && layout.shared_corners && count > 1) {
        if (patches.size() != count) return "decoding a level-0 tile needs its patches' records";
        const SharedCorners shared = shared_corners(patches);
        PngImage image;
        if (const std::string e = png_decode(data, size, int(shared.stored.size()), plane_count(channels), 1, 8, image); !e.empty())
            return "AQP node image: " + e;
        out.assign(count, PatchGrid{});
        std::vector<uint32_t> v(size_t(channels) * 4);
        for (uint32_t q = 0; q < count; ++q) {
            for (int s = 0; s < 4; ++s) {
                const uint32_t k = shared.index[q][size_t(s)];
                get_corner(image, channels, k, s, v);
                if (!move_position(v, s, patches[shared.stored[k].first], patches[q]))
                    return strprintf("AQP level-0 tile: the corner of patch %u at sample %d lies outside the patch's frame",
                                     first_patch + q, s);
            }
            values_to_grid(v, first_patch + q, 0, colors, channels, nullptr, out[q]);
        }
        return "";
    }
    const std::vector<uint32_t> stored = stored_samples(side, level > 0);
    const uint64_t width = uint64_t(stored.size()) * count;
    if (width > uint64_t(1) << 30) return strprintf("a tile of %u patches at level %d is too wide", count, level);
    PngImage image;
    const std::string e = layout.byte_planes ? png_decode(data, size, int(width), plane_count(channels), 1, 8, image)
                                             : png_decode(data, size, 2 * side, side, 3, 16, image);
    if (!e.empty()) return "AQP node image: " + e;
    out.assign(count, PatchGrid{});
    std::vector<uint32_t> v;
    for (size_t q = 0; q < count; ++q) {
        const PatchGrid* c = level > 0 ? coarser[q] : nullptr;
        if (level > 0 && !c) continue;
        if (std::string bad = unpack_values(image, side, channels, layout.byte_planes, stored, q, v); !bad.empty()) return bad;
        values_to_grid(v, first_patch + uint32_t(q), level, colors, channels, c, out[q]);
    }
    return "";
}

std::string decode_patch_node(const uint8_t* data, size_t size, uint32_t patch, int level, NodeLayout layout,
                              const PatchGrid* coarser, PatchGrid& out) {
    if (level > 0 && !usable_coarser(coarser, level, layout.colors))
        return strprintf("decoding level %d needs the patch's decoded level %d", level, level - 1);
    std::vector<PatchGrid> grids;
    if (std::string e = decode_tile_node(data, size, patch, 1, level, layout,
                                         level > 0 ? std::vector<const PatchGrid*>{coarser} : std::vector<const PatchGrid*>{}, grids);
        !e.empty())
        return e;
    out = std::move(grids[0]);
    return "";
}

}  // namespace catpaq::aqp
