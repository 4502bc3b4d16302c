// The lossless fragment codec (see common_codec/fragment_codec.h for the API).
//
// Bitstream, version 1 (all little-endian)
// ----------------------------------------
//   header (24 bytes): u32 magic "CFRG" | u8 version = 1 | u8 flags = 0 | u16 reserved = 0 |
//                      u32 vertex_count V | u32 triangle_count T | u64 checksum = XXH3-64 of the
//                      payload (every byte after this field)
//   payload:
//     u16 header_fold   XOR of the six u16 words at header bytes 4..15 (version .. T): a change
//                       to a header field is detected although the checksum does not cover it
//     u8  coding        0 = compressed (below); 1 = stored: V x (u32 word0, u32 word1), then
//                       T x 3 x u32 indices, nothing else (chosen when it is not larger)
//   compressed:
//     u8  modes         bits 0-1 position coding: 0 = cumulative weights (a, b, c) =
//                       (w1+w2+w3, w2+w3, w3) (the index enumeration of barycentric.h), 1 =
//                       weights (w1, w2, w3), 2 = raw 24-bit index (any index >= the grid size);
//                       bits 2-3 normal predictor: 0 = gate average, 1 = parallelogram,
//                       2 = geometric; bit 4 colour predictor: 0 = gate average,
//                       1 = parallelogram; bit 5: R and B residuals are coded relative to the
//                       G residual; bits 6-7 zero
//     i8 x 9            geometric normal predictor only: row-major 3x3 matrix M mapping a normal
//                       computed in (a, b, c) space to the frame of the normals (any scale)
//     varint E          number of degenerate triangles (a repeated index), coded explicitly
//     varint N          number of connectivity symbols
//     entropy coded     rans.h: u32 state0..3 | varint bit_bytes | rANS bytes | raw bit stream.
//                       Symbols go through rANS (lane per symbol below), the low bits of large
//                       residuals and explicit indices through the raw bit stream; in decode
//                       order:
//       tables          connectivity (6 symbols), 3 position tables (absent for raw positions),
//                       normal u, v, colour R, G, B: alphabet size, scale and log-domain weights
//                       (rans.h), symbols on lane 0
//       connectivity    N traversal symbols (symbol k on lane k & 3) and, in the bit stream,
//                       SPLIT indices; then E x 3 indices of bit_width(V - 1) bits each
//       positions       per vertex in decoded order: 3 residual values (lanes 0, 1, 2), or 24 bits
//       normals         per vertex: u, v residual values (lanes 0, 1), modulo 256
//       colours         per vertex: G, R, B residual values (lanes 0, 1, 2), modulo 256
//     Every byte must be consumed and all rANS states must end at their initial value.
//
// Connectivity: a deterministic front traversal in the spirit of the cut-border machine (and of
// Corto's coder). The front is a set of directed edge loops (the border of the triangles decoded
// so far), each edge (v0 -> v1) remembering the third vertex `opp` of the triangle it came from;
// all edges live in one array processed in FIFO order, skipping consumed ones. When the queue is
// exhausted and triangles remain, a new component starts with a triangle whose three vertices
// are each coded NEW or SPLIT. Per popped edge one symbol:
//   NEW       the triangle across the edge is (v1, v0, v) with a vertex v never seen before:
//             the edge is replaced by (v0 -> v), (v -> v1)
//   LEFT      ... with v = the next edge's v1: the edge and the next are replaced by (v0 -> v)
//   RIGHT     ... with v = the previous edge's v0: it and the previous become (v -> v1)
//   END       both (closes a loop: previous, edge and next are removed)
//   SPLIT     as NEW with an already seen vertex, its index in bit_width(seen - 1) raw bits
//   BOUNDARY  no further triangle across this edge
// The traversal stops as soon as T - E triangles have been produced. Vertices are numbered in
// order of first appearance; vertices used by no regular triangle follow in their original
// order. Any input is expressible: non-manifold edges, inconsistent orientation, duplicate
// triangles and touching components simply cost restarts and SPLITs; only degenerate triangles
// (which the front cannot express) are sent as explicit index triples. The decoder rejects any
// symbol that would make a degenerate triangle, so the front never holds a loop shorter than 2.
//
// Attribute prediction: a vertex created by NEW at gate (v0, v1, opp) is predicted from
// v0 + v1 - opp (parallelogram) or (v0 + v1) / 2 (gate average); other vertices from the
// previous vertex in decoded order (the first one from zero). Positions are predicted coordinate
// by coordinate, each prediction clamped to the range the already decoded coordinates allow
// (a in [0, 463], b in [0, a], c in [0, b]; in weight space w1 in [0, 463], w2 in [0, 463 - w1],
// w3 in [0, 463 - w1 - w2]). The geometric normal predictor sums, per vertex, the (integer)
// cross products of its triangles in (a, b, c) space, maps the sum by M and projects it to the
// octahedral code in double arithmetic, rounding half up (vertices with a zero sum take the
// previous vertex's normal). (Averaging it with the neighbours' parallelogram where both agree
// saves about 0.5 bit per vertex on the bunny but chains every vertex to its predecessors and
// costs about 7% of the decoding speed, so it is not done.) Normal and colour residuals wrap
// modulo 256.
//
// Residual values: zig-zag mapped z; symbol z for z < 8, otherwise, with k = floor(log2 z),
// symbol 8 + 2 (k - 3) + (bit k-1 of z) followed by the k - 1 low bits of z in the bit stream.
#include "common_codec/fragment_codec.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cassert>
#include <cmath>
#include <cstring>

#include "base/checksum.h"
#include "common_codec/octahedral.h"
#include "rans.h"

namespace catpaq {

namespace {

constexpr uint8_t kMagicBytes[4] = {'C', 'F', 'R', 'G'};
constexpr uint8_t kVersion = 1;
constexpr size_t kHeaderBytes = 24;
constexpr size_t kChecksumOffset = 16;
constexpr uint8_t kCodingCompressed = 0;
constexpr uint8_t kCodingStored = 1;

enum ConnSymbol : uint32_t { kNew = 0, kLeft, kRight, kEnd, kSplit, kBoundary, kConnSymbols };

enum Stream : int {
    kStreamConn = 0,
    kStreamPos0,
    kStreamPos1,
    kStreamPos2,
    kStreamNormU,
    kStreamNormV,
    kStreamColR,
    kStreamColG,
    kStreamColB,
    kStreamCount,
    kStreamRaw = 255,
};

// rANS lane of each stream (the coordinates of one vertex decode in parallel); connectivity
// symbols use lane (symbol index & 3).
constexpr int kStreamLane[kStreamCount] = {0, 0, 1, 2, 0, 1, 1, 0, 2};

enum PositionMode { kPosCumulative = 0, kPosWeights = 1, kPosRaw = 2 };
enum NormalMode { kNormalAverage = 0, kNormalParallelogram = 1, kNormalGeometric = 2 };

constexpr int32_t kGrid = kBaryGrid;
constexpr uint32_t kNone = 0xffffffffu;
constexpr uint32_t kDead = 0xffffffffu;

uint32_t zigzag(int32_t v) { return (uint32_t(v) << 1) ^ uint32_t(v >> 31); }
int32_t unzigzag(uint32_t z) { return int32_t(z >> 1) ^ -int32_t(z & 1); }

int bit_width_u32(uint32_t v) { return int(std::bit_width(v)); }

// Value buckets: symbol, number of extra bits, extra bits value.
struct Bucket {
    uint32_t sym, nbits, extra;
};
Bucket bucket_of(uint32_t z) {
    if (z < 8) return {z, 0, 0};
    int k = bit_width_u32(z) - 1;
    return {uint32_t(8 + 2 * (k - 3)) + ((z >> (k - 1)) & 1u), uint32_t(k - 1), z & ((1u << (k - 1)) - 1)};
}
// Per bucket symbol: (base << 8) | number of extra bits.
struct BucketDecode {
    std::array<uint32_t, rans::kMaxAlphabet> packed{};
    constexpr BucketDecode() {
        for (uint32_t s = 0; s < uint32_t(rans::kMaxAlphabet); ++s) {
            if (s < 8) {
                packed[s] = s << 8;
            } else {
                uint32_t k = 3 + (s - 8) / 2, hi = (s - 8) & 1;
                packed[s] = (((1u << k) | (hi << (k - 1))) << 8) | (k - 1);
            }
        }
    }
};
constexpr BucketDecode kBucketDecode{};
static_assert((kBucketDecode.packed[rans::kMaxAlphabet - 1] & 0xff) <= 13);

// Tetrahedral-number enumeration of barycentric.h: index = tet(a) + tri(b) + c.
struct BaryTables {
    std::array<uint32_t, kBaryGrid + 1> tet{}, tri{};
    constexpr BaryTables() {
        for (uint32_t a = 0; a <= uint32_t(kBaryGrid); ++a) {
            tet[a] = a * (a + 1) * (a + 2) / 6;
            tri[a] = a * (a + 1) / 2;
        }
    }
};
constexpr BaryTables kBaryTables{};
static_assert(kBaryTables.tet[kBaryGrid] + kBaryTables.tri[kBaryGrid] + kBaryGrid + 1 == kBaryIndexCount);

// ---------------------------------------------------------------------------------------------
// The front, shared by encoder and decoder so both evolve it identically. Edges live in one
// array (FIFO order = array order); callers reserve room for 3 more edges before each step.

struct FrontEdge {
    uint32_t v0, v1, opp, prev, next;  // prev == kDead: consumed
};

struct Front {
    std::vector<FrontEdge> store;
    FrontEdge* e = nullptr;
    uint32_t size = 0, head = 0;

