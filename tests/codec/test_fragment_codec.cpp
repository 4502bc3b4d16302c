#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "base/checksum.h"
#include "common_codec/barycentric.h"
#include "common_codec/fragment_codec.h"
#include "common_codec/octahedral.h"

using namespace catpaq;

namespace {

// Byte offsets of the format (fragment_codec.cpp): header, then u16 header fold, u8 coding,
// u8 modes (compressed coding only).
constexpr size_t kHeaderSize = 24;
constexpr size_t kCodingOffset = 26;
constexpr size_t kModesOffset = 27;

uint64_t key(const PackedVertex& v) { return (uint64_t(v.word1) << 32) | v.word0; }

// The mesh as what the codec promises to keep: the multiset of vertices and the multiset of
// triangles as vertex-content triples, each rotated to start at its smallest rotation (so
// orientation is kept but the starting corner is not).
struct Canonical {
    std::vector<uint64_t> vertices;
    std::vector<std::array<uint64_t, 3>> triangles;
    bool operator==(const Canonical& o) const { return vertices == o.vertices && triangles == o.triangles; }
};

Canonical canonical(const FragmentMesh& m) {
    Canonical c;
    for (const PackedVertex& v : m.vertices) c.vertices.push_back(key(v));
    std::sort(c.vertices.begin(), c.vertices.end());
    for (size_t t = 0; t < m.triangle_count(); ++t) {
        std::array<uint64_t, 3> k = {key(m.vertices[m.indices[3 * t]]), key(m.vertices[m.indices[3 * t + 1]]),
                                     key(m.vertices[m.indices[3 * t + 2]])};
        std::array<uint64_t, 3> best = k;
        for (int r = 1; r < 3; ++r) {
            std::array<uint64_t, 3> rot = {k[size_t(r)], k[size_t((r + 1) % 3)], k[size_t((r + 2) % 3)]};
            best = std::min(best, rot);
        }
        c.triangles.push_back(best);
    }
    std::sort(c.triangles.begin(), c.triangles.end());
    return c;
}

std::vector<uint8_t> encode(const FragmentMesh& m, FragmentEncodeStats* stats = nullptr, int version = kFragmentVersion) {
    std::vector<uint8_t> bytes;
    size_t n = fragment_encode(m, bytes, stats, version);
    EXPECT_EQ(bytes[4], version);
    EXPECT_EQ(n, bytes.size());
    EXPECT_LE(n, fragment_encode_bound(m.vertices.size(), m.triangle_count()));
    return bytes;
}

// Encodes, decodes and checks the round trip; returns the encoded bytes.
std::vector<uint8_t> expect_round_trip(const FragmentMesh& m, int version = kFragmentVersion) {
    FragmentEncodeStats stats;
    std::vector<uint8_t> bytes = encode(m, &stats, version);
    EXPECT_EQ(stats.header_bytes + stats.connectivity_bytes + stats.position_bytes + stats.normal_bytes +
                  stats.color_bytes,
              bytes.size());
    uint32_t vc = 0, tc = 0;
    EXPECT_EQ(fragment_peek(bytes.data(), bytes.size(), vc, tc), FragmentStatus::Ok);
    EXPECT_EQ(vc, m.vertices.size());
    EXPECT_EQ(tc, m.triangle_count());
    FragmentMesh out;
    out.vertices.resize(3);  // previous contents must be replaced
    FragmentStatus st = fragment_decode(bytes.data(), bytes.size(), out);
    EXPECT_EQ(st, FragmentStatus::Ok) << fragment_status_name(st);
    EXPECT_EQ(out.vertices.size(), m.vertices.size());
    EXPECT_EQ(out.indices.size(), m.indices.size());
    for (uint32_t i : out.indices) EXPECT_LT(i, out.vertices.size());
    EXPECT_TRUE(canonical(out) == canonical(m)) << "decoded fragment differs";
    return bytes;
}

// Test-only: recomputes the header fold and the checksum after a mutation, so the payload
// parser itself (not the checksum) sees the mutated bytes.
void refresh_integrity(std::vector<uint8_t>& b) {
    if (b.size() < kHeaderSize) return;
    if (b.size() >= kHeaderSize + 2) {
        uint16_t fold = 0;
        for (size_t at = 4; at < 16; at += 2) fold ^= uint16_t(b[at] | (b[at + 1] << 8));
        b[kHeaderSize] = uint8_t(fold);
        b[kHeaderSize + 1] = uint8_t(fold >> 8);
    }
    uint64_t sum = checksum64(b.data() + kHeaderSize, b.size() - kHeaderSize);
    for (int i = 0; i < 8; ++i) b[16 + size_t(i)] = uint8_t(sum >> (8 * i));
}

// ---- realistic vertex content ---------------------------------------------------------------

// A Kuhn tetrahedron with canonical corners (lattice cell of side 1024).
std::array<LatticePoint, 4> kuhn_tet() {
    std::array<LatticePoint, 4> c = {LatticePoint{0, 0, 0}, LatticePoint{1024, 0, 0}, LatticePoint{1024, 1024, 0},
                                     LatticePoint{1024, 1024, 1024}};
    canonical_order(c);
    return c;
}

PackedVertex smooth_vertex(const double p[3], const double n[3], const VertexLayout& layout) {
    uint16_t normal = oct_encode_precise(float(n[0]), float(n[1]), float(n[2]));
    auto chan = [](double x) { return uint8_t(std::clamp(128.0 + 100.0 * std::sin(x), 0.0, 255.0)); };
    const uint8_t rgb[3] = {chan(p[0] * 0.01), chan(p[1] * 0.013 + 1.0), chan(p[2] * 0.017 + 2.0)};
    return pack_vertex(layout, bary_quantize(p, kuhn_tet(), 0xf, layout.grid), normal, rgb);
}

// A regular grid patch of n x n vertices (2 (n-1)^2 triangles) on a gently curved surface inside
// the Kuhn tetrahedron (1024 >= x >= y >= z >= 0), appended to `m`. Grid coordinates
// (x0 + i step, y0 + j step) must stay within [0, 610].
void add_grid(FragmentMesh& m, int n, double x0, double y0, double step) {
    uint32_t base = uint32_t(m.vertices.size());
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            double gx = x0 + i * step, gy = y0 + j * step;
            double p[3] = {400.0 + 0.95 * gx, 20.0 + 0.6 * gy, 12.0 + 6.0 * std::sin(gx * 0.02) * std::cos(gy * 0.03)};
            double nn[3] = {-0.1 * std::cos(gx * 0.02), 0.2 * std::sin(gy * 0.03), 1.0};
            m.vertices.push_back(smooth_vertex(p, nn, m.layout));
        }
    for (int j = 0; j + 1 < n; ++j)
        for (int i = 0; i + 1 < n; ++i) {
            uint32_t a = base + uint32_t(j * n + i), b = a + 1, c = a + uint32_t(n), d = c + 1;
            m.indices.insert(m.indices.end(), {a, b, d, a, d, c});
        }
}

