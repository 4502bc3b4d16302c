// aqp_node_bench: how to lay out an AQP node's samples in PNG, measured on a dataset's own
// samples. Every node of DATASET.cpq is decoded and re-encoded in several layouts; for each the
// total payload, bits per distinct finest sample and encoding time are printed, as ratios to
// three-png, the first. The stored payload printed above the table is the dataset's own layout.
//
//   three-png     position RGB16, normal GA8, colour RGB8: one PNG each
//   one-png       one RGB16 PNG per node, twice as wide: positions on the left, on the right
//                 R = normal u << 8 | v, G = red << 8 | green, B = blue << 8
//   one-png-delta as one-png, but levels above 0 store each sample's difference from its
//                 prediction by the coarser level (the average of the two coarse neighbours
//                 along the row, the column, or the (i,j)-(i+1,j+1) diagonal), zigzag coded;
//                 samples the coarser level has are 0 (the dataset layout of versions 1-2)
//   three-png-delta  the same differences in three PNGs
//   one-png-delta-geo  as one-png-delta, but normals as differences from the normal of the
//                 decoded positions' grid (integer cross product of central differences): worse
//                 (a 50k sphere at 33 x 33: 45.9 bits per sample against 20.6), the quantized
//                 positions are too coarse a few samples apart to predict 8-bit normals
//   planes-delta  the deltas of one-png-delta as byte planes (x high, x low, ... normal u, v,
//                 red, green, blue) in one 8-bit grey PNG, a plane per row (first measured
//                 as n rows of n per plane: 200k scan-like mesh with colours, 17 x 17, 40.8 bits
//                 per sample against 47.7; bunny 34.7 against 41.6)
//   planes-new    as planes-delta, leaving out the samples a coarser level has (always 0): mixed
//                 while planes were n rows of n (scan 41.5, bunny 32.2); with a plane per row it
//                 pays (1M-triangle mesh 22.7 bits per sample against 25.7) and is the dataset
//                 layout (version 3)
//   planes-cubic-pos  as planes-delta, positions between coarse samples predicted by the 4-tap
//                 cubic (-1 9 9 -1) / 16 where four coarse taps exist: 0.3% smaller on the scan,
//                 0.4% larger on the bunny, not worth a second predictor
// and the one-png-delta nodes with only the positions, the normals or the colours kept (the other
// channels zero), to show where the bytes go. Then tiles: the byte planes of G patches with
// consecutive ids in one image per level, for G = 1 (the dataset layout), 4, 16, 64 and all,
// bytes per level: each PNG pays its fixed overhead (about 60 bytes) and deflate its code tables
// once per tile instead of once per patch (1M-triangle scan-like mesh, 900 patches of 33 x 33:
// 22.7 bits per sample at G = 1, 19.8 at 4, 19.2 at 16; level 0 of all patches in one image
// 27 KB against 101 KB as 900 images).
//
// usage: aqp_node_bench DATASET.cpq [--compression N]
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "aqp/dataset.h"
#include "aqp/png_codec.h"
#include "base/error.h"

using namespace catpaq;
using namespace catpaq::aqp;