    void reset(size_t expected) {
        if (store.size() < expected) store.resize(expected);
        e = store.data();
        size = head = 0;
    }
    void reserve3() {
        if (size + 3 > store.size()) [[unlikely]] {
            store.resize(store.size() * 2 + 16);
            e = store.data();
        }
    }
    // Next live edge in FIFO order, or false when the queue is exhausted. Skips one consumed
    // edge without a branch (e[size] is readable: reserve3 keeps room); longer runs are rare.
    bool pop(uint32_t& i) {
        uint32_t h = head;
        h += uint32_t(h < size) & uint32_t(e[h].prev == kDead);
        while (h < size && e[h].prev == kDead) [[unlikely]]
            ++h;
        head = h;
        if (h == size) return false;
        i = h;
        head = h + 1;
        return true;
    }
    void start(uint32_t a, uint32_t b, uint32_t c) {
        uint32_t i = size;
        e[i] = {a, b, c, i + 2, i + 1};
        e[i + 1] = {b, c, a, i, i + 2};
        e[i + 2] = {c, a, b, i + 1, i};
        size += 3;
    }
    // Triangle (v1, v0, v) with v new or split: edge i is replaced by (v0 -> v), (v -> v1).
    void add_vertex(uint32_t i, const FrontEdge& ei, uint32_t v) {
        uint32_t a = size, b = a + 1;
        e[a] = {ei.v0, v, ei.v1, ei.prev, b};
        e[b] = {v, ei.v1, ei.v0, a, ei.next};
        e[ei.prev].next = a;
        e[ei.next].prev = b;
        e[i].prev = kDead;
        size += 2;
    }
    // v = e[next].v1: edges i and next are replaced by (v0 -> v). Needs a loop of >= 3 edges.
    void left(uint32_t i, const FrontEdge& ei, uint32_t v) {
        const uint32_t n = ei.next, nn = e[n].next;
        uint32_t c = size++;
        e[c] = {ei.v0, v, ei.v1, ei.prev, nn};
        e[ei.prev].next = c;
        e[nn].prev = c;
        e[i].prev = kDead;
        e[n].prev = kDead;
    }
    // v = e[prev].v0: edges prev and i are replaced by (v -> v1).
    void right(uint32_t i, const FrontEdge& ei, uint32_t v) {
        const uint32_t p = ei.prev, pp = e[p].prev;
        uint32_t c = size++;
        e[c] = {v, ei.v1, ei.v0, pp, ei.next};
        e[pp].next = c;
        e[ei.next].prev = c;
        e[i].prev = kDead;
        e[p].prev = kDead;
    }
    // prev, i and next are removed (e[prev].v0 == e[next].v1).
    void end(uint32_t i, const FrontEdge& ei) {
        const uint32_t p = ei.prev, n = ei.next, pp = e[p].prev, nn = e[n].next;
        e[i].prev = kDead;
        e[p].prev = kDead;
        e[n].prev = kDead;
        if (pp != n) {
            e[pp].next = nn;
            e[nn].prev = pp;
        }
    }
};

// ---------------------------------------------------------------------------------------------
// Encoder side: symbols are collected per stream, in decode order, before the tables exist.

struct Sink {
    struct Item {
        uint32_t value;  // symbol, or raw bits
        uint32_t extra;  // the symbol's extra bits (bit stream)
        uint8_t stream;  // kStreamRaw: raw bits
        uint8_t nbits;
        uint8_t lane;
    };
    std::vector<Item> items;
    std::array<std::array<uint32_t, rans::kMaxAlphabet>, kStreamCount> counts{};
    size_t raw_bits = 0;
    uint32_t conn_symbols = 0;