FragmentMesh grid_patch(int n, const VertexLayout& layout = {}) {
    FragmentMesh m;
    m.layout = layout;
    add_grid(m, n, 0.0, 0.0, 600.0 / (n - 1));
    return m;
}

// Subdivided icosahedron inside the Kuhn tetrahedron, with exact sphere normals.
FragmentMesh icosphere(int subdivisions, const VertexLayout& layout = {}) {
    const double t = (1.0 + std::sqrt(5.0)) / 2.0;
    std::vector<std::array<double, 3>> p = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                                            {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
    std::vector<uint32_t> f = {0, 11, 5, 0, 5,  1,  0, 1, 7, 0, 7,  10, 0, 10, 11, 1, 5, 9, 5, 11,
                               4, 11, 10, 2, 10, 7, 6, 7, 1, 8, 3,  9,  4, 3,  4,  2, 3, 2, 6, 3,
                               6, 8,  3,  8, 9,  4, 9, 5, 2, 4, 11, 6,  2, 10, 8,  6, 7, 9, 8, 1};
    for (auto& v : p) {
        double l = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
        for (double& x : v) x /= l;
    }
    for (int s = 0; s < subdivisions; ++s) {
        std::map<std::pair<uint32_t, uint32_t>, uint32_t> mid;
        auto midpoint = [&](uint32_t a, uint32_t b) {
            auto k = std::minmax(a, b);
            auto it = mid.find(k);
            if (it != mid.end()) return it->second;
            std::array<double, 3> m3;
            for (int i = 0; i < 3; ++i) m3[size_t(i)] = p[a][size_t(i)] + p[b][size_t(i)];
            double l = std::sqrt(m3[0] * m3[0] + m3[1] * m3[1] + m3[2] * m3[2]);
            for (double& x : m3) x /= l;
            p.push_back(m3);
            return mid[k] = uint32_t(p.size() - 1);
        };
        std::vector<uint32_t> g;
        for (size_t i = 0; i < f.size(); i += 3) {
            uint32_t a = f[i], b = f[i + 1], c = f[i + 2];
            uint32_t ab = midpoint(a, b), bc = midpoint(b, c), ca = midpoint(c, a);
            g.insert(g.end(), {a, ab, ca, b, bc, ab, c, ca, bc, ab, bc, ca});
        }
        f = g;
    }
    FragmentMesh m;
    m.layout = layout;
    const double center[3] = {700, 450, 200}, radius = 170;
    for (const auto& v : p) {
        double q[3] = {center[0] + radius * v[0], center[1] + radius * v[1], center[2] + radius * v[2]};
        m.vertices.push_back(smooth_vertex(q, v.data(), layout));
    }
    m.indices = f;
    return m;
}

// Random 64-bit vertices: any bit pattern, including invalid position indices.
std::vector<PackedVertex> random_vertices(std::mt19937_64& rng, size_t n) {
    std::vector<PackedVertex> v(n);
    for (auto& x : v) {
        uint64_t r = rng();
        x.word0 = uint32_t(r);
        x.word1 = uint32_t(r >> 32);
    }
    return v;
}

// A grid patch whose colours vary by one step per vertex at most (joint coding) or are random.
FragmentMesh coloured_patch(int n, bool noisy, uint64_t seed) {
    FragmentMesh m = grid_patch(n);
    std::mt19937_64 rng(seed);
    for (size_t i = 0; i < m.vertices.size(); ++i) {
        PackedVertex& v = m.vertices[i];
        const int x = int(i % size_t(n)), y = int(i / size_t(n));
        const uint8_t r = noisy ? uint8_t(rng()) : uint8_t(100 + x / 3), g = noisy ? uint8_t(rng()) : uint8_t(80 + y / 4),
                      b = noisy ? uint8_t(rng()) : uint8_t(30 + (x + y) / 5);
        v = PackedVertex::make(v.position_index(), v.normal(), r, g, b);
    }
    return m;
}

// A small realistic fragment used by the corruption and fuzz tests.
FragmentMesh small_fragment() {
    FragmentMesh m = grid_patch(9);
    add_grid(m, 4, 100.0, 300.0, 20.0);           // second component
    m.vertices.push_back(m.vertices[0]);           // isolated duplicate vertex
    m.indices.insert(m.indices.end(), {0, 1, 1});  // degenerate triangle
    return m;
}

}  // namespace

// ---- round trips ----------------------------------------------------------------------------

TEST(FragmentCodec, RoundTripIsLosslessOnARegularGridPatch) {
    FragmentMesh m = grid_patch(40);
    std::vector<uint8_t> bytes = expect_round_trip(m);
    EXPECT_EQ(bytes[kCodingOffset], 0) << "a smooth grid must use the compressed coding";
    // A regular patch compresses well below the 64-bit vertex + 3 x 32-bit indices.
    EXPECT_LT(bytes.size() * 8.0 / m.vertices.size(), 40.0);
}

TEST(FragmentCodec, RoundTripIsLosslessOnAClosedIcosphere) {
    FragmentMesh m = icosphere(4);  // 2562 vertices, 5120 triangles, no border
    std::vector<uint8_t> bytes = expect_round_trip(m);
    EXPECT_EQ(bytes[kCodingOffset], 0);
}

TEST(FragmentCodec, GeometricNormalPredictorIsChosenForSurfaceNormals) {
    FragmentMesh m = icosphere(3);
    std::vector<uint8_t> bytes = expect_round_trip(m);
    ASSERT_EQ(bytes[kCodingOffset], 0);
    EXPECT_EQ((bytes[kModesOffset] >> 2) & 3, 2) << "normal predictor";
}

TEST(FragmentCodec, WeightSpacePositionCodingIsChosenWhenCheaperAndRoundTrips) {
    // Noise on w2 alone: one coordinate in weight space, two in cumulative space.
    FragmentMesh m = grid_patch(30);
    std::mt19937_64 rng(7);
    for (PackedVertex& v : m.vertices) {
        BaryWeights w;
        ASSERT_TRUE(bary_unpack(v.position_index(), kBaryGrid, w));
        int d = int(rng() % 9) - 4;
        if (w[2] + d >= 0 && w[0] - d >= 0) {
            w[2] += d;
            w[0] -= d;
        }
        v.word0 = (v.word0 & 0xff000000u) | bary_pack(w);
    }
    std::vector<uint8_t> bytes = expect_round_trip(m);
    ASSERT_EQ(bytes[kCodingOffset], 0);
    EXPECT_EQ(bytes[kModesOffset] & 3, 1) << "position coding";
}