namespace {

// Channel values of a sample: x y z (16 bits), normal u v, r g b (8 bits).
struct Sample {
    int v[8];
};

std::vector<Sample> samples_of(const PatchGrid& g, bool colors) {
    std::vector<Sample> out(g.position.size());
    for (size_t s = 0; s < out.size(); ++s) {
        out[s].v[0] = g.position[s][0], out[s].v[1] = g.position[s][1], out[s].v[2] = g.position[s][2];
        out[s].v[3] = g.normal[s] & 0xff, out[s].v[4] = g.normal[s] >> 8;
        for (int c = 0; c < 3; ++c) out[s].v[5 + c] = colors ? g.color[s][c] : 0;
    }
    return out;
}

int zigzag(int x, int bits) {
    const int mod = 1 << bits;
    x = ((x % mod) + mod) % mod;      // into [0, 2^bits)
    if (x >= mod / 2) x -= mod;       // into [-2^(bits-1), 2^(bits-1))
    return x >= 0 ? 2 * x : -2 * x - 1;
}

// Differences from the coarser level's prediction (level l from level l-1's samples).
std::vector<Sample> level_delta(const std::vector<Sample>& fine, const std::vector<Sample>& coarse, int size) {
    const int coarse_size = size / 2 + 1;
    auto c = [&](int i, int j) -> const Sample& { return coarse[size_t(j) * coarse_size + i]; };
    std::vector<Sample> out(fine.size());
    for (int j = 0; j < size; ++j)
        for (int i = 0; i < size; ++i) {
            const Sample& f = fine[size_t(j) * size + i];
            Sample& o = out[size_t(j) * size + i];
            for (int ch = 0; ch < 8; ++ch) {
                const int bits = ch < 3 ? 16 : 8;
                int prediction;
                if (i % 2 == 0 && j % 2 == 0) prediction = c(i / 2, j / 2).v[ch];
                else if (j % 2 == 0) prediction = (c(i / 2, j / 2).v[ch] + c(i / 2 + 1, j / 2).v[ch]) >> 1;
                else if (i % 2 == 0) prediction = (c(i / 2, j / 2).v[ch] + c(i / 2, j / 2 + 1).v[ch]) >> 1;
                else prediction = (c(i / 2, j / 2).v[ch] + c(i / 2 + 1, j / 2 + 1).v[ch]) >> 1;
                o.v[ch] = zigzag(f.v[ch] - prediction, bits);
            }
        }
    return out;
}

// As level_delta, but positions between coarse samples predicted by the 4-tap cubic
// (-1 9 9 -1) / 16 along the row, column or diagonal where all four coarse taps exist (on a
// patch edge they stay on the edge), linearly elsewhere (planes-cubic-pos).
std::vector<Sample> level_delta_cubic(const std::vector<Sample>& fine, const std::vector<Sample>& coarse, int size) {
    const int cs = size / 2 + 1;
    auto c = [&](int i, int j, int ch) -> int { return coarse[size_t(j) * cs + i].v[ch]; };
    auto inside = [&](int i, int j) { return i >= 0 && j >= 0 && i < cs && j < cs; };
    std::vector<Sample> out(fine.size());
    for (int j = 0; j < size; ++j)
        for (int i = 0; i < size; ++i) {
            const Sample& f = fine[size_t(j) * size + i];
            Sample& o = out[size_t(j) * size + i];
            const int ci = i / 2, cj = j / 2;
            int di = 0, dj = 0;
            if (i % 2 && j % 2) di = 1, dj = 1;
            else if (i % 2) di = 1;
            else if (j % 2) dj = 1;
            for (int ch = 0; ch < 8; ++ch) {
                const int bits = ch < 3 ? 16 : 8;
                int prediction;
                if (di == 0 && dj == 0) prediction = c(ci, cj, ch);
                else {
                    const int a = c(ci, cj, ch), b = c(ci + di, cj + dj, ch);
                    // an edge sample (row 0 / last, column 0 / last) only uses its own edge: taps stay on it
                    if (ch < 3 && inside(ci - di, cj - dj) && inside(ci + 2 * di, cj + 2 * dj)) {
                        const int z = c(ci - di, cj - dj, ch), w = c(ci + 2 * di, cj + 2 * dj, ch);
                        int p = (9 * (a + b) - z - w + 8) >> 4;
                        prediction = std::clamp(p, 0, 65535);
                    } else
                        prediction = (a + b) >> 1;
                }
                o.v[ch] = zigzag(f.v[ch] - prediction, bits);
            }
        }
    return out;
}

// The octahedral code (u, v bytes as signed values) of the grid's normal at (i, j), from the
// integer positions alone: central differences along i and j (one-sided on the border), their
// cross product in 64-bit integers, the octahedral projection with integer division. Exact, so
// an encoder and any decoder agree on it.
int64_t divide_rounded(int64_t a, int64_t b) {  // a / b rounded half away from zero, b > 0
    return a >= 0 ? (2 * a + b) / (2 * b) : -((-2 * a + b) / (2 * b));
}

std::pair<int, int> geometric_normal(const std::vector<Sample>& s, int size, int i, int j) {
    auto at = [&](int x, int y) -> const Sample& { return s[size_t(y) * size + x]; };
    const Sample &a = at(std::min(i + 1, size - 1), j), &b = at(std::max(i - 1, 0), j);
    const Sample &c = at(i, std::min(j + 1, size - 1)), &d = at(i, std::max(j - 1, 0));
    int64_t du[3], dv[3];
    for (int k = 0; k < 3; ++k) du[k] = a.v[k] - b.v[k], dv[k] = c.v[k] - d.v[k];
    const int64_t n[3] = {du[1] * dv[2] - du[2] * dv[1], du[2] * dv[0] - du[0] * dv[2], du[0] * dv[1] - du[1] * dv[0]};
    const int64_t l1 = std::llabs(n[0]) + std::llabs(n[1]) + std::llabs(n[2]);
    if (l1 == 0) return {0, 0};
    int64_t u = n[0], v = n[1];
    if (n[2] < 0) {
        u = (l1 - std::llabs(n[1])) * (n[0] < 0 ? -1 : 1);
        v = (l1 - std::llabs(n[0])) * (n[1] < 0 ? -1 : 1);
    }
    return {int(divide_rounded(127 * u, l1)), int(divide_rounded(127 * v, l1))};
}

// The normal bytes replaced by their difference from geometric_normal (of the original positions),
// zigzag coded; other channels as given.
std::vector<Sample> normals_from_geometry(const std::vector<Sample>& values, const std::vector<Sample>& original, int size) {
    std::vector<Sample> out = values;
    for (int j = 0; j < size; ++j)
        for (int i = 0; i < size; ++i) {
            auto [pu, pv] = geometric_normal(original, size, i, j);
            Sample& o = out[size_t(j) * size + i];
            const Sample& x = original[size_t(j) * size + i];
            o.v[3] = zigzag(int(int8_t(uint8_t(x.v[3]))) - pu, 8);
            o.v[4] = zigzag(int(int8_t(uint8_t(x.v[4]))) - pv, 8);
        }
    return out;
}

size_t three_png(const std::vector<Sample>& s, int size, bool colors, int compression) {
    PngImage pos{size, size, 3, 16, {}}, nrm{size, size, 2, 8, {}}, rgb{size, size, 3, 8, {}};
    for (const Sample& x : s) {
        pos.values.insert(pos.values.end(), {uint16_t(x.v[0]), uint16_t(x.v[1]), uint16_t(x.v[2])});
        nrm.values.insert(nrm.values.end(), {uint16_t(x.v[3]), uint16_t(x.v[4])});
        rgb.values.insert(rgb.values.end(), {uint16_t(x.v[5]), uint16_t(x.v[6]), uint16_t(x.v[7])});
    }
    size_t bytes = 8 + 4 + png_encode(pos, compression).size() + 4 + png_encode(nrm, compression).size();
    if (colors) bytes += 4 + png_encode(rgb, compression).size();
    return bytes;
}

size_t one_png(const std::vector<Sample>& s, int size, int compression) {
    PngImage im{2 * size, size, 3, 16, {}};
    im.values.resize(im.value_count());
    for (int j = 0; j < size; ++j)
        for (int i = 0; i < size; ++i) {
            const Sample& x = s[size_t(j) * size + i];
            uint16_t* left = &im.values[(size_t(j) * 2 * size + i) * 3];
            uint16_t* right = &im.values[(size_t(j) * 2 * size + size + i) * 3];
            left[0] = uint16_t(x.v[0]), left[1] = uint16_t(x.v[1]), left[2] = uint16_t(x.v[2]);
            right[0] = uint16_t(x.v[3] << 8 | x.v[4]);
            right[1] = uint16_t(x.v[5] << 8 | x.v[6]);
            right[2] = uint16_t(x.v[7] << 8);
        }
    return png_encode(im, compression).size();
}


// Byte planes in one 8-bit grey PNG, a plane per row, no row filters (planes-delta; planes-new,
// `skip_old`, leaves out the samples the coarser level has: the dataset layout of version 3).
size_t planes_png(const std::vector<Sample>& s, int size, bool colors, bool skip_old, int compression) {
    std::vector<int> order;
    for (int j = 0; j < size; ++j)
        for (int i = 0; i < size; ++i)
            if (!(skip_old && i % 2 == 0 && j % 2 == 0)) order.push_back(j * size + i);
    std::vector<uint16_t> bytes;
    const int planes_n = colors ? 11 : 8;
    for (int pl = 0; pl < planes_n; ++pl)
        for (int idx : order) {
            const Sample& x = s[size_t(idx)];
            int v;
            if (pl < 6) v = pl % 2 == 0 ? x.v[pl / 2] >> 8 : x.v[pl / 2] & 0xff;
            else v = x.v[pl - 3];
            bytes.push_back(uint16_t(v));
        }
    PngImage im{int(order.size()), planes_n, 1, 8, std::move(bytes)};
    return png_encode(im, compression, false).size();
}

// Byte planes of several patches' nodes of one level in one 8-bit grey PNG, plane-major (plane 0
// of every patch, then plane 1, ...), a plane of every patch per row, the samples of the coarser
// level left out (`skip_old`) as in the dataset: what grouping patches into tiles would save.
size_t tile_png(const std::vector<const std::vector<Sample>*>& nodes, int size, bool colors, bool skip_old, int compression) {
    const int planes_n = colors ? 11 : 8;
    std::vector<uint16_t> bytes;
    size_t per_row = 0;
    for (int pl = 0; pl < planes_n; ++pl) {
        per_row = 0;
        for (const std::vector<Sample>* node : nodes)
            for (size_t s = 0; s < node->size(); ++s) {
                if (skip_old && (s % size_t(size)) % 2 == 0 && (s / size_t(size)) % 2 == 0) continue;
                const Sample& x = (*node)[s];
                bytes.push_back(uint16_t(pl < 6 ? (pl % 2 == 0 ? x.v[pl / 2] >> 8 : x.v[pl / 2] & 0xff) : x.v[pl - 3]));
                ++per_row;
            }
    }
    PngImage im{int(per_row), planes_n, 1, 8, std::move(bytes)};
    return png_encode(im, compression, false).size();
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: aqp_node_bench DATASET.cpq [--compression N]\n");
        return 2;
    }
    int compression = 6;
    for (int i = 2; i + 1 < argc; ++i)
        if (!std::strcmp(argv[i], "--compression")) compression = std::atoi(argv[i + 1]);
    try {
        AqpDataset d(argv[1]);
        const bool colors = d.meta().has_colors();
        const int k = d.finest_level();
        // The dataset's node bytes (whatever its tiles).
        size_t stored = 0;
        for (const ArchiveEntry& e : d.archive().entries()) stored += e.size;
        struct Variant {
            const char* name;
            size_t bytes = 0;
            double seconds = 0;
        } variants[12] = {{"three-png"},           {"one-png"},          {"one-png-delta"},    {"three-png-delta"},
                         {"  positions only"},    {"  normals only"},   {"  colours only"},
                         {"one-png-delta-geo"},   {"  geo normals only"}, {"planes-delta"}, {"planes-new"}, {"planes-cubic-pos"}};
        size_t finest_patch_samples = 0;
        // Every node's deltas, by level and patch, for the tile measurement below.
        std::vector<std::vector<std::vector<Sample>>> deltas(size_t(k) + 1, std::vector<std::vector<Sample>>(d.patch_count()));
        for (uint32_t p = 0; p < d.patch_count(); ++p) {
            std::vector<Sample> coarser;
            for (int l = 0; l <= k; ++l) {
                const PatchGrid g = d.decode(p, l);
                const std::vector<Sample> s = samples_of(g, colors);
                if (l == k) finest_patch_samples += s.size();
                auto timed = [&](Variant& v, auto&& encode) {
                    auto t = std::chrono::steady_clock::now();
                    v.bytes += encode();
                    v.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
                };
                timed(variants[0], [&] { return three_png(s, g.size, colors, compression); });
                timed(variants[1], [&] { return one_png(s, g.size, compression); });
                const std::vector<Sample> delta = l == 0 ? s : level_delta(s, coarser, g.size);
                timed(variants[2], [&] { return one_png(delta, g.size, compression); });
                timed(variants[3], [&] { return three_png(delta, g.size, colors, compression); });
                const std::vector<Sample> geo = normals_from_geometry(delta, s, g.size);
                timed(variants[7], [&] { return one_png(geo, g.size, compression); });
                {
                    std::vector<Sample> only = geo;
                    for (Sample& x : only)
                        for (int ch : {0, 1, 2, 5, 6, 7}) x.v[ch] = 0;
                    timed(variants[8], [&] { return one_png(only, g.size, compression); });
                }
                timed(variants[9], [&] { return planes_png(delta, g.size, colors, false, compression); });
                deltas[size_t(l)][p] = delta;
                timed(variants[10], [&] { return planes_png(delta, g.size, colors, l > 0, compression); });
                timed(variants[11], [&] {
                    return planes_png(l > 0 ? level_delta_cubic(s, coarser, g.size) : delta, g.size, colors, false, compression);
                });
                // The one-png-delta node with all but some channels zeroed: where the bytes go.
                for (int part = 0; part < 3; ++part) {
                    std::vector<Sample> only = delta;
                    for (Sample& x : only)
                        for (int ch = 0; ch < 8; ++ch)
                            if ((ch < 3 ? 0 : ch < 5 ? 1 : 2) != part) x.v[ch] = 0;
                    timed(variants[4 + part], [&] { return one_png(only, g.size, compression); });
                }
                coarser = s;
            }
        }
        // Distinct finest samples of a closed layout: about patches x (2^k)^2 (edges and corners shared).
        const double distinct = double(d.patch_count()) * double(1 << k) * double(1 << k);
        std::printf("dataset %s: %zu patches, level %d, colours %s, stored payload %zu bytes (%.2f bits per sample)\n",
                    argv[1], d.patch_count(), k, colors ? "yes" : "no", stored, 8.0 * double(stored) / distinct);
        std::printf("%-14s %12s %10s %12s %10s\n", "layout", "bytes", "ratio", "bits/sample", "encode s");
        for (const Variant& v : variants)
            std::printf("%-14s %12zu %10.3f %12.2f %10.3f\n", v.name, v.bytes, double(v.bytes) / double(variants[0].bytes),
                        8.0 * double(v.bytes) / distinct, v.seconds);
        (void)finest_patch_samples;
        // Tiles: G patches (consecutive ids) per PNG at each level, bytes per level.
        std::printf("\ntiles of G patches per image (no row filters), bytes by level (coarse to fine):\n");
        for (size_t group : {size_t(1), size_t(4), size_t(16), size_t(64), d.patch_count()}) {
            std::printf("G %5zu:", group);
            size_t total = 0;
            for (int l = 0; l <= k; ++l) {
                size_t bytes = 0;
                for (size_t first = 0; first < d.patch_count(); first += group) {
                    std::vector<const std::vector<Sample>*> nodes;
                    for (size_t p = first; p < std::min(d.patch_count(), first + group); ++p) nodes.push_back(&deltas[size_t(l)][p]);
                    bytes += tile_png(nodes, (1 << l) + 1, colors, l > 0, compression);
                }
                total += bytes;
                std::printf(" %9zu", bytes);
            }
            std::printf("  total %zu (%.2f bits per sample)\n", total, 8.0 * double(total) / distinct);
        }
    } catch (const Error& e) {
        std::fprintf(stderr, "aqp_node_bench: %s\n", e.what());
        return 1;
    }
    return 0;
}