    int lane_of(int stream) { return stream == kStreamConn ? int(conn_symbols++ & 3) : kStreamLane[stream]; }
    void sym(int stream, uint32_t s) {
        items.push_back({s, 0, uint8_t(stream), 0, uint8_t(lane_of(stream))});
        ++counts[size_t(stream)][s];
    }
    void bits(uint32_t v, int n) {  // n <= 32
        raw_bits += size_t(n);
        if (n > 0) items.push_back({v, 0, uint8_t(kStreamRaw), uint8_t(n), 0});
    }
    void value(int stream, uint32_t z) {
        Bucket b = bucket_of(z);
        items.push_back({b.sym, b.extra, uint8_t(stream), uint8_t(b.nbits), uint8_t(lane_of(stream))});
        ++counts[size_t(stream)][b.sym];
        raw_bits += b.nbits;
    }
    // Estimated coded size of the given streams plus all raw bits, tables included.
    double cost(int first_stream, int last_stream) const {
        double bits_total = double(raw_bits);
        for (int s = first_stream; s <= last_stream; ++s) {
            const uint32_t* c = counts[size_t(s)].data();
            rans::TableDesc d = rans::describe_counts(c, rans::kMaxAlphabet);
            rans::FreqTable f;
            rans::build_freqs(d, f);
            bits_total += rans::data_cost_bits(c, f) + rans::table_cost_bits(d);
        }
        return bits_total;
    }
};

// Per-vertex prediction sources (new numbering); index V stands for a virtual zero vertex.
struct Pred {
    uint32_t a, b, c;  // gate v0, gate v1, opposite (all equal for "previous vertex")
};

// Bitwise select between two doubles (exact, and without a branch on unpredictable data).
CATPAQ_RANS_INLINE double select(bool c, double a, double b) {
    uint64_t ua, ub;
    std::memcpy(&ua, &a, 8);
    std::memcpy(&ub, &b, 8);
    const uint64_t m = 0 - uint64_t(c);
    uint64_t r = (ua & m) | (ub & ~m);
    double out;
    std::memcpy(&out, &r, 8);
    return out;
}

// Geometric normal: projects a vector to the octahedral code (signed bytes, c / 127); the lower
// hemisphere is folded as in octahedral.cpp (sign of zero taken as positive).
CATPAQ_RANS_INLINE bool project_oct(double x, double y, double z, int& cu, int& cv) {
    double l1 = std::fabs(x) + std::fabs(y) + std::fabs(z);
    if (!(l1 > 0.0)) return false;
    double s = 127.0 / l1;
    double u = x * s, v = y * s;
    const double fu = select(u < 0.0, -1.0, 1.0) * (127.0 - std::fabs(v));
    const double fv = select(v < 0.0, -1.0, 1.0) * (127.0 - std::fabs(u));
    u = select(z < 0.0, fu, u);
    v = select(z < 0.0, fv, v);
    // Round half up: |u|, |v| <= 127, so u + 128.5 > 0 and truncation is floor.
    cu = std::clamp(int(u + 128.5) - 128, -127, 127);
    cv = std::clamp(int(v + 128.5) - 128, -127, 127);
    return true;
}

// Cumulative barycentric coordinates (a, b, c) of a vertex (fourth entry unused, for alignment).
using Coord = std::array<int32_t, 4>;
// Sums of integer cross products: each product component is below 2^19 in magnitude
// (coordinates are <= 463), so |sum| < 2^42 for any fragment (exact in doubles too).
using NormalSum = std::array<int64_t, 4>;

// Area-weighted normals in (a, b, c) space: sum of the cross products of each vertex's triangles.
void accumulate_normals(const uint32_t* indices, size_t triangles, const Coord* s, NormalSum* acc) {
    for (size_t t = 0; t < triangles; ++t) {
        uint32_t i = indices[3 * t], j = indices[3 * t + 1], k = indices[3 * t + 2];
        const Coord si = s[i], sj = s[j], sk = s[k];
        int32_t e1x = sj[0] - si[0], e1y = sj[1] - si[1], e1z = sj[2] - si[2];
        int32_t e2x = sk[0] - si[0], e2y = sk[1] - si[1], e2z = sk[2] - si[2];
        int64_t nx = e1y * e2z - e1z * e2y, ny = e1z * e2x - e1x * e2z, nz = e1x * e2y - e1y * e2x;
        for (uint32_t v : {i, j, k}) {
            acc[v][0] += nx;
            acc[v][1] += ny;
            acc[v][2] += nz;
        }
    }
}

// Predicted normal of a vertex under the geometric predictor; `prev_u/v` is the fallback. M n is
// exact in doubles (|m| <= 128 and |n| < 2^42, so |M n| < 2^51).
CATPAQ_RANS_INLINE void geometric_prediction(const NormalSum& n, const std::array<int8_t, 9>& m, int prev_u,
                                             int prev_v, int& pu, int& pv) {
    const double n0 = double(n[0]), n1 = double(n[1]), n2 = double(n[2]);
    double x = double(m[0]) * n0 + double(m[1]) * n1 + double(m[2]) * n2;
    double y = double(m[3]) * n0 + double(m[4]) * n1 + double(m[5]) * n2;
    double z = double(m[6]) * n0 + double(m[7]) * n1 + double(m[8]) * n2;
    if (!project_oct(x, y, z, pu, pv)) {
        pu = prev_u;
        pv = prev_v;
    }
}

uint16_t read_u16(const uint8_t* p) { return uint16_t(p[0] | (p[1] << 8)); }
uint32_t read_u32(const uint8_t* p) {
    return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}
void put_u16(std::vector<uint8_t>& out, uint16_t v) {
    out.push_back(uint8_t(v));
    out.push_back(uint8_t(v >> 8));
}
void put_u32(std::vector<uint8_t>& out, uint32_t v) {
    for (int i = 0; i < 4; ++i) out.push_back(uint8_t(v >> (8 * i)));
}
void put_varint(std::vector<uint8_t>& out, uint64_t v) {
    while (v >= 0x80) {
        out.push_back(uint8_t(v | 0x80));
        v >>= 7;
    }
    out.push_back(uint8_t(v));
}

uint16_t header_fold(const uint8_t* header) {
    uint16_t f = 0;
    for (size_t at = 4; at < kChecksumOffset; at += 2) f ^= read_u16(header + at);
    return f;
}

// Colour channel helpers (r = 0, g = 1, b = 2) of word1.
inline int channel(uint32_t word1, int c) { return int((word1 >> (8 + 8 * c)) & 0xffu); }

// ---------------------------------------------------------------------------------------------
// Encoder

struct EncoderState {
    uint32_t V = 0;
    std::vector<PackedVertex> verts;  // new order, plus the virtual zero vertex at V
    std::vector<Pred> pred;           // per new vertex
    std::vector<uint32_t> indices;    // all triangles, new numbering (regular then degenerate)
};

void emit_positions(const EncoderState& st, int mode, const std::vector<Coord>& s, Sink& sink) {
    const uint32_t V = st.V;
    if (mode == kPosRaw) {
        for (uint32_t v = 0; v < V; ++v) sink.bits(st.verts[v].position_index(), 24);
        return;
    }
    // Coordinates in the coding space (index V: the virtual zero vertex).
    std::vector<int32_t> q0(V + 1), q1(V + 1), q2(V + 1);
    for (uint32_t v = 0; v <= V; ++v) {
        if (mode == kPosCumulative) {
            q0[v] = s[v][0], q1[v] = s[v][1], q2[v] = s[v][2];
        } else {
            q0[v] = s[v][0] - s[v][1], q1[v] = s[v][1] - s[v][2], q2[v] = s[v][2];
        }
    }
    for (uint32_t v = 0; v < V; ++v) {
        const Pred& p = st.pred[v];
        int32_t x0 = q0[v], x1 = q1[v], x2 = q2[v];
        int32_t hi0 = kGrid;
        int32_t hi1 = mode == kPosCumulative ? x0 : kGrid - x0;
        int32_t p0 = std::clamp(q0[p.a] + q0[p.b] - q0[p.c], 0, hi0);
        int32_t p1 = std::clamp(q1[p.a] + q1[p.b] - q1[p.c], 0, hi1);
        int32_t hi2 = mode == kPosCumulative ? x1 : kGrid - x0 - x1;
        int32_t p2 = std::clamp(q2[p.a] + q2[p.b] - q2[p.c], 0, hi2);
        sink.value(kStreamPos0, zigzag(x0 - p0));
        sink.value(kStreamPos1, zigzag(x1 - p1));
        sink.value(kStreamPos2, zigzag(x2 - p2));
    }
}

inline int normal_u(const PackedVertex& v) { return int8_t(uint8_t(v.word0 >> 24)); }
inline int normal_v(const PackedVertex& v) { return int8_t(uint8_t(v.word1)); }
inline uint32_t wrap_residual(int actual, int pred) { return zigzag(int32_t(int8_t(uint8_t(actual - pred)))); }

void emit_normals(const EncoderState& st, int mode, const std::vector<NormalSum>* acc, const std::array<int8_t, 9>& m,
                  Sink& sink) {
    const uint32_t V = st.V;
    for (uint32_t v = 0; v < V; ++v) {
        const Pred& p = st.pred[v];
        int pu, pv;
        if (mode == kNormalGeometric) {
            const PackedVertex& prev = st.verts[v == 0 ? V : v - 1];
            geometric_prediction((*acc)[v], m, normal_u(prev), normal_v(prev), pu, pv);
        } else if (mode == kNormalAverage) {
            pu = (normal_u(st.verts[p.a]) + normal_u(st.verts[p.b])) >> 1;
            pv = (normal_v(st.verts[p.a]) + normal_v(st.verts[p.b])) >> 1;
        } else {
            pu = std::clamp(normal_u(st.verts[p.a]) + normal_u(st.verts[p.b]) - normal_u(st.verts[p.c]), -127, 127);
            pv = std::clamp(normal_v(st.verts[p.a]) + normal_v(st.verts[p.b]) - normal_v(st.verts[p.c]), -127, 127);
        }
        sink.value(kStreamNormU, wrap_residual(normal_u(st.verts[v]), pu));
        sink.value(kStreamNormV, wrap_residual(normal_v(st.verts[v]), pv));
    }
}

void emit_colors(const EncoderState& st, bool parallelogram, bool decorrelate, Sink& sink) {
    const uint32_t V = st.V;
    for (uint32_t v = 0; v < V; ++v) {
        const Pred& p = st.pred[v];
        int r[3];
        for (int c = 0; c < 3; ++c) {
            int a = channel(st.verts[p.a].word1, c), b = channel(st.verts[p.b].word1, c);
            int pc = parallelogram ? std::clamp(a + b - channel(st.verts[p.c].word1, c), 0, 255) : (a + b + 1) >> 1;
            r[c] = channel(st.verts[v].word1, c) - pc;
        }
        if (decorrelate) {
            r[0] -= r[1];
            r[2] -= r[1];
        }
        sink.value(kStreamColG, zigzag(int8_t(uint8_t(r[1]))));
        sink.value(kStreamColR, zigzag(int8_t(uint8_t(r[0]))));
        sink.value(kStreamColB, zigzag(int8_t(uint8_t(r[2]))));
    }
}

// Fits M (normals ~ M * geometric normal) by least squares over unit vectors; false if
// degenerate.
bool fit_normal_matrix(const EncoderState& st, const std::vector<NormalSum>& acc, std::array<int8_t, 9>& m) {
    double g[3][3] = {}, h[3][3] = {};
    size_t used = 0;
    for (uint32_t v = 0; v < st.V; ++v) {
        double n[3] = {double(acc[v][0]), double(acc[v][1]), double(acc[v][2])};
        double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        if (!(len > 0.0)) continue;
        for (double& x : n) x /= len;
        float t[3];
        oct_decode(st.verts[v].normal(), t);
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) {
                g[i][j] += n[i] * n[j];
                h[i][j] += double(t[i]) * n[j];
            }
        ++used;
    }
    if (used < 3) return false;
    // M = H G^-1.
    double det = g[0][0] * (g[1][1] * g[2][2] - g[1][2] * g[2][1]) - g[0][1] * (g[1][0] * g[2][2] - g[1][2] * g[2][0]) +
                 g[0][2] * (g[1][0] * g[2][1] - g[1][1] * g[2][0]);
    if (!(std::fabs(det) > 1e-9 * double(used) * double(used) * double(used))) return false;
    double inv[3][3];
    inv[0][0] = (g[1][1] * g[2][2] - g[1][2] * g[2][1]) / det;
    inv[0][1] = (g[0][2] * g[2][1] - g[0][1] * g[2][2]) / det;
    inv[0][2] = (g[0][1] * g[1][2] - g[0][2] * g[1][1]) / det;
    inv[1][0] = (g[1][2] * g[2][0] - g[1][0] * g[2][2]) / det;
    inv[1][1] = (g[0][0] * g[2][2] - g[0][2] * g[2][0]) / det;
    inv[1][2] = (g[0][2] * g[1][0] - g[0][0] * g[1][2]) / det;
    inv[2][0] = (g[1][0] * g[2][1] - g[1][1] * g[2][0]) / det;
    inv[2][1] = (g[0][1] * g[2][0] - g[0][0] * g[2][1]) / det;
    inv[2][2] = (g[0][0] * g[1][1] - g[0][1] * g[1][0]) / det;
    double mm[9], top = 0;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
            double s = 0;
            for (int k = 0; k < 3; ++k) s += h[i][k] * inv[k][j];
            mm[3 * i + j] = s;
            top = std::max(top, std::fabs(s));
        }
    if (!(top > 0.0) || !std::isfinite(top)) return false;
    for (int i = 0; i < 9; ++i) m[size_t(i)] = int8_t(std::lround(mm[i] * 127.0 / top));
    return true;
}

}  // namespace