TEST(FragmentCodec, RoundTripIsLosslessWithBordersAndSeveralComponents) {
    FragmentMesh m = grid_patch(20);
    add_grid(m, 7, 50.0, 400.0, 10.0);
    add_grid(m, 5, 300.0, 200.0, 10.0);
    // A hole: drop the triangles of a few quads in the middle of the first patch.
    std::vector<uint32_t> kept;
    for (size_t t = 0; t < m.triangle_count(); ++t)
        if (t < 300 || t > 320) kept.insert(kept.end(), m.indices.begin() + 3 * t, m.indices.begin() + 3 * t + 3);
    m.indices = kept;
    expect_round_trip(m);
}

TEST(FragmentCodec, RoundTripIsLosslessWithNonManifoldEdges) {
    FragmentMesh m = grid_patch(10);
    // A fin: a third and fourth triangle on existing edges of the grid.
    uint32_t apex = uint32_t(m.vertices.size());
    m.vertices.push_back(m.vertices[55]);
    m.vertices.back().word1 ^= 0x100;
    m.indices.insert(m.indices.end(), {44, 45, apex, 45, 44, apex, 12, 13, apex});
    // Bow-tie vertex: two fans touching at one vertex.
    add_grid(m, 3, 0, 0, 5);
    uint32_t b = uint32_t(m.vertices.size()) - 9;
    m.indices.insert(m.indices.end(), {b + 4, 60, 61});
    expect_round_trip(m);
}

TEST(FragmentCodec, RoundTripIsLosslessWithFlippedOrientationNeighbours) {
    FragmentMesh m = grid_patch(12);
    std::mt19937_64 rng(3);
    for (size_t t = 0; t < m.triangle_count(); ++t)
        if (rng() % 4 == 0) std::swap(m.indices[3 * t + 1], m.indices[3 * t + 2]);
    expect_round_trip(m);
}

TEST(FragmentCodec, RoundTripIsLosslessWithDegenerateTriangles) {
    FragmentMesh m = grid_patch(8);
    m.indices.insert(m.indices.end(), {3, 3, 4, 5, 6, 5, 7, 7, 7, 9, 10, 9});
    std::vector<uint8_t> bytes = expect_round_trip(m);
    EXPECT_EQ(bytes[kCodingOffset], 0);
}

TEST(FragmentCodec, RoundTripIsLosslessWithDuplicateTriangles) {
    FragmentMesh m = grid_patch(8);
    std::vector<uint32_t> extra(m.indices.begin(), m.indices.begin() + 30);  // same orientation
    m.indices.insert(m.indices.end(), extra.begin(), extra.end());
    m.indices.insert(m.indices.end(), {20, 22, 21, 20, 21, 22, 20, 21, 22});  // both orientations
    expect_round_trip(m);
}

TEST(FragmentCodec, RoundTripIsLosslessWithIsolatedVertices) {
    FragmentMesh m = grid_patch(8);
    std::mt19937_64 rng(11);
    std::vector<PackedVertex> extra = random_vertices(rng, 5);
    m.vertices.insert(m.vertices.begin() + 10, extra.begin(), extra.end());
    for (uint32_t& i : m.indices)
        if (i >= 10) i += 5;
    m.vertices.push_back(m.vertices[0]);  // a duplicate vertex nobody uses
    expect_round_trip(m);
}

TEST(FragmentCodec, RoundTripIsLosslessOnAnEmptyMesh) {
    FragmentMesh m;
    std::vector<uint8_t> bytes = expect_round_trip(m);
    EXPECT_LE(bytes.size(), 32u);
    FragmentMesh onlyVertices;
    std::mt19937_64 rng(5);
    onlyVertices.vertices = random_vertices(rng, 3);
    expect_round_trip(onlyVertices);
}

TEST(FragmentCodec, RoundTripIsLosslessOnASingleTriangle) {
    FragmentMesh m = grid_patch(2);
    m.vertices.erase(m.vertices.begin() + 2);
    m.indices = {0, 1, 2};
    expect_round_trip(m);
}

TEST(FragmentCodec, RoundTripIsLosslessOnRandomWordsAndInvalidPositions) {
    std::mt19937_64 rng(99);
    for (int round = 0; round < 20; ++round) {
        FragmentMesh m = grid_patch(6 + round);
        // Replace the vertex content by arbitrary words (position indices beyond the grid,
        // normal bytes -128): the stored or raw-position paths must still be lossless.
        std::vector<PackedVertex> v = random_vertices(rng, m.vertices.size());
        if (round % 2) {
            // Keep valid positions but random normals and colours.
            for (size_t i = 0; i < v.size(); ++i) v[i].word0 = (v[i].word0 & 0xff000000u) | m.vertices[i].position_index();
        }
        m.vertices = v;
        expect_round_trip(m);
    }
}

TEST(FragmentCodec, PositionIndicesBeyondTheGridUseRawPositionsLosslessly) {
    FragmentMesh m = grid_patch(20);
    for (size_t i = 0; i < m.vertices.size(); i += 7)  // some indices >= kBaryIndexCount
        m.vertices[i].word0 = (m.vertices[i].word0 & 0xff000000u) | (kBaryIndexCount + uint32_t(i));
    std::vector<uint8_t> bytes = expect_round_trip(m);
    ASSERT_EQ(bytes[kCodingOffset], 0) << "smooth normals and colours still compress";
    EXPECT_EQ(bytes[kModesOffset] & 3, 2) << "position coding";
}

TEST(FragmentCodec, TinyIncompressibleFragmentsFallBackToStoredCodingWithinTheBound) {
    std::mt19937_64 rng(17);
    FragmentMesh m;
    m.vertices = random_vertices(rng, 4);
    m.indices = {0, 1, 2, 2, 1, 3};
    std::vector<uint8_t> bytes = expect_round_trip(m);
    EXPECT_EQ(bytes[kCodingOffset], 1) << "stored coding";
    EXPECT_EQ(bytes.size(), fragment_encode_bound(m.vertices.size(), m.triangle_count()));
    // Larger random content still compresses (connectivity) and never exceeds the bound.
    m.vertices = random_vertices(rng, 300);
    m.indices.clear();
    for (int k = 0; k < 600; ++k) m.indices.push_back(uint32_t(rng() % 300));
    bytes = expect_round_trip(m);
    EXPECT_LT(bytes.size(), fragment_encode_bound(m.vertices.size(), m.triangle_count()));
}

TEST(FragmentCodec, RoundTripIsLosslessOnA200kTriangleMesh) {
    FragmentMesh m = grid_patch(318);  // 200,978 triangles
    ASSERT_GE(m.triangle_count(), 200000u);
    std::vector<uint8_t> bytes = expect_round_trip(m);
    EXPECT_EQ(bytes[kCodingOffset], 0);
}

TEST(FragmentCodec, RoundTripIsLosslessOnAHighValenceFanAndStackedDuplicates) {
    FragmentMesh m = grid_patch(3);
    // 3000 triangles around vertex 4 (a non-manifold fan: each rim edge is used many times),
    // then 2000 copies of one triangle.
    for (uint32_t k = 0; k < 3000; ++k) {
        uint32_t a = k % 9, b = (k + 1 + k / 9) % 9;
        if (a == 4 || b == 4 || a == b) continue;
        m.indices.insert(m.indices.end(), {4, a, b});
    }
    for (int k = 0; k < 2000; ++k) m.indices.insert(m.indices.end(), {0, 1, 4});
    expect_round_trip(m);
}

// ---- damaged input --------------------------------------------------------------------------

namespace {

// Fragments of every version in the compressed coding: small_fragment (degenerate triangles,
// two components), icosphere(3) (the geometric normal predictor, which version 2 changed) and a
// patch of smooth colours (version 2's joint colour coding).
std::vector<std::vector<uint8_t>> damage_seeds() {
    std::vector<std::vector<uint8_t>> seeds;
    for (int version = kFragmentOldestVersion; version <= kFragmentVersion; ++version)
        for (const FragmentMesh& m : {small_fragment(), icosphere(3), coloured_patch(9, false, 4)})
            seeds.push_back(encode(m, nullptr, version));
    return seeds;
}

}  // namespace

TEST(FragmentCodec, EveryTruncationIsRejected) {
    int geometric = 0;
    for (const std::vector<uint8_t>& bytes : damage_seeds()) {
        SCOPED_TRACE(int(bytes[4]));
        ASSERT_EQ(bytes[kCodingOffset], 0);
        geometric += ((bytes[kModesOffset] >> 2) & 3) == 2;
        FragmentMesh out;
        for (size_t n = 0; n < bytes.size(); ++n) {
            std::vector<uint8_t> cut(bytes.begin(), bytes.begin() + long(n));  // own allocation: ASan sees overreads
            FragmentStatus st = fragment_decode(cut.data(), cut.size(), out);
            EXPECT_NE(st, FragmentStatus::Ok) << "length " << n;
            if (n < kHeaderSize) {
                EXPECT_EQ(st, FragmentStatus::Truncated);
            }
        }
    }
    EXPECT_EQ(geometric, kFragmentVersion - kFragmentOldestVersion + 1) << "one seed per version with geometric normals";
    int joint = 0;
    for (const std::vector<uint8_t>& bytes : damage_seeds()) joint += (bytes[kModesOffset] >> 6) & 1;
    EXPECT_GE(joint, 1) << "a version 2 seed with the joint colour coding";
}

TEST(FragmentCodec, EverySingleBitFlipIsDetected) {
    for (const std::vector<uint8_t>& bytes : damage_seeds()) {
        SCOPED_TRACE(int(bytes[4]));
        FragmentMesh out;
        ASSERT_EQ(fragment_decode(bytes.data(), bytes.size(), out), FragmentStatus::Ok);
        for (size_t at = 0; at < bytes.size(); ++at)
            for (int bit = 0; bit < 8; ++bit) {
                std::vector<uint8_t> b = bytes;
                b[at] ^= uint8_t(1u << bit);
                FragmentStatus st = fragment_decode(b.data(), b.size(), out);
                ASSERT_NE(st, FragmentStatus::Ok) << "byte " << at << " bit " << bit;
                if (at >= 16) {
                    EXPECT_EQ(st, FragmentStatus::ChecksumMismatch);
                }
            }
    }
}

// With the checksum and the header fold recomputed, every truncation of the payload and every
// changed payload byte reaches the parser: it must answer with an error code or a mesh whose
// indices are in range, never crash or read out of bounds (run under ASan in CI).
TEST(FragmentCodec, CorruptPayloadsWithValidChecksumsGiveErrorCodesInEveryVersion) {
    std::mt19937_64 rng(16);
    for (const std::vector<uint8_t>& bytes : damage_seeds()) {
        SCOPED_TRACE(int(bytes[4]));
        FragmentMesh out;
        size_t ok = 0, tried = 0;
        for (size_t n = kHeaderSize + 3; n < bytes.size(); ++n) {
            std::vector<uint8_t> cut(bytes.begin(), bytes.begin() + long(n));
            refresh_integrity(cut);
            EXPECT_NE(fragment_decode(cut.data(), cut.size(), out), FragmentStatus::Ok) << "length " << n;
        }
        for (size_t at = kHeaderSize + 2; at < bytes.size(); ++at)
            for (int k = 0; k < 4; ++k) {
                std::vector<uint8_t> b = bytes;
                b[at] = uint8_t(rng());
                if (b[at] == bytes[at]) continue;
                refresh_integrity(b);
                const FragmentStatus st = fragment_decode(b.data(), b.size(), out);
                ++tried;
                if (st == FragmentStatus::Ok) {
                    ++ok;
                    for (uint32_t i : out.indices) ASSERT_LT(i, out.vertices.size());
                } else {
                    EXPECT_TRUE(out.vertices.empty() && out.indices.empty());
                }
            }
        // A changed residual can still decode (to other values); most changes are caught.
        EXPECT_LT(ok, tried / 2);
    }
}

TEST(FragmentCodec, ExtraTrailingBytesAreRejected) {
    std::vector<uint8_t> bytes = encode(small_fragment());
    bytes.push_back(0);
    FragmentMesh out;
    EXPECT_EQ(fragment_decode(bytes.data(), bytes.size(), out), FragmentStatus::ChecksumMismatch);
    refresh_integrity(bytes);  // even with a matching checksum the parser finds the extra byte
    EXPECT_EQ(fragment_decode(bytes.data(), bytes.size(), out), FragmentStatus::Corrupt);
}