const char* fragment_status_name(FragmentStatus status) {
    switch (status) {
        case FragmentStatus::Ok: return "ok";
        case FragmentStatus::Truncated: return "truncated";
        case FragmentStatus::BadMagic: return "bad magic";
        case FragmentStatus::UnsupportedVersion: return "unsupported version";
        case FragmentStatus::ChecksumMismatch: return "checksum mismatch";
        case FragmentStatus::Corrupt: return "corrupt";
        case FragmentStatus::TooLarge: return "too large";
    }
    return "unknown";
}

size_t fragment_encode_bound(size_t vertex_count, size_t triangle_count) {
    return kHeaderBytes + 3 + 8 * vertex_count + 12 * triangle_count;
}

size_t fragment_encode(const FragmentMesh& mesh, std::vector<uint8_t>& out, FragmentEncodeStats* stats) {
    const size_t V_size = mesh.vertices.size(), T_size = mesh.triangle_count();
    assert(mesh.indices.size() % 3 == 0);
    assert(V_size <= kFragmentMaxVertices && T_size <= kFragmentMaxTriangles);
    const uint32_t V = uint32_t(V_size), T = uint32_t(T_size);
    const uint32_t* idx = mesh.indices.data();
    for (size_t i = 0; i < mesh.indices.size(); ++i) assert(idx[i] < V);

    // Split regular and degenerate triangles.
    std::vector<uint32_t> regular, degenerate;
    regular.reserve(T);
    for (uint32_t t = 0; t < T; ++t) {
        uint32_t a = idx[3 * t], b = idx[3 * t + 1], c = idx[3 * t + 2];
        (a == b || b == c || c == a ? degenerate : regular).push_back(t);
    }
    const uint32_t R = uint32_t(regular.size());

    // Directed half-edges of regular triangles by origin vertex (CSR), each vertex's entries
    // sorted by target: (target, triangle). A lookup binary-searches the target and scans that
    // group from a cursor that skips visited triangles, so even pathological fans and stacks of
    // duplicate triangles cost O(log degree) amortised per lookup.
    std::vector<uint32_t> first(V + 1, 0);
    for (uint32_t t : regular)
        for (int k = 0; k < 3; ++k) ++first[idx[3 * t + k] + 1];
    for (uint32_t v = 0; v < V; ++v) first[v + 1] += first[v];
    std::vector<std::pair<uint32_t, uint32_t>> half(size_t(first[V]));
    {
        std::vector<uint32_t> fill(first.begin(), first.end() - 1);
        for (uint32_t t : regular)
            for (int k = 0; k < 3; ++k) half[fill[idx[3 * t + k]]++] = {idx[3 * t + (k + 1) % 3], t};
        for (uint32_t v = 0; v < V; ++v)
            if (first[v + 1] - first[v] > 1) std::sort(half.begin() + first[v], half.begin() + first[v + 1]);
    }
    std::vector<uint32_t> cursor(half.size());  // at a group's first entry: where to resume
    for (size_t h = 0; h < half.size(); ++h) cursor[h] = uint32_t(h);
    std::vector<uint8_t> visited(T, 0);
    auto find_across = [&](uint32_t from, uint32_t to) -> uint32_t {
        auto lo = half.begin() + first[from], hi = half.begin() + first[from + 1];
        auto g = std::lower_bound(lo, hi, std::pair<uint32_t, uint32_t>{to, 0});
        if (g == hi || g->first != to) return kNone;
        const uint32_t group = uint32_t(g - half.begin());
        uint32_t h = cursor[group];
        while (h < first[from + 1] && half[h].first == to && visited[half[h].second]) ++h;
        cursor[group] = h;
        if (h < first[from + 1] && half[h].first == to) return half[h].second;
        return kNone;
    };

    EncoderState st;
    st.V = V;
    std::vector<uint32_t> new_id(V, kNone), old_of_new;
    old_of_new.reserve(V);
    st.pred.reserve(V);
    st.indices.reserve(size_t(T) * 3);
    Sink conn;
    uint32_t seen = 0;
    auto number = [&](uint32_t old, Pred p) {
        new_id[old] = seen++;
        old_of_new.push_back(old);
        st.pred.push_back(p);
    };
    auto previous_pred = [&]() {
        uint32_t p = seen == 0 ? V : seen - 1;
        return Pred{p, p, p};
    };
    auto put_split = [&](uint32_t old) {
        conn.sym(kStreamConn, kSplit);
        conn.bits(new_id[old], bit_width_u32(seen - 1));
    };

    Front front;
    front.reset(size_t(R) * 2 + 16);
    size_t next_start = 0;
    uint32_t done = 0;
    while (done < R) {
        uint32_t i;
        front.reserve3();
        if (!front.pop(i)) {
            while (visited[regular[next_start]]) ++next_start;
            uint32_t t = regular[next_start];
            visited[t] = 1;
            uint32_t c[3] = {idx[3 * t], idx[3 * t + 1], idx[3 * t + 2]};
            for (uint32_t x : c) {
                if (new_id[x] == kNone) {
                    conn.sym(kStreamConn, kNew);
                    number(x, previous_pred());
                } else {
                    put_split(x);
                }
            }
            front.start(c[0], c[1], c[2]);
            for (uint32_t x : c) st.indices.push_back(new_id[x]);
            ++done;
            continue;
        }
        const FrontEdge ei = front.e[i];
        uint32_t t = find_across(ei.v1, ei.v0);
        if (t == kNone) {
            conn.sym(kStreamConn, kBoundary);
            continue;
        }
        visited[t] = 1;
        ++done;
        uint32_t w = idx[3 * t] ^ idx[3 * t + 1] ^ idx[3 * t + 2] ^ ei.v0 ^ ei.v1;
        if (new_id[w] == kNone) {
            conn.sym(kStreamConn, kNew);
            number(w, Pred{new_id[ei.v0], new_id[ei.v1], new_id[ei.opp]});
            front.add_vertex(i, ei, w);
        } else {
            bool left = front.e[ei.next].v1 == w, right = front.e[ei.prev].v0 == w;
            if (left && right) {
                conn.sym(kStreamConn, kEnd);
                front.end(i, ei);
            } else if (left) {
                conn.sym(kStreamConn, kLeft);
                front.left(i, ei, w);
            } else if (right) {
                conn.sym(kStreamConn, kRight);
                front.right(i, ei, w);
            } else {
                put_split(w);
                front.add_vertex(i, ei, w);
            }
        }
        st.indices.push_back(new_id[ei.v1]);
        st.indices.push_back(new_id[ei.v0]);
        st.indices.push_back(new_id[w]);
    }
    // Vertices outside regular triangles, in original order.
    for (uint32_t v = 0; v < V; ++v)
        if (new_id[v] == kNone) number(v, previous_pred());
    // Degenerate triangles, explicit.
    const int index_bits = V > 0 ? bit_width_u32(V - 1) : 0;
    for (uint32_t t : degenerate)
        for (int k = 0; k < 3; ++k) {
            uint32_t n = new_id[idx[3 * t + k]];
            conn.bits(n, index_bits);
            st.indices.push_back(n);
        }

    st.verts.resize(size_t(V) + 1);
    for (uint32_t v = 0; v < V; ++v) st.verts[v] = mesh.vertices[old_of_new[v]];
    st.verts[V] = PackedVertex{};

    // Positions.
    bool all_valid = true;
    std::vector<Coord> coords(size_t(V) + 1, Coord{0, 0, 0, 0});
    for (uint32_t v = 0; v < V && all_valid; ++v) {
        BaryWeights w;
        if (!bary_unpack(st.verts[v].position_index(), w)) {
            all_valid = false;
            break;
        }
        coords[v] = {w[1] + w[2] + w[3], w[2] + w[3], w[3], 0};
    }
    int pos_mode = kPosRaw;
    Sink pos;
    if (all_valid) {
        double best = 1e300;
        for (int mode : {kPosCumulative, kPosWeights}) {
            Sink s;
            emit_positions(st, mode, coords, s);
            double c = s.cost(kStreamPos0, kStreamPos2);
            if (c < best) {
                best = c;
                pos_mode = mode;
                pos = std::move(s);
            }
        }
    } else {
        emit_positions(st, kPosRaw, coords, pos);
    }

    // Normals.
    int normal_mode = kNormalAverage;
    std::array<int8_t, 9> matrix{};
    Sink nor;
    {
        double best = 1e300;
        std::vector<NormalSum> acc;
        bool geometric = false;
        if (pos_mode != kPosRaw && V > 0) {
            acc.assign(V, NormalSum{0, 0, 0, 0});
            accumulate_normals(st.indices.data(), st.indices.size() / 3, coords.data(), acc.data());
            geometric = fit_normal_matrix(st, acc, matrix);
        }
        for (int mode : {kNormalAverage, kNormalParallelogram, kNormalGeometric}) {
            if (mode == kNormalGeometric && !geometric) continue;
            Sink s;
            emit_normals(st, mode, &acc, matrix, s);
            double c = s.cost(kStreamNormU, kStreamNormV) + (mode == kNormalGeometric ? 72 : 0);
            if (c < best) {
                best = c;
                normal_mode = mode;
                nor = std::move(s);
            }
        }
    }

    // Colours.
    bool color_parallelogram = false, color_decorrelate = false;
    Sink col;
    {
        double best = 1e300;
        for (int k = 0; k < 4; ++k) {
            Sink s;
            emit_colors(st, k & 1, k & 2, s);
            double c = s.cost(kStreamColR, kStreamColB);
            if (c < best) {
                best = c;
                color_parallelogram = k & 1;
                color_decorrelate = k & 2;
                col = std::move(s);
            }
        }
    }

    // Tables, then everything in decode order. Sections (for the size report): tables of each
    // part, then the symbols of each part.
    rans::Encoder enc;
    std::array<rans::FreqTable, kStreamCount> freqs;
    const Sink* parts[4] = {&conn, &pos, &nor, &col};
    const int stream_part[kStreamCount] = {0, 1, 1, 1, 2, 2, 3, 3, 3};
    std::vector<int> section_part;
    for (int s = 0; s < kStreamCount; ++s) {
        if (stream_part[s] == 1 && pos_mode == kPosRaw) continue;
        if (section_part.empty() || section_part.back() != stream_part[s]) {
            enc.begin_section();
            section_part.push_back(stream_part[s]);
        }
        const uint32_t* counts = parts[stream_part[s]]->counts[size_t(s)].data();
        int alphabet = s == kStreamConn ? int(kConnSymbols) : rans::kMaxAlphabet;
        rans::TableDesc d = rans::describe_counts(counts, alphabet);
        bool ok = rans::build_freqs(d, freqs[size_t(s)]);
        assert(ok);
        (void)ok;
        enc.put_table(d);
    }
    for (int p = 0; p < 4; ++p) {
        enc.begin_section();
        section_part.push_back(p);
        for (const Sink::Item& it : parts[p]->items) {
            if (it.stream == kStreamRaw) {
                enc.put_bits(it.value, it.nbits);
            } else {
                enc.put(freqs[it.stream], it.value, it.lane);
                enc.put_bits(it.extra, it.nbits);
            }
        }
    }

    // Assemble.
    const size_t base = out.size();
    std::vector<uint8_t> header(kHeaderBytes, 0);
    std::memcpy(header.data(), kMagicBytes, 4);
    header[4] = kVersion;
    for (int i = 0; i < 4; ++i) {
        header[8 + i] = uint8_t(V >> (8 * i));
        header[12 + i] = uint8_t(T >> (8 * i));
    }
    std::vector<uint8_t> payload;
    put_u16(payload, header_fold(header.data()));
    payload.push_back(kCodingCompressed);
    payload.push_back(uint8_t(pos_mode | (normal_mode << 2) | (color_parallelogram << 4) | (color_decorrelate << 5)));
    if (normal_mode == kNormalGeometric)
        for (int8_t x : matrix) payload.push_back(uint8_t(x));
    put_varint(payload, degenerate.size());
    put_varint(payload, conn.conn_symbols);
    const size_t prefix_bytes = payload.size();
    std::vector<size_t> section_bytes;
    enc.finish(payload, &section_bytes);

    FragmentEncodeStats s;
    const size_t stored_payload = 3 + 8 * size_t(V) + 12 * size_t(T);
    if (payload.size() >= stored_payload) {
        payload.resize(2);
        payload.push_back(kCodingStored);
        for (const PackedVertex& v : mesh.vertices) {
            put_u32(payload, v.word0);
            put_u32(payload, v.word1);
        }
        for (uint32_t i : mesh.indices) put_u32(payload, i);
        s.header_bytes = kHeaderBytes + 3;
        s.connectivity_bytes = 12 * size_t(T);
        s.position_bytes = 3 * size_t(V);
        s.normal_bytes = 2 * size_t(V);
        s.color_bytes = 3 * size_t(V);
    } else {
        s.header_bytes = kHeaderBytes + prefix_bytes - (normal_mode == kNormalGeometric ? 9 : 0);
        s.normal_bytes = normal_mode == kNormalGeometric ? 9 : 0;
        size_t* target[4] = {&s.connectivity_bytes, &s.position_bytes, &s.normal_bytes, &s.color_bytes};
        for (size_t i = 0; i < section_bytes.size(); ++i) *target[section_part[i]] += section_bytes[i];
    }
    uint64_t sum = checksum64(payload.data(), payload.size());
    for (int i = 0; i < 8; ++i) header[kChecksumOffset + size_t(i)] = uint8_t(sum >> (8 * i));
    out.insert(out.end(), header.begin(), header.end());
    out.insert(out.end(), payload.begin(), payload.end());
    if (stats) *stats = s;
    return out.size() - base;
}