TEST(FragmentCodec, HeaderFieldsAreValidated) {
    std::vector<uint8_t> bytes = encode(small_fragment());
    FragmentMesh out;
    uint32_t vc, tc;
    std::vector<uint8_t> b = bytes;
    b[0] = 'X';
    EXPECT_EQ(fragment_decode(b.data(), b.size(), out), FragmentStatus::BadMagic);
    for (int version : {0, kFragmentVersion + 1}) {
        b = bytes;
        b[4] = uint8_t(version);
        EXPECT_EQ(fragment_peek(b.data(), b.size(), vc, tc), FragmentStatus::UnsupportedVersion) << version;
    }
    b = bytes;
    b[11] = 0x40;  // vertex count 2^30
    EXPECT_EQ(fragment_peek(b.data(), b.size(), vc, tc), FragmentStatus::TooLarge);
    // A count changed consistently with the checksum is still caught by the header fold...
    b = bytes;
    b[8] ^= 1;
    uint64_t sum = checksum64(b.data() + kHeaderSize, b.size() - kHeaderSize);
    for (int i = 0; i < 8; ++i) b[16 + size_t(i)] = uint8_t(sum >> (8 * i));
    EXPECT_EQ(fragment_decode(b.data(), b.size(), out), FragmentStatus::Corrupt);
    // ... and, with the fold refreshed too, by the payload parser.
    refresh_integrity(b);
    EXPECT_EQ(fragment_decode(b.data(), b.size(), out), FragmentStatus::Corrupt);
    EXPECT_TRUE(out.vertices.empty() && out.indices.empty());
}

TEST(FragmentCodec, FuzzedInputNeverCrashesTheDecoder) {
    std::mt19937_64 rng(2024);
    FragmentMesh out;
    auto check = [&](const std::vector<uint8_t>& b) {
        FragmentStatus st = fragment_decode(b.data(), b.size(), out);
        if (st == FragmentStatus::Ok) {
            uint32_t vc = 0, tc = 0;
            EXPECT_EQ(fragment_peek(b.data(), b.size(), vc, tc), FragmentStatus::Ok);
            EXPECT_EQ(out.vertices.size(), vc);
            EXPECT_EQ(out.indices.size(), 3 * size_t(tc));
            for (uint32_t i : out.indices) EXPECT_LT(i, out.vertices.size());
        } else {
            EXPECT_TRUE(out.vertices.empty() && out.indices.empty());
        }
        return st == FragmentStatus::Ok;
    };
    // Random buffers, with and without a plausible header.
    for (int i = 0; i < 3000; ++i) {
        std::vector<uint8_t> b(rng() % 200);
        for (auto& x : b) x = uint8_t(rng());
        check(b);
        if (b.size() >= kHeaderSize) {
            const uint8_t head[8] = {'C', 'F', 'R', 'G', uint8_t(1 + i % kFragmentVersion), 0, 0, 0};
            std::copy(head, head + 8, b.begin());
            for (int k = 8; k < 16; ++k) b[size_t(k)] = (k % 4 == 0) ? uint8_t(rng() % 64) : 0;
            refresh_integrity(b);
            check(b);
        }
    }
    // Mutations of valid fragments (every coding path), checksum recomputed so the parser runs.
    std::vector<std::vector<uint8_t>> seeds = {encode(small_fragment()), encode(icosphere(1)), encode(grid_patch(3)),
                                               encode(icosphere(1), nullptr, 1)};
    {
        FragmentMesh r = grid_patch(7);
        r.vertices = random_vertices(rng, r.vertices.size());
        seeds.push_back(encode(r));
    }
    int parsed_ok = 0;
    for (const auto& seed : seeds)
        for (int i = 0; i < 2500; ++i) {
            std::vector<uint8_t> b = seed;
            int edits = 1 + int(rng() % 4);
            for (int e = 0; e < edits; ++e) {
                size_t at = kHeaderSize + 2 + rng() % (b.size() - kHeaderSize - 2);
                switch (rng() % 4) {
                    case 0: b[at] ^= uint8_t(1u << (rng() % 8)); break;
                    case 1: b[at] = uint8_t(rng()); break;
                    case 2: b.erase(b.begin() + long(at)); break;
                    default: b.insert(b.begin() + long(at), uint8_t(rng())); break;
                }
                if (b.size() <= kHeaderSize + 3) break;
            }
            // Sometimes the low byte of a count too (large counts only cost allocation time).
            if (rng() % 8 == 0) b[rng() % 2 ? 8 : 12] ^= uint8_t(1u << (rng() % 8));
            refresh_integrity(b);
            parsed_ok += check(b);
        }
    // Most mutations must be caught by the parser's own consistency checks.
    EXPECT_LT(parsed_ok, 1000);
}

// ---- vertex layouts -------------------------------------------------------------------------

namespace {

// Every layout at its finest grid and at a coarser one.
const VertexLayout kLayouts[] = {
    {VertexLayoutKind::Rgb24, kBaryGrid},    {VertexLayoutKind::Rgb24, 100},
    {VertexLayoutKind::Rgb18, kMaxIndexGrid}, {VertexLayoutKind::Rgb18, 700},
    {VertexLayoutKind::Position48, kMaxWideGrid}, {VertexLayoutKind::Position48, 2000},
};

std::string describe(const VertexLayout& l) { return std::string(l.name()) + "/" + std::to_string(l.grid); }

}  // namespace

TEST(FragmentCodec, RoundTripIsLosslessInEveryVertexLayout) {
    for (const VertexLayout& layout : kLayouts) {
        SCOPED_TRACE(describe(layout));
        FragmentMesh patch = grid_patch(30, layout);
        add_grid(patch, 7, 50.0, 400.0, 10.0);
        patch.indices.insert(patch.indices.end(), {0, 1, 1});  // a degenerate triangle
        for (const FragmentMesh& m : {patch, icosphere(3, layout)}) {
            std::vector<uint8_t> bytes = expect_round_trip(m);
            EXPECT_EQ(bytes[kCodingOffset], 0) << "smooth content compresses";
            EXPECT_EQ(fragment_layout(bytes.data()), layout);
            FragmentMesh out;
            ASSERT_EQ(fragment_decode(bytes.data(), bytes.size(), out), FragmentStatus::Ok);
            EXPECT_EQ(out.layout, layout);
            EXPECT_NE(bytes[kModesOffset] & 3, 2) << "valid positions are predicted, not stored raw";
        }
    }
}

TEST(FragmentCodec, ArbitraryWordsRoundTripInEveryVertexLayout) {
    // Positions beyond the grid (raw position bits of the layout's width), any normal and
    // colour bits: still lossless, through the raw-position or the stored coding.
    std::mt19937_64 rng(5);
    for (const VertexLayout& layout : kLayouts) {
        SCOPED_TRACE(describe(layout));
        for (int round = 0; round < 6; ++round) {
            FragmentMesh m = grid_patch(8 + round, layout);
            std::vector<PackedVertex> words = random_vertices(rng, m.vertices.size());
            if (round % 2)  // valid positions, random everything else: only some vertices raw
                for (size_t i = 0; i < words.size(); i += 3) words[i] = m.vertices[i];
            m.vertices = words;
            expect_round_trip(m);
        }
    }
}

TEST(FragmentCodec, ColourlessLayoutSpendsNoBytesOnColour) {
    FragmentEncodeStats with, without;
    encode(icosphere(3, VertexLayout{VertexLayoutKind::Rgb24, kBaryGrid}), &with);
    encode(icosphere(3, VertexLayout{VertexLayoutKind::Position48, kBaryGrid}), &without);
    EXPECT_GT(with.color_bytes, 0u);
    EXPECT_EQ(without.color_bytes, 0u);
    // The same grid: the same positions, so the same position cost up to table details.
    EXPECT_NEAR(double(without.position_bytes), double(with.position_bytes), 0.02 * double(with.position_bytes));
}

TEST(FragmentCodec, HeaderNamesTheLayoutAndInvalidLayoutsAreRejected) {
    FragmentMesh out;
    uint32_t vc, tc;
    // The first datasets' layout keeps its bytes: layout 0, grid field 0.
    std::vector<uint8_t> legacy = encode(grid_patch(5));
    EXPECT_EQ(legacy[5], 0);
    EXPECT_EQ(legacy[6] | (legacy[7] << 8), 0);
    std::vector<uint8_t> wide = encode(grid_patch(5, VertexLayout{VertexLayoutKind::Position48, 5000}));
    EXPECT_EQ(wide[5], 1);
    EXPECT_EQ(wide[6] | (wide[7] << 8), 5000);
    auto with_header = [&](uint8_t layout, uint16_t grid) {
        std::vector<uint8_t> b = wide;
        b[5] = layout;
        b[6] = uint8_t(grid);
        b[7] = uint8_t(grid >> 8);
        refresh_integrity(b);
        return b;
    };
    std::vector<uint8_t> b = with_header(3, 5000);
    EXPECT_EQ(fragment_peek(b.data(), b.size(), vc, tc), FragmentStatus::UnsupportedVersion);
    b = with_header(1, 0);  // Position48 has no default grid
    EXPECT_EQ(fragment_peek(b.data(), b.size(), vc, tc), FragmentStatus::Corrupt);
    b = with_header(1, uint16_t(kMaxWideGrid + 1));
    EXPECT_EQ(fragment_decode(b.data(), b.size(), out), FragmentStatus::Corrupt);
    b = with_header(0, 5000);  // beyond the 24-bit index's grid
    EXPECT_EQ(fragment_decode(b.data(), b.size(), out), FragmentStatus::Corrupt);
    // A changed layout (to a valid one) is caught by the header fold even when the checksum was
    // recomputed.
    b = encode(grid_patch(5, VertexLayout{VertexLayoutKind::Position48, 1000}));
    b[5] = 2;
    uint64_t sum = checksum64(b.data() + kHeaderSize, b.size() - kHeaderSize);
    for (int i = 0; i < 8; ++i) b[16 + size_t(i)] = uint8_t(sum >> (8 * i));
    EXPECT_EQ(fragment_decode(b.data(), b.size(), out), FragmentStatus::Corrupt);
}

// ---- format stability -----------------------------------------------------------------------

namespace {

// A 5 x 5 grid patch (32 triangles) with integer-built vertex words: the compressed coding.
FragmentMesh golden_tiny_fragment() {
    FragmentMesh m;
    for (int j = 0; j < 5; ++j)
        for (int i = 0; i < 5; ++i) {
            BaryWeights w = {300 - 7 * i - 6 * j, 40 + 7 * i, 60 + 6 * j, 63};
            uint16_t normal = uint16_t(uint8_t(int8_t(10 + i)) | (uint8_t(int8_t(-20 + 2 * j)) << 8));
            m.vertices.push_back(PackedVertex::make(bary_pack(w), normal, uint8_t(100 + 3 * i), uint8_t(50 + 5 * j), 7));
        }
    for (uint32_t j = 0; j < 4; ++j)
        for (uint32_t i = 0; i < 4; ++i) {
            uint32_t a = j * 5 + i, b = a + 1, c = a + 5, d = c + 1;
            m.indices.insert(m.indices.end(), {a, b, d, a, d, c});
        }
    return m;
}

std::string hex_of(const std::vector<uint8_t>& bytes) {
    std::string hex;
    char buf[4];
    for (uint8_t b : bytes) {
        std::snprintf(buf, sizeof buf, "%02x", b);
        hex += buf;
    }
    return hex;
}

std::vector<uint8_t> bytes_of(const std::string& hex) {
    std::vector<uint8_t> out;
    for (size_t i = 0; i + 1 < hex.size(); i += 2) out.push_back(uint8_t(std::stoi(hex.substr(i, 2), nullptr, 16)));
    return out;
}

// Version 1's bytes of golden_tiny_fragment(), as the first datasets stored them.
const char* const kGoldenTinyVersion1 =
    "43465247010000001900000020000000477d510788a0072738000015002dc76b"
    "3f0200e6e46505d0220a3c9d40261567a51c54ccbddb9b90d9db141c2c2170dc"
    "e7cff200d5ad2f072d1cce917a93eaa6b387b2aff9d7b05ff856fe0e565e5259"
    "b5521e050ed683f56029580c5684f5602558107be1114401";

}  // namespace

TEST(FragmentCodec, GoldenBytesOfATinyFragmentAreStable) {
    const FragmentMesh m = golden_tiny_fragment();
    std::vector<uint8_t> bytes = expect_round_trip(m, 1);
    EXPECT_EQ(bytes[kCodingOffset], 0) << "the golden fragment must exercise the compressed coding";
    // If this changes, the bitstream changed: bump the version in fragment_codec.cpp (and the
    // format documentation) unless the change is deliberate and nothing was ever stored.
    EXPECT_EQ(hex_of(bytes), kGoldenTinyVersion1);
    std::vector<uint8_t> v2 = expect_round_trip(m, 2);
    EXPECT_EQ(hex_of(v2),
              "43465247020000001900000020000000aacfbff42268ba5d3b000055002dab3a"
              "ad094af09a09289a9c0f3bc93b55134e91abf8c5b5be7901892bac469cb89e79"
              "cbfc872df720b288880da57afe0429033916203b89d4e1ad700244f26aad9ff8"
              "3e4219d58d64b7829a050ed683f56029580c56c443c206c45e780451");
}