FragmentStatus fragment_peek(const uint8_t* data, size_t size, uint32_t& vertex_count, uint32_t& triangle_count) {
    if (size < kHeaderBytes) return FragmentStatus::Truncated;
    if (std::memcmp(data, kMagicBytes, 4) != 0) return FragmentStatus::BadMagic;
    if (data[4] != kVersion || data[5] != 0) return FragmentStatus::UnsupportedVersion;
    if (read_u16(data + 6) != 0) return FragmentStatus::Corrupt;
    vertex_count = read_u32(data + 8);
    triangle_count = read_u32(data + 12);
    if (vertex_count > kFragmentMaxVertices || triangle_count > kFragmentMaxTriangles) return FragmentStatus::TooLarge;
    return FragmentStatus::Ok;
}

namespace {

FragmentStatus decode_stored(const uint8_t* p, size_t size, uint32_t V, uint32_t T, FragmentMesh& out) {
    if (size != 8 * size_t(V) + 12 * size_t(T)) return FragmentStatus::Corrupt;
    out.vertices.resize(V);
    out.indices.resize(size_t(T) * 3);
    for (uint32_t v = 0; v < V; ++v) {
        out.vertices[v].word0 = read_u32(p + 8 * size_t(v));
        out.vertices[v].word1 = read_u32(p + 8 * size_t(v) + 4);
    }
    p += 8 * size_t(V);
    for (size_t i = 0; i < size_t(T) * 3; ++i) {
        out.indices[i] = read_u32(p + 4 * i);
        if (out.indices[i] >= V) return FragmentStatus::Corrupt;
    }
    return FragmentStatus::Ok;
}

// Scratch memory of the decoder, kept per thread between calls (fragments are small and
// decoded by the thousand); fragments above kWorkspaceKeepVertices use a temporary one.
struct Workspace {
    Front front;
    std::vector<Pred> pred;
    std::vector<uint8_t> symbols;
    std::vector<Coord> coords;
    std::vector<int8_t> nu, nv;
    std::vector<NormalSum> acc;
    std::vector<std::array<uint8_t, 4>> rgb;
    std::array<rans::DecodeTable, kStreamCount> tables;
};
constexpr uint32_t kWorkspaceKeepVertices = 1u << 16;

template <class T>
void grow(std::vector<T>& v, size_t n) {
    if (v.size() < n) v.resize(n);
}

// Decoding helpers. kFast: the caller has checked that enough rANS bytes remain for every
// symbol of the current item (2 per symbol) and called need_bits for its raw bits.
template <bool kFast, int L>
CATPAQ_RANS_INLINE uint32_t dsym(rans::Decoder& d, const rans::TableView& t) {
    if constexpr (kFast)
        return d.sym<L>(t);
    else
        return d.get<L>(t);
}
template <bool kFast, int L>
CATPAQ_RANS_INLINE int32_t dresidual(rans::Decoder& d, const rans::TableView& t) {
    uint32_t s = dsym<kFast, L>(d, t);
    const uint32_t b = kBucketDecode.packed[s];
    return unzigzag((b >> 8) | d.take_bits(b & 0xff));
}
constexpr uint32_t kMaxExtraBits = 13;  // bucket symbols < 32

// Runs body.template operator()<kFast>(v) for v in [0, n): in fast mode while the remaining
// rANS bytes cover `symbols` symbols per item, one checked item otherwise. need_bits is called
// for `symbols` values per item.
template <class Body>
CATPAQ_RANS_INLINE void for_each_item(rans::Decoder& dec, uint32_t n, uint32_t symbols, Body&& body) {
    const uint32_t bits = symbols * kMaxExtraBits;
    const size_t bytes = size_t(symbols) * rans::Decoder::kMaxBytesPerSymbol;
    uint32_t v = 0;
    while (v < n) {
        size_t fast = std::min<size_t>(n - v, dec.rans_bytes_left() / bytes);
        for (uint32_t stop = v + uint32_t(fast); v < stop; ++v) {
            dec.need_bits(bits);
            body.template operator()<true>(v);
        }
        if (v < n) {
            dec.need_bits(bits);
            body.template operator()<false>(v);
            ++v;
        }
    }
}

// Each decoding pass copies the decoder into a local (kept in registers) and copies it back.
//
// Connectivity: the `nsym` traversal symbols are decoded first in a tight loop, then the
// traversal consumes them (reading SPLIT indices from the bit stream). Fills tri (3 R indices)
// and pred; returns the number of vertices seen.
FragmentStatus decode_connectivity(rans::Decoder& io, const rans::DecodeTable& conn_table, uint32_t V, uint32_t R,
                                   uint32_t nsym, Workspace& ws, uint32_t* tri, uint32_t& seen_out) {
    grow(ws.symbols, size_t(nsym) + 1);
    uint8_t* sym = ws.symbols.data();
    {
        rans::Decoder dec = io;
        const rans::TableView conn(conn_table);
        uint32_t k = 0;
        // Symbol k is on lane k & 3.
        while (nsym - k >= 4 && dec.rans_bytes_left() >= 4 * rans::Decoder::kMaxBytesPerSymbol) {
            sym[k] = uint8_t(dec.sym<0>(conn));
            sym[k + 1] = uint8_t(dec.sym<1>(conn));
            sym[k + 2] = uint8_t(dec.sym<2>(conn));
            sym[k + 3] = uint8_t(dec.sym<3>(conn));
            k += 4;
        }
        for (; k < nsym; ++k) {
            switch (k & 3) {
                case 0: sym[k] = uint8_t(dec.get<0>(conn)); break;
                case 1: sym[k] = uint8_t(dec.get<1>(conn)); break;
                case 2: sym[k] = uint8_t(dec.get<2>(conn)); break;
                default: sym[k] = uint8_t(dec.get<3>(conn)); break;
            }
        }
        io = dec;
    }
    sym[nsym] = 0xff;  // sentinel: running out of symbols reads an invalid one
    rans::Decoder dec = io;
    Pred* pred = ws.pred.data();
    Front& front = ws.front;
    front.reset(std::min<size_t>(size_t(R) * 2 + 16, size_t(1) << 20));
    uint32_t seen = 0;
    const uint8_t* next = sym;
    for (uint32_t done = 0; done < R;) {
        front.reserve3();
        uint32_t i;
        if (!front.pop(i)) {
            // A new component: three vertices, each NEW or SPLIT.
            uint32_t c[3];
            for (int k = 0; k < 3; ++k) {
                uint32_t s = *next++;
                if (s == kNew) {
                    if (seen == V) return FragmentStatus::Corrupt;
                    uint32_t q = seen == 0 ? V : seen - 1;
                    pred[seen] = Pred{q, q, q};
                    c[k] = seen++;
                } else if (s == kSplit) {
                    if (seen == 0) return FragmentStatus::Corrupt;
                    c[k] = dec.get_bits(uint32_t(bit_width_u32(seen - 1)));
                    if (c[k] >= seen) return FragmentStatus::Corrupt;
                } else {
                    return FragmentStatus::Corrupt;
                }
            }
            if (c[0] == c[1] || c[1] == c[2] || c[2] == c[0]) return FragmentStatus::Corrupt;
            front.start(c[0], c[1], c[2]);
            tri[0] = c[0], tri[1] = c[1], tri[2] = c[2];
            tri += 3;
            ++done;
            continue;
        }
        const FrontEdge ei = front.e[i];
        const uint32_t s = *next++;
        uint32_t v;
        if (s <= kRight) [[likely]] {
            // NEW, LEFT and RIGHT without branches (they are the bulk and unpredictable); the
            // same edits as Front::add_vertex / left / right.
            // Selections use masks: the compiler would otherwise branch on them.
            FrontEdge* e = front.e;
            const uint32_t is_new = s == kNew, is_left = s == kLeft, is_right = s == kRight;
            const uint32_t m_new = 0u - is_new, m_left = 0u - is_left, m_right = 0u - is_right;
            const uint32_t p = ei.prev, n = ei.next;
            const uint32_t vl = e[n].v1, vr = e[p].v0, pp = e[p].prev, nn = e[n].next;
            v = (seen & m_new) | (vl & m_left) | (vr & m_right);
            pred[(seen & m_new) | (V & ~m_new)] = Pred{ei.v0, ei.v1, ei.opp};  // slot V: scratch
            seen += is_new;
            if ((seen > V) | (v == ei.v0) | (v == ei.v1)) [[unlikely]]
                return FragmentStatus::Corrupt;
            const uint32_t left_anchor = (pp & m_right) | (p & ~m_right);
            const uint32_t right_anchor = (nn & m_left) | (n & ~m_left);
            const uint32_t f = front.size, last = f + is_new;
            // First new edge: (v0 -> v), or (v -> v1) for RIGHT; second (NEW only): (v -> v1).
            e[f].v0 = (v & m_right) | (ei.v0 & ~m_right);
            e[f].v1 = (ei.v1 & m_right) | (v & ~m_right);
            e[f].opp = (ei.v0 & m_right) | (ei.v1 & ~m_right);
            e[f].prev = left_anchor;
            e[f].next = ((f + 1) & m_new) | (right_anchor & ~m_new);
            e[f + 1] = FrontEdge{v, ei.v1, ei.v0, f, right_anchor};  // room reserved by reserve3
            e[left_anchor].next = f;
            e[right_anchor].prev = last;
            e[(n & m_left) | (p & m_right) | (i & m_new)].prev = kDead;
            e[i].prev = kDead;
            front.size = last + 1;
            tri[0] = ei.v1, tri[1] = ei.v0, tri[2] = v;
            tri += 3;
            ++done;
            continue;
        }
        switch (s) {
            case kBoundary:
                continue;
            case kEnd:
                v = front.e[ei.next].v1;
                if (v == ei.v0 || v == ei.v1 || front.e[ei.prev].v0 != v) return FragmentStatus::Corrupt;
                front.end(i, ei);
                break;
            case kSplit:
                if (seen == 0) return FragmentStatus::Corrupt;
                v = dec.get_bits(uint32_t(bit_width_u32(seen - 1)));
                if (v >= seen || v == ei.v0 || v == ei.v1) return FragmentStatus::Corrupt;
                front.add_vertex(i, ei, v);
                break;
            default:
                return FragmentStatus::Corrupt;
        }
        tri[0] = ei.v1, tri[1] = ei.v0, tri[2] = v;
        tri += 3;
        ++done;
    }
    if (next != sym + nsym) return FragmentStatus::Corrupt;  // symbols left over
    seen_out = seen;
    io = dec;
    return FragmentStatus::Ok;
}

// Positions: fills word0's position bits and ws.sa/sb/sc (cumulative coordinates, index V = 0).
// False on a coordinate out of range.
bool decode_positions(rans::Decoder& io, Workspace& ws, int pos_mode, uint32_t V, const Pred* pred,
                      PackedVertex* vert) {
    rans::Decoder dec = io;
    Coord* s = ws.coords.data();
    s[V] = {0, 0, 0, 0};
    uint32_t bad = 0;  // accumulated range violations, checked once
    const rans::TableView t0(ws.tables[kStreamPos0]), t1(ws.tables[kStreamPos1]), t2(ws.tables[kStreamPos2]);
    if (pos_mode == kPosRaw) {
        for (uint32_t v = 0; v < V; ++v) vert[v].word0 = dec.get_bits(24);
    } else if (pos_mode == kPosCumulative) {
        for_each_item(dec, V, 3, [&]<bool kFast>(uint32_t v) __attribute__((always_inline)) {
            const Pred q = pred[v];
            const Coord A = s[q.a], B = s[q.b], C = s[q.c];
            int32_t a = std::clamp(A[0] + B[0] - C[0], 0, kGrid) + dresidual<kFast, 0>(dec, t0);
            int32_t rb = dresidual<kFast, 1>(dec, t1), rc = dresidual<kFast, 2>(dec, t2);
            bad |= uint32_t(a) > uint32_t(kGrid);
            a = std::clamp(a, 0, kGrid);
            int32_t b = std::clamp(A[1] + B[1] - C[1], 0, a) + rb;
            bad |= uint32_t(b) > uint32_t(a);
            b = std::clamp(b, 0, a);
            int32_t c = std::clamp(A[2] + B[2] - C[2], 0, b) + rc;
            bad |= uint32_t(c) > uint32_t(b);
            c = std::clamp(c, 0, b);
            s[v] = {a, b, c, 0};
            vert[v].word0 = kBaryTables.tet[size_t(a)] + kBaryTables.tri[size_t(b)] + uint32_t(c);
        });
    } else {
        // Weight space: (w1, w2, w3) kept in s during the pass, converted after.
        for_each_item(dec, V, 3, [&]<bool kFast>(uint32_t v) __attribute__((always_inline)) {
            const Pred q = pred[v];
            const Coord A = s[q.a], B = s[q.b], C = s[q.c];
            int32_t w1 = std::clamp(A[0] + B[0] - C[0], 0, kGrid) + dresidual<kFast, 0>(dec, t0);
            int32_t r2 = dresidual<kFast, 1>(dec, t1), r3 = dresidual<kFast, 2>(dec, t2);
            bad |= uint32_t(w1) > uint32_t(kGrid);
            w1 = std::clamp(w1, 0, kGrid);
            int32_t w2 = std::clamp(A[1] + B[1] - C[1], 0, kGrid - w1) + r2;
            bad |= uint32_t(w2) > uint32_t(kGrid - w1);
            w2 = std::clamp(w2, 0, kGrid - w1);
            int32_t w3 = std::clamp(A[2] + B[2] - C[2], 0, kGrid - w1 - w2) + r3;
            bad |= uint32_t(w3) > uint32_t(kGrid - w1 - w2);
            w3 = std::clamp(w3, 0, kGrid - w1 - w2);
            s[v] = {w1, w2, w3, 0};
            int32_t a = w1 + w2 + w3, b = w2 + w3;
            vert[v].word0 = kBaryTables.tet[size_t(a)] + kBaryTables.tri[size_t(b)] + uint32_t(w3);
        });
        for (uint32_t v = 0; v < V; ++v) s[v] = {s[v][0] + s[v][1] + s[v][2], s[v][1] + s[v][2], s[v][2], 0};
    }
    io = dec;
    return bad == 0;
}

// Normals: ORs u into word0 and sets word1 to v (signed bytes; index V is the virtual zero vertex).
void decode_normals(rans::Decoder& io, Workspace& ws, int normal_mode, const std::array<int8_t, 9>& matrix, uint32_t V,
                    uint32_t T, const Pred* pred, const uint32_t* indices, PackedVertex* vert) {
    grow(ws.nu, size_t(V) + 1);
    grow(ws.nv, size_t(V) + 1);
    int8_t *nu = ws.nu.data(), *nv = ws.nv.data();
    nu[V] = nv[V] = 0;
    rans::Decoder dec = io;
    const rans::TableView tu(ws.tables[kStreamNormU]), tv(ws.tables[kStreamNormV]);
    if (normal_mode == kNormalGeometric) {
        ws.acc.assign(V, NormalSum{0, 0, 0, 0});
        accumulate_normals(indices, T, ws.coords.data(), ws.acc.data());
        const NormalSum* acc = ws.acc.data();
        int prev_u = 0, prev_v = 0;
        for_each_item(dec, V, 2, [&]<bool kFast>(uint32_t v) __attribute__((always_inline)) {
            int ru = dresidual<kFast, 0>(dec, tu), rv = dresidual<kFast, 1>(dec, tv);
            int pu, pv;
            geometric_prediction(acc[v], matrix, prev_u, prev_v, pu, pv);
            prev_u = int8_t(uint8_t(pu + ru));
            prev_v = int8_t(uint8_t(pv + rv));
            nu[v] = int8_t(prev_u), nv[v] = int8_t(prev_v);
        });
    } else if (normal_mode == kNormalAverage) {
        for_each_item(dec, V, 2, [&]<bool kFast>(uint32_t v) __attribute__((always_inline)) {
            const Pred q = pred[v];
            int ru = dresidual<kFast, 0>(dec, tu), rv = dresidual<kFast, 1>(dec, tv);
            nu[v] = int8_t(uint8_t(((nu[q.a] + nu[q.b]) >> 1) + ru));
            nv[v] = int8_t(uint8_t(((nv[q.a] + nv[q.b]) >> 1) + rv));
        });
    } else {
        for_each_item(dec, V, 2, [&]<bool kFast>(uint32_t v) __attribute__((always_inline)) {
            const Pred q = pred[v];
            int ru = dresidual<kFast, 0>(dec, tu), rv = dresidual<kFast, 1>(dec, tv);
            nu[v] = int8_t(uint8_t(std::clamp(nu[q.a] + nu[q.b] - nu[q.c], -127, 127) + ru));
            nv[v] = int8_t(uint8_t(std::clamp(nv[q.a] + nv[q.b] - nv[q.c], -127, 127) + rv));
        });
    }
    io = dec;
    for (uint32_t v = 0; v < V; ++v) {
        vert[v].word0 |= uint32_t(uint8_t(nu[v])) << 24;
        vert[v].word1 = uint8_t(nv[v]);
    }
}

// Colours: ORs R, G, B into word1.
template <bool kParallelogram>
void decode_colors_with(rans::Decoder& io, Workspace& ws, bool decorrelate, uint32_t V, const Pred* pred,
                        PackedVertex* vert) {
    grow(ws.rgb, size_t(V) + 1);
    std::array<uint8_t, 4>* rgb = ws.rgb.data();
    rgb[V] = {0, 0, 0, 0};
    rans::Decoder dec = io;
    const rans::TableView tr(ws.tables[kStreamColR]), tg(ws.tables[kStreamColG]), tb(ws.tables[kStreamColB]);
    const int32_t dmask = decorrelate ? -1 : 0;
    auto predict = [](int a, int b, int c) {
        if constexpr (kParallelogram)
            return std::clamp(a + b - c, 0, 255);
        else
            return (a + b + 1) >> 1;
    };
    for_each_item(dec, V, 3, [&]<bool kFast>(uint32_t v) __attribute__((always_inline)) {
        const Pred q = pred[v];
        int32_t rg = dresidual<kFast, 0>(dec, tg);
        int32_t rr = dresidual<kFast, 1>(dec, tr) + (rg & dmask);
        int32_t rb = dresidual<kFast, 2>(dec, tb) + (rg & dmask);
        const std::array<uint8_t, 4> A = rgb[q.a], B = rgb[q.b], C = rgb[q.c];
        const uint32_t r = uint8_t(predict(A[0], B[0], C[0]) + rr);
        const uint32_t g = uint8_t(predict(A[1], B[1], C[1]) + rg);
        const uint32_t bl = uint8_t(predict(A[2], B[2], C[2]) + rb);
        rgb[v] = {uint8_t(r), uint8_t(g), uint8_t(bl), 0};
        vert[v].word1 |= r << 8 | g << 16 | bl << 24;
    });
    io = dec;
}

void decode_colors(rans::Decoder& io, Workspace& ws, bool parallelogram, bool decorrelate, uint32_t V,
                   const Pred* pred, PackedVertex* vert) {
    if (parallelogram)
        decode_colors_with<true>(io, ws, decorrelate, V, pred, vert);
    else
        decode_colors_with<false>(io, ws, decorrelate, V, pred, vert);
}

FragmentStatus decode_compressed(const uint8_t* p, size_t size, uint32_t V, uint32_t T, FragmentMesh& out,
                                 Workspace& ws) {
    if (size < 1) return FragmentStatus::Corrupt;
    const uint8_t modes = *p++;
    --size;
    const int pos_mode = modes & 3, normal_mode = (modes >> 2) & 3;
    const bool color_parallelogram = (modes >> 4) & 1, color_decorrelate = (modes >> 5) & 1;
    if (pos_mode > kPosRaw || normal_mode > kNormalGeometric || (modes >> 6) != 0) return FragmentStatus::Corrupt;
    if (normal_mode == kNormalGeometric && pos_mode == kPosRaw) return FragmentStatus::Corrupt;
    std::array<int8_t, 9> matrix{};
    if (normal_mode == kNormalGeometric) {
        if (size < 9) return FragmentStatus::Corrupt;
        for (int i = 0; i < 9; ++i) matrix[size_t(i)] = int8_t(p[i]);
        p += 9;
        size -= 9;
    }
    uint64_t E = 0;
    for (int shift = 0;; shift += 7) {
        if (size == 0 || shift > 28) return FragmentStatus::Corrupt;
        uint8_t b = *p++;
        --size;
        E |= uint64_t(b & 0x7f) << shift;
        if (!(b & 0x80)) break;
    }
    if (E > T) return FragmentStatus::Corrupt;
    const uint32_t R = T - uint32_t(E);
    uint64_t conn_symbols = 0;
    for (int shift = 0;; shift += 7) {
        if (size == 0 || shift > 28) return FragmentStatus::Corrupt;
        uint8_t b = *p++;
        --size;
        conn_symbols |= uint64_t(b & 0x7f) << shift;
        if (!(b & 0x80)) break;
    }
    // Every triangle takes one symbol (three to start a component), every BOUNDARY one of the
    // at most 3 R front edges.
    if (conn_symbols > 6 * uint64_t(R) || conn_symbols < R) return FragmentStatus::Corrupt;
    if (R > 0 && V < 3) return FragmentStatus::Corrupt;

    rans::Decoder dec;
    if (!dec.init(p, size)) return FragmentStatus::Corrupt;
    for (int s = 0; s < kStreamCount; ++s) {
        if (pos_mode == kPosRaw && s >= kStreamPos0 && s <= kStreamPos2) continue;
        rans::FreqTable f;
        if (!dec.get_table(f, ws.tables[size_t(s)])) return FragmentStatus::Corrupt;
        if (s == kStreamConn && f.nsym > int(kConnSymbols)) return FragmentStatus::Corrupt;
    }

    out.vertices.resize(V);
    out.indices.resize(size_t(T) * 3);
    grow(ws.pred, size_t(V) + 1);
    Pred* pred = ws.pred.data();
    uint32_t seen = 0;
    FragmentStatus st = decode_connectivity(dec, ws.tables[kStreamConn], V, R, uint32_t(conn_symbols), ws,
                                            out.indices.data(), seen);
    if (st != FragmentStatus::Ok) return st;
    for (; seen < V; ++seen) {
        uint32_t q = seen == 0 ? V : seen - 1;
        pred[seen] = Pred{q, q, q};
    }
    const int index_bits = V > 0 ? bit_width_u32(V - 1) : 0;
    uint32_t* tri = out.indices.data() + 3 * size_t(R);
    for (uint64_t k = 0; k < 3 * E; ++k) {
        uint32_t v = dec.get_bits(uint32_t(index_bits));
        if (v >= V) return FragmentStatus::Corrupt;
        *tri++ = v;
    }
    if (!dec.ok()) return FragmentStatus::Corrupt;

    // Positions (index V: the virtual zero vertex).
    grow(ws.coords, size_t(V) + 1);
    if (!decode_positions(dec, ws, pos_mode, V, pred, out.vertices.data())) return FragmentStatus::Corrupt;
    decode_normals(dec, ws, normal_mode, matrix, V, T, pred, out.indices.data(), out.vertices.data());
    decode_colors(dec, ws, color_parallelogram, color_decorrelate, V, pred, out.vertices.data());
    if (!dec.finished_cleanly()) return FragmentStatus::Corrupt;
    return FragmentStatus::Ok;
}

}  // namespace