// Datasets on disk hold version 1 fragments: the stored bytes (not a fresh encoding) still decode
// to the mesh they were made from.
TEST(FragmentCodec, Version1BytesOnDiskStillDecode) {
    const std::vector<uint8_t> stored = bytes_of(kGoldenTinyVersion1);
    ASSERT_EQ(stored[4], 1);
    FragmentMesh out;
    ASSERT_EQ(fragment_decode(stored.data(), stored.size(), out), FragmentStatus::Ok);
    EXPECT_TRUE(canonical(out) == canonical(golden_tiny_fragment()));
}

namespace {

// Meshes that exercise every coding mode and the traversal's special cases.
std::vector<std::pair<std::string, FragmentMesh>> varied_meshes() {
    std::vector<std::pair<std::string, FragmentMesh>> cases;
    for (int n : {2, 3, 5, 9, 17, 40}) cases.push_back({"grid " + std::to_string(n), grid_patch(n)});
    for (int s = 0; s <= 3; ++s) cases.push_back({"icosphere " + std::to_string(s), icosphere(s)});
    cases.push_back({"small fragment", small_fragment()});
    {
        FragmentMesh m = grid_patch(3);  // a non-manifold fan and stacked duplicates
        for (uint32_t k = 0; k < 300; ++k) {
            uint32_t a = k % 9, b = (k + 1 + k / 9) % 9;
            if (a != 4 && b != 4 && a != b) m.indices.insert(m.indices.end(), {4, a, b});
        }
        for (int k = 0; k < 200; ++k) m.indices.insert(m.indices.end(), {0, 1, 4});
        cases.push_back({"fan", m});
    }
    {
        FragmentMesh m = grid_patch(30);  // noise on w2: weight-space positions
        std::mt19937_64 rng(7);
        for (PackedVertex& v : m.vertices) {
            BaryWeights w;
            bary_unpack(v.position_index(), kBaryGrid, w);
            int d = int(rng() % 9) - 4;
            if (w[2] + d >= 0 && w[0] - d >= 0) {
                w[2] += d;
                w[0] -= d;
            }
            v.word0 = (v.word0 & 0xff000000u) | bary_pack(w);
        }
        cases.push_back({"weights", m});
    }
    {
        FragmentMesh m = grid_patch(12);  // flipped neighbours, degenerate and duplicate triangles
        std::mt19937_64 rng(3);
        for (size_t t = 0; t < m.triangle_count(); ++t)
            if (rng() % 4 == 0) std::swap(m.indices[3 * t + 1], m.indices[3 * t + 2]);
        m.indices.insert(m.indices.end(), {3, 3, 4, 5, 6, 5, 7, 7, 7, 20, 22, 21, 20, 21, 22});
        cases.push_back({"flipped", m});
    }
    {
        std::mt19937_64 rng(99);  // arbitrary words: raw positions, odd normals and colours
        for (int round = 0; round < 4; ++round) {
            FragmentMesh m = grid_patch(10 + round);
            std::vector<PackedVertex> v = random_vertices(rng, m.vertices.size());
            if (round % 2)
                for (size_t i = 0; i < v.size(); ++i) v[i].word0 = (v[i].word0 & 0xff000000u) | m.vertices[i].position_index();
            m.vertices = v;
            cases.push_back({"random words " + std::to_string(round), m});
        }
    }
    return cases;
}

}  // namespace

// The encoder was restructured for speed (trial modes only counted, symbols coded with
// reciprocal tables, per-thread scratch memory) without changing a single output byte. These
// digests (XXH3-64 of the encoded bytes of version 1) were taken with the encoder before that
// change.
TEST(FragmentCodec, EncodedBytesOfVariedMeshesAreUnchanged) {
    const std::vector<std::pair<std::string, FragmentMesh>> cases = varied_meshes();
    const uint64_t expected[] = {
        0x9e2c54af7039fd12ull,  // grid 2
        0x473f42ed61c3072full,  // grid 3
        0xf523235e75f35ec5ull,  // grid 5
        0x18252e010e162881ull,  // grid 9
        0x0f85352971ebbeb1ull,  // grid 17
        0xa4401f18a556ca71ull,  // grid 40
        0xc67dc4f054062ba5ull,  // icosphere 0
        0xe14197f739c00767ull,  // icosphere 1
        0xbd6a5a96c1aca54dull,  // icosphere 2
        0xe0b4f61571f8a9f0ull,  // icosphere 3
        0xaff567900fe2d23bull,  // small fragment
        0x5660a84d2933f5e0ull,  // fan
        0xd5507cbb9b8c4537ull,  // weights
        0xa561a7877c2a3825ull,  // flipped
        0x34e4d7dfc4814cb4ull,  // random words 0
        0x2a80af97825d7d22ull,  // random words 1
        0x661576c51b444373ull,  // random words 2
        0xa6669e27c8fd7a63ull,  // random words 3
    };
    ASSERT_EQ(cases.size(), sizeof expected / sizeof expected[0]);
    for (size_t i = 0; i < cases.size(); ++i) {
        std::vector<uint8_t> bytes = encode(cases[i].second, nullptr, 1);
        char digest[24];
        std::snprintf(digest, sizeof digest, "0x%016llxull", (unsigned long long)checksum64(bytes.data(), bytes.size()));
        EXPECT_EQ(checksum64(bytes.data(), bytes.size()), expected[i]) << cases[i].first << ": now " << digest;
    }
}

// ---- version 2 ------------------------------------------------------------------------------

// Version 2 changed how the geometric normal prediction is computed (float) and added the joint
// colour coding, nothing else: from the same input, both versions decode to the very same vertex
// and index arrays (not only the same mesh up to the permutations the codec allows).
TEST(FragmentCodec, Version2DecodesToTheSameArraysAsVersion1) {
    std::vector<std::pair<std::string, FragmentMesh>> cases = varied_meshes();
    for (const VertexLayout& layout : kLayouts) {
        cases.push_back({"icosphere 3 " + describe(layout), icosphere(3, layout)});
        cases.push_back({"grid 23 " + describe(layout), grid_patch(23, layout)});
    }
    size_t geometric = 0;
    for (const auto& [name, m] : cases) {
        SCOPED_TRACE(name);
        const std::vector<uint8_t> b1 = encode(m, nullptr, 1), b2 = encode(m, nullptr, 2);
        FragmentMesh d1, d2;
        ASSERT_EQ(fragment_decode(b1.data(), b1.size(), d1), FragmentStatus::Ok);
        ASSERT_EQ(fragment_decode(b2.data(), b2.size(), d2), FragmentStatus::Ok);
        EXPECT_TRUE(d1.layout == d2.layout);
        ASSERT_EQ(d1.vertices.size(), d2.vertices.size());
        for (size_t v = 0; v < d1.vertices.size(); ++v) ASSERT_EQ(key(d1.vertices[v]), key(d2.vertices[v])) << v;
        EXPECT_EQ(d1.indices, d2.indices);
        geometric += b2[kCodingOffset] == 0 && ((b2[kModesOffset] >> 2) & 3) == 2;
    }
    EXPECT_GE(geometric, 8u) << "the cases must exercise version 2's geometric normals";
}