namespace {

FragmentStatus decode_fragment(const uint8_t* data, size_t size, FragmentMesh& out) {
    uint32_t V = 0, T = 0;
    FragmentStatus st = fragment_peek(data, size, V, T);
    if (st != FragmentStatus::Ok) return st;
    const uint8_t* payload = data + kHeaderBytes;
    const size_t payload_size = size - kHeaderBytes;
    uint64_t expected = 0;
    for (int i = 0; i < 8; ++i) expected |= uint64_t(data[kChecksumOffset + size_t(i)]) << (8 * i);
    if (checksum64(payload, payload_size) != expected) return FragmentStatus::ChecksumMismatch;
    if (payload_size < 3) return FragmentStatus::Corrupt;
    if (read_u16(payload) != header_fold(data)) return FragmentStatus::Corrupt;
    const uint8_t coding = payload[2];
    if (coding == kCodingStored) return decode_stored(payload + 3, payload_size - 3, V, T, out);
    if (coding != kCodingCompressed) return FragmentStatus::Corrupt;
    if (V <= kWorkspaceKeepVertices) {
        thread_local Workspace ws;
        return decode_compressed(payload + 3, payload_size - 3, V, T, out, ws);
    }
    Workspace ws;
    return decode_compressed(payload + 3, payload_size - 3, V, T, out, ws);
}

}  // namespace

FragmentStatus fragment_decode(const uint8_t* data, size_t size, FragmentMesh& out) {
    // `out` is resized, not cleared first: every element is overwritten, and reusing a mesh
    // of similar size then costs no zero-filling.
    FragmentStatus st = decode_fragment(data, size, out);
    if (st != FragmentStatus::Ok) {
        out.vertices.clear();
        out.indices.clear();
    }
    return st;
}

}  // namespace catpaq