// Round trips of version 2 with the geometric predictor on generated fragments of every layout
// and of vertex counts that are and are not multiples of the predictor's block of four.
TEST(FragmentCodec, Version2RoundTripIsLosslessOnGeneratedFragments) {
    size_t geometric = 0;
    for (const VertexLayout& layout : kLayouts) {
        SCOPED_TRACE(describe(layout));
        for (int n : {4, 5, 6, 7, 16, 31}) {
            FragmentMesh m = grid_patch(n, layout);
            const std::vector<uint8_t> bytes = expect_round_trip(m, 2);
            EXPECT_EQ(bytes[4], 2);
        }
        for (int sub = 0; sub <= 4; ++sub) {
            const std::vector<uint8_t> bytes = expect_round_trip(icosphere(sub, layout), 2);
            geometric += bytes[kCodingOffset] == 0 && ((bytes[kModesOffset] >> 2) & 3) == 2;
        }
    }
    // (Coarse grids and small spheres often prefer the parallelogram.)
    EXPECT_GE(geometric, std::size(kLayouts)) << "round trips with the geometric normal predictor";
}

// The float prediction costs no bytes (the same prediction as version 1's but for rare
// roundings); the joint colour coding may cost a little where it is not the smaller coding
// (kJointColourAllowance), within the 1% the format change may cost.
TEST(FragmentCodec, Version2CostsAtMostOnePercentMoreBytesThanVersion1) {
    size_t v1 = 0, v2 = 0;
    for (const auto& [name, m] : varied_meshes()) {
        v1 += encode(m, nullptr, 1).size();
        v2 += encode(m, nullptr, 2).size();
    }
    for (int sub = 3; sub <= 5; ++sub) {
        v1 += encode(icosphere(sub), nullptr, 1).size();
        v2 += encode(icosphere(sub), nullptr, 2).size();
    }
    EXPECT_LE(double(v2), 1.01 * double(v1));
}

TEST(FragmentCodec, EncodedBytesOfVariedMeshesAreStableInVersion2) {
    const std::vector<std::pair<std::string, FragmentMesh>> cases = varied_meshes();
    std::string now;
    for (const auto& [name, m] : cases) {
        const std::vector<uint8_t> bytes = encode(m, nullptr, 2);
        char digest[32];
        std::snprintf(digest, sizeof digest, "0x%016llxull,", (unsigned long long)checksum64(bytes.data(), bytes.size()));
        now += digest;
    }
    // If this changes, version 2's bitstream changed (see GoldenBytesOfATinyFragmentAreStable).
    EXPECT_EQ(now,
              "0x7130bf7821da06f8ull,0xbf531cf99904a2fbull,0x152318f912442f87ull,0x09ec36a063567c67ull,"
              "0x4056b7746da7babdull,0x43d2d6ca4a96c3f2ull,0x24fde9af2ae775e2ull,0xa6fbca585d113cdbull,"
              "0xb2d9e5b0d9e09a22ull,0xa51be7d3cd2e18a2ull,0x4d12bede0a5be7f9ull,0x16be6f14befc845dull,"
              "0xdb5ad8010974afe2ull,0x9b545f39f184f256ull,0xf7b976b6ab739b42ull,0xcc2519e887e470ecull,"
              "0x8441a2df46a825e1ull,0xd3bf700dfc6411f3ull,");
}

namespace {

constexpr uint8_t kJointColourBit = 1 << 6;  // modes bit 6, version 2

}  // namespace

TEST(FragmentCodec, JointColourCodingIsChosenForSmoothColoursAndDecodesLikeVersion1) {
    const FragmentMesh m = coloured_patch(25, false, 1);
    const std::vector<uint8_t> v2 = expect_round_trip(m, 2);
    ASSERT_EQ(v2[kCodingOffset], 0);
    EXPECT_NE(v2[kModesOffset] & kJointColourBit, 0) << "joint colour coding";
    const std::vector<uint8_t> v1 = encode(m, nullptr, 1);
    FragmentMesh d1, d2;
    ASSERT_EQ(fragment_decode(v1.data(), v1.size(), d1), FragmentStatus::Ok);
    ASSERT_EQ(fragment_decode(v2.data(), v2.size(), d2), FragmentStatus::Ok);
    for (size_t v = 0; v < d1.vertices.size(); ++v) ASSERT_EQ(key(d1.vertices[v]), key(d2.vertices[v])) << v;
    EXPECT_EQ(d1.indices, d2.indices);
    // Some vertices escape (colour steps of two) and some do not: both paths of the decoder.
    FragmentMesh mixed = m;
    for (size_t i = 0; i < mixed.vertices.size(); i += 25) {
        PackedVertex& v = mixed.vertices[i];
        v = PackedVertex::make(v.position_index(), v.normal(), uint8_t(v.word1 >> 8), uint8_t(v.word1 >> 16), 250);
    }
    const std::vector<uint8_t> b = expect_round_trip(mixed, 2);
    EXPECT_NE(b[kModesOffset] & kJointColourBit, 0) << "joint colour coding with escapes";
}

TEST(FragmentCodec, NoisyColoursKeepTheSeparateColourCoding) {
    const std::vector<uint8_t> bytes = expect_round_trip(coloured_patch(20, true, 2), 2);
    ASSERT_EQ(bytes[kCodingOffset], 0);
    EXPECT_EQ(bytes[kModesOffset] & kJointColourBit, 0);
}

// The joint colour bit is version 2's and needs colours: set in a version 1 fragment or in a
// colourless layout's, the fragment is corrupt.
TEST(FragmentCodec, JointColourBitIsRejectedInVersion1AndWithoutColours) {
    FragmentMesh out;
    for (const std::vector<uint8_t>& bytes :
         {encode(coloured_patch(12, false, 3), nullptr, 1),
          encode(grid_patch(12, VertexLayout{VertexLayoutKind::Position48, 2000}), nullptr, 2)}) {
        ASSERT_EQ(bytes[kCodingOffset], 0);
        ASSERT_EQ(bytes[kModesOffset] & kJointColourBit, 0);
        std::vector<uint8_t> b = bytes;
        b[kModesOffset] |= kJointColourBit;
        refresh_integrity(b);
        EXPECT_EQ(fragment_decode(b.data(), b.size(), out), FragmentStatus::Corrupt);
    }
}
