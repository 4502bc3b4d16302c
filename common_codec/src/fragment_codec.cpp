// The lossless fragment codec (see common_codec/fragment_codec.h for the API).
//
// Bitstream, versions 1 and 2 (all little-endian)
// -----------------------------------------------
// Version 2 differs from version 1 in two places, both for decoding speed: the arithmetic of the
// geometric normal predictor (below: single precision instead of double and 64-bit integer sums)
// and the joint colour coding (modes bit 6). The decoder reads both versions; the encoder writes
// version 2 unless asked for 1 (fragment_encode's `version`). From the same input both decode to
// the same vertex and index arrays.
//
//   header (24 bytes): u32 magic "CFRG" | u8 version = 1 or 2 | u8 vertex layout (0 = Rgb24,
//                      1 = Position48, 2 = Rgb18, packed_vertex.h) | u16 grid G (0 stands for 463, and is
//                      what Rgb24 with G = 463 writes: the bytes of the first datasets) |
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
//                       weights (w1, w2, w3), 2 = raw payload position bits (24 for Rgb24, 30
//                       for Rgb18, 48 for Position48: any vertex whose position is not valid
//                       for the grid);
//                       bits 2-3 normal predictor: 0 = gate average, 1 = parallelogram,
//                       2 = geometric; bit 4 colour predictor: 0 = gate average,
//                       1 = parallelogram; bit 5: R and B residuals are coded relative to the
//                       G residual; bit 6 (version 2, colour layouts only): joint colour
//                       coding; bit 7 zero (version 1: bits 6-7 zero)
//     i8 x 9            geometric normal predictor only: row-major 3x3 matrix M mapping a normal
//                       computed in (a, b, c) space to the frame of the normals (any scale)
//     varint E          number of degenerate triangles (a repeated index), coded explicitly
//     varint N          number of connectivity symbols
//     entropy coded     rans.h: u32 state0..3 | varint bit_bytes | rANS bytes | raw bit stream.
//                       Symbols go through rANS (lane per symbol below), the low bits of large
//                       residuals and explicit indices through the raw bit stream; in decode
//                       order:
//       tables          connectivity (6 symbols), 3 position tables (absent for raw positions),
//                       normal u, v, colour R, G, B, then with the joint colour coding the joint
//                       table (at most 28 symbols): alphabet size, scale and log-domain weights
//                       (rans.h), symbols on lane 0; layouts without colour have no colour
//                       tables and no colour values
//       connectivity    N traversal symbols (symbol k on lane k & 3) and, in the bit stream,
//                       SPLIT indices; then E x 3 indices of bit_width(V - 1) bits each
//       positions       per vertex in decoded order: 3 residual values (lanes 0, 1, 2), or 24
//                       (48) raw bits
//       normals         per vertex: u, v residual values (lanes 0, 1), modulo 256
//       colours         per vertex: G, R, B residual values (lanes 0, 1, 2), modulo 2^bits
//                       (8 bits per channel for Rgb24, 6 for Rgb18). Joint colour coding: V
//                       joint symbols (vertex v's on lane v & 3), j = zG + 3 zR + 9 zB when
//                       the zig-zag mapped values zG, zR, zB of the vertex's three residuals
//                       (as the separate coding codes them) are all below 3, else 27 (escape);
//                       then for each escaped vertex, in order, its G, R, B residual values as
//                       in the separate coding (lanes 0, 1, 2, with the G, R, B tables)
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
// (a in [0, G], b in [0, a], c in [0, b]; in weight space w1 in [0, G], w2 in [0, G - w1],
// w3 in [0, G - w1 - w2]). The geometric normal predictor sums, per vertex, the cross products
// of its triangles in (a, b, c) space, maps the sum by M and projects it to the octahedral code,
// rounding half up (vertices with a zero sum take the previous vertex's normal). (Averaging it
// with the neighbours' parallelogram where both agree saves about 0.5 bit per vertex on the bunny
// but chains every vertex to its predecessors and costs about 7% of the decoding speed, so it is
// not done.) Normal residuals wrap modulo 256, colour residuals modulo the channel's range.
//
// The geometric predictor's arithmetic, over the triangles in decoded order (the traversal's,
// then the explicit ones), each (i, j, k) with e1 = s_j - s_i, e2 = s_k - s_i (s: the vertex's
// cumulative coordinates) and n = (e1y e2z - e1z e2y, e1z e2x - e1x e2z, e1x e2y - e1y e2x)
// added to the sums of i, j and k in that order (sums start at zero); then per vertex, with the
// sum N and M's entries m0..m8 (row-major):
//   x = (m0 N0 + m1 N1) + m2 N2, y = (m3 N0 + m4 N1) + m5 N2, z = (m6 N0 + m7 N1) + m8 N2,
//   l1 = (|x| + |y|) + |z|; no prediction unless l1 > 0; s = 127 / l1, u = x s, v = y s;
//   if z < 0: (u, v) = (+-(127 - |v|), +-(127 - |u|)) with the signs of u and v (zero positive);
//   predicted code = clamp(floor(u + 128.5) - 128, -127, 127), the same for v.
//   Version 1: n and the sums in exact 64-bit integers, the rest in IEEE double precision.
//   Version 2: everything in IEEE single precision (round to nearest, no fused multiply-add),
//   each operation rounded in the order written. The sums and the projection then take four
//   components or four vertices per SSE2 instruction, which made decoding the 1M-triangle scan's
//   dataset about 1.1x faster; the predictions differ from version 1's only by rare roundings
//   (the same bytes on the bunny and the scan).
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

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "base/checksum.h"
#include "common_codec/octahedral.h"
#include "rans.h"

namespace catpaq {

namespace {

constexpr uint8_t kMagicBytes[4] = {'C', 'F', 'R', 'G'};
// Version 1: geometric normals in double from 64-bit integer sums. Version 2: in float
// (predict_normals_f). Both decode; the encoder writes kFragmentVersion unless asked otherwise.
static_assert(kFragmentVersion == 2 && kFragmentOldestVersion == 1);
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
    kStreamColJoint,  // version 2, modes bit 6
    kStreamCount,
};

// rANS lane of each stream (the coordinates of one vertex decode in parallel); connectivity
// symbols use lane (symbol index & 3). (Putting every part's symbols on the four lanes in turn
// instead, so that the fourth lane is not idle, made the decoder 4% slower: with four lanes and
// three tables in one loop the compiler ran out of registers.)
constexpr int kStreamLane[kStreamCount] = {0, 0, 1, 2, 0, 1, 1, 0, 2, 0};

// Version 2's joint colour coding (modes bit 6): a vertex's three coded colour values (G, R, B
// residuals, zig-zag mapped) as one symbol zg + 3 zr + 9 zb when each is below 3, else the escape
// and, later, the three values as in the separate coding. Smooth colours (a scan's: 1.4 bits per
// vertex for all three channels) then cost one rANS symbol per vertex instead of three: the
// symbols, not the bytes, were the colours' share of the decoding time.
constexpr uint32_t kJointEscape = 27;
constexpr int kJointSymbols = 28;
CATPAQ_RANS_INLINE uint32_t joint_symbol(uint32_t zg, uint32_t zr, uint32_t zb) {
    return zg < 3 && zr < 3 && zb < 3 ? zg + 3 * zr + 9 * zb : kJointEscape;
}
// The residuals (G, R, B) of each joint symbol below the escape.
struct JointResiduals {
    std::array<std::array<int32_t, 4>, kJointEscape> rgb{};
    constexpr JointResiduals() {
        constexpr int32_t unzig[3] = {0, -1, 1};
        for (uint32_t j = 0; j < kJointEscape; ++j) rgb[j] = {unzig[j % 3], unzig[j / 3 % 3], unzig[j / 9], 0};
    }
};
constexpr JointResiduals kJointResiduals{};

enum PositionMode { kPosCumulative = 0, kPosWeights = 1, kPosRaw = 2 };
enum NormalMode { kNormalAverage = 0, kNormalParallelogram = 1, kNormalGeometric = 2 };

constexpr uint32_t kNone = 0xffffffffu;
constexpr uint32_t kDead = 0xffffffffu;

uint32_t zigzag(int32_t v) { return (uint32_t(v) << 1) ^ uint32_t(v >> 31); }
int32_t unzigzag(uint32_t z) { return int32_t(z >> 1) ^ -int32_t(z & 1); }

int bit_width_u32(uint32_t v) { return int(std::bit_width(v)); }

// Value buckets: symbol, number of extra bits, extra bits value.
struct Bucket {
    uint32_t sym, nbits, extra;
};
constexpr Bucket bucket_by_bits(uint32_t z) {
    if (z < 8) return {z, 0, 0};
    int k = int(std::bit_width(z)) - 1;
    return {uint32_t(8 + 2 * (k - 3)) + ((z >> (k - 1)) & 1u), uint32_t(k - 1), z & ((1u << (k - 1)) - 1)};
}
// Symbol and extra-bit count of every value below 1024 (positions on the 24-bit layout's grid
// are below 2 * 463, normals and colours below 256; larger grids' residuals go the long way). A lookup instead of the branch on z < 8,
// which the encoder mispredicted often (it buckets every residual of every trial mode).
struct BucketTable {
    std::array<uint8_t, 1024> sym{}, nbits{};
    constexpr BucketTable() {
        for (uint32_t z = 0; z < 1024; ++z) {
            sym[z] = uint8_t(bucket_by_bits(z).sym);
            nbits[z] = uint8_t(bucket_by_bits(z).nbits);
        }
    }
};
constexpr BucketTable kBucketTable{};
CATPAQ_RANS_INLINE Bucket bucket_of(uint32_t z) {
    if (z >= 1024) [[unlikely]]
        return bucket_by_bits(z);
    const uint32_t n = kBucketTable.nbits[z];
    return {kBucketTable.sym[z], n, z & ((1u << n) - 1)};
}
// Per bucket symbol: (base << 8) | number of extra bits; and the same unpacked (the decoder's
// form: loads instead of unpacking instructions).
struct BucketDecode {
    std::array<uint32_t, rans::kMaxAlphabet> packed{}, base{}, nbits{};
    constexpr BucketDecode() {
        for (uint32_t s = 0; s < uint32_t(rans::kMaxAlphabet); ++s) {
            if (s < 8) {
                packed[s] = s << 8;
            } else {
                uint32_t k = 3 + (s - 8) / 2, hi = (s - 8) & 1;
                packed[s] = (((1u << k) | (hi << (k - 1))) << 8) | (k - 1);
            }
            base[s] = packed[s] >> 8;
            nbits[s] = packed[s] & 0xff;
        }
    }
};
constexpr BucketDecode kBucketDecode{};
static_assert((kBucketDecode.packed[rans::kMaxAlphabet - 1] & 0xff) <= 13);

// Tetrahedral-number enumeration of barycentric.h: index = tet(a) + tri(b) + c.
struct BaryTables {
    std::array<uint32_t, kMaxIndexGrid + 1> tet{}, tri{};
    constexpr BaryTables() {
        for (uint32_t a = 0; a <= uint32_t(kMaxIndexGrid); ++a) {
            tet[a] = uint32_t(uint64_t(a) * (a + 1) * (a + 2) / 6);
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
// Sums of integer cross products: each product component is below 2^29 in magnitude
// (coordinates are <= 16383, so each product fits 32 bits). The encoder and the decoder evaluate
// the prediction with the same operations in the same order, so it agrees on both sides whether
// or not the doubles below are exact (they are for the 24-bit layout's grid).
using NormalSum = std::array<int64_t, 4>;
// Area-weighted normals in (a, b, c) space: sum of the cross products of each vertex's triangles.
// One triangle's cross product added to its three corners' sums.
CATPAQ_RANS_INLINE void accumulate_triangle(const uint32_t* tri, const Coord* s, NormalSum* acc) {
    uint32_t i = tri[0], j = tri[1], k = tri[2];
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

void accumulate_normals(const uint32_t* indices, size_t triangles, const Coord* s, NormalSum* acc) {
    for (size_t t = 0; t < triangles; ++t) accumulate_triangle(indices + 3 * t, s, acc);
}

#if defined(__SSE2__)
// The matrix M as packed doubles: columns of the (x, y) rows, and the z row.
struct NormalMatrix {
    __m128d c0, c1, c2;  // (m0, m3), (m1, m4), (m2, m5)
    double z0, z1, z2;   // m6, m7, m8
    explicit NormalMatrix(const std::array<int8_t, 9>& m)
        : c0(_mm_setr_pd(m[0], m[3])), c1(_mm_setr_pd(m[1], m[4])), c2(_mm_setr_pd(m[2], m[5])), z0(m[6]), z1(m[7]),
          z2(m[8]) {}
};

// geometric_prediction's arithmetic with u and v in the two halves of one SSE2 register: the same
// IEEE operations in the same order on each half (so the same bits as the scalar form below,
// which stays the reference for other targets), without the scalar form's moves of doubles
// through integer registers for the selects. Measured: the geometric normal pass was a fifth of
// the decoder's profile, most of it here.
CATPAQ_RANS_INLINE bool geometric_prediction_sse2(const NormalSum& n, const NormalMatrix& m, int& pu, int& pv) {
    const double n0 = double(n[0]), n1 = double(n[1]), n2 = double(n[2]);
    const __m128d N0 = _mm_set1_pd(n0), N1 = _mm_set1_pd(n1), N2 = _mm_set1_pd(n2);
    // (x, y) = ((m0 n0 + m1 n1) + m2 n2, (m3 n0 + m4 n1) + m5 n2), as the scalar form.
    const __m128d xy = _mm_add_pd(_mm_add_pd(_mm_mul_pd(m.c0, N0), _mm_mul_pd(m.c1, N1)), _mm_mul_pd(m.c2, N2));
    const double z = m.z0 * n0 + m.z1 * n1 + m.z2 * n2;
    const __m128d sign = _mm_set1_pd(-0.0);
    const __m128d axy = _mm_andnot_pd(sign, xy);  // (|x|, |y|)
    const double l1 = (_mm_cvtsd_f64(axy) + _mm_cvtsd_f64(_mm_unpackhi_pd(axy, axy))) + std::fabs(z);
    if (!(l1 > 0.0)) [[unlikely]]
        return false;
    const __m128d uv = _mm_mul_pd(xy, _mm_set1_pd(127.0 / l1));
    // Folded: (sign(u) (127 - |v|), sign(v) (127 - |u|)), the sign of zero taken as positive;
    // multiplying by -1 is flipping the sign bit.
    const __m128d auv = _mm_andnot_pd(sign, uv);
    const __m128d rest = _mm_sub_pd(_mm_set1_pd(127.0), _mm_shuffle_pd(auv, auv, 1));
    const __m128d fold = _mm_xor_pd(rest, _mm_and_pd(_mm_cmplt_pd(uv, _mm_setzero_pd()), sign));
    const __m128d r = z < 0.0 ? fold : uv;
    // Round half up: |u|, |v| <= 127, so u + 128.5 > 0 and truncation is floor.
    const __m128i t = _mm_cvttpd_epi32(_mm_add_pd(r, _mm_set1_pd(128.5)));
    pu = std::clamp(_mm_cvtsi128_si32(t) - 128, -127, 127);
    pv = std::clamp(_mm_cvtsi128_si32(_mm_shuffle_epi32(t, 1)) - 128, -127, 127);
    return true;
}
#endif

// Predicted normal of a vertex under the geometric predictor; `prev_u/v` is the fallback.
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

// ---- Version 2's geometric normals, in float ------------------------------------------------
// The same predictor as version 1's (area-weighted sum of the triangles' cross products in
// (a, b, c) space, mapped by M, projected to the octahedral code, rounded half up), evaluated in
// float, four components per SSE2 register: the cross product and the sum of a corner as one
// vector each (version 1: three 64-bit integer read-modify-writes per corner), and the
// projection four vertices at a time (version 1: one vertex, in double). Float rounds
// differently from the exact integer sums now and then, which moves a prediction by one step
// at most and costs nothing measurable; encoder and decoder run these same functions, so they
// agree bit for bit (IEEE single precision, no contraction: -ffp-contract=off).

// Coordinates (a, b, c, 0) or a normal sum (x, y, z, 0).
using Float4 = std::array<float, 4>;

CATPAQ_RANS_INLINE Float4 to_float4(const Coord& c) { return {float(c[0]), float(c[1]), float(c[2]), 0.0f}; }

// One triangle's cross product (e1 x e2, e1 = s[j] - s[i], e2 = s[k] - s[i]) added to its three
// corners' sums, in this order.
CATPAQ_RANS_INLINE void accumulate_triangle_f(const uint32_t* tri, const Float4* s, Float4* acc) {
    const uint32_t i = tri[0], j = tri[1], k = tri[2];
#if defined(__SSE2__)
    const __m128 si = _mm_loadu_ps(s[i].data());
    const __m128 e1 = _mm_sub_ps(_mm_loadu_ps(s[j].data()), si), e2 = _mm_sub_ps(_mm_loadu_ps(s[k].data()), si);
    // (e1y e2z - e1z e2y, e1z e2x - e1x e2z, e1x e2y - e1y e2x, 0)
    const __m128 a = _mm_shuffle_ps(e1, e1, _MM_SHUFFLE(3, 0, 2, 1)), b = _mm_shuffle_ps(e2, e2, _MM_SHUFFLE(3, 1, 0, 2));
    const __m128 c = _mm_shuffle_ps(e1, e1, _MM_SHUFFLE(3, 1, 0, 2)), d = _mm_shuffle_ps(e2, e2, _MM_SHUFFLE(3, 0, 2, 1));
    const __m128 n = _mm_sub_ps(_mm_mul_ps(a, b), _mm_mul_ps(c, d));
    for (uint32_t v : {i, j, k}) _mm_storeu_ps(acc[v].data(), _mm_add_ps(_mm_loadu_ps(acc[v].data()), n));
#else
    const Float4 si = s[i], sj = s[j], sk = s[k];
    const float e1x = sj[0] - si[0], e1y = sj[1] - si[1], e1z = sj[2] - si[2];
    const float e2x = sk[0] - si[0], e2y = sk[1] - si[1], e2z = sk[2] - si[2];
    const float nx = e1y * e2z - e1z * e2y, ny = e1z * e2x - e1x * e2z, nz = e1x * e2y - e1y * e2x;
    for (uint32_t v : {i, j, k}) {
        acc[v][0] += nx;
        acc[v][1] += ny;
        acc[v][2] += nz;
    }
#endif
}

// No prediction (a zero sum): the vertex takes the previous vertex's normal. Never a predicted
// value, which is clamped to [-127, 127].
constexpr int8_t kNoPrediction = -128;

// The projection of one sum (the reference the vector form below follows operation by
// operation): (u, v) or kNoPrediction in both.
CATPAQ_RANS_INLINE void predict_normal_f(const Float4& n, const std::array<int8_t, 9>& m, int8_t* uv) {
    const float x = (float(m[0]) * n[0] + float(m[1]) * n[1]) + float(m[2]) * n[2];
    const float y = (float(m[3]) * n[0] + float(m[4]) * n[1]) + float(m[5]) * n[2];
    const float z = (float(m[6]) * n[0] + float(m[7]) * n[1]) + float(m[8]) * n[2];
    const float l1 = (std::fabs(x) + std::fabs(y)) + std::fabs(z);
    if (!(l1 > 0.0f)) {
        uv[0] = uv[1] = kNoPrediction;
        return;
    }
    const float sc = 127.0f / l1;
    float u = x * sc, v = y * sc;
    if (z < 0.0f) {
        // Folded, the sign of zero taken as positive (negating is exact).
        const float fu = u < 0.0f ? -(127.0f - std::fabs(v)) : 127.0f - std::fabs(v);
        const float fv = v < 0.0f ? -(127.0f - std::fabs(u)) : 127.0f - std::fabs(u);
        u = fu;
        v = fv;
    }
    // Round half up: |u|, |v| <= 127, so u + 128.5 > 0 and truncation is floor.
    uv[0] = int8_t(std::clamp(int(u + 128.5f) - 128, -127, 127));
    uv[1] = int8_t(std::clamp(int(v + 128.5f) - 128, -127, 127));
}

#if defined(__SSE2__)
// predict_normal_f of four vertices at once, lane by lane the same operations.
struct NormalPredictor4 {
    __m128 m0, m1, m2, m3, m4, m5, m6, m7, m8;
    explicit NormalPredictor4(const std::array<int8_t, 9>& m)
        : m0(_mm_set1_ps(m[0])), m1(_mm_set1_ps(m[1])), m2(_mm_set1_ps(m[2])), m3(_mm_set1_ps(m[3])),
          m4(_mm_set1_ps(m[4])), m5(_mm_set1_ps(m[5])), m6(_mm_set1_ps(m[6])), m7(_mm_set1_ps(m[7])),
          m8(_mm_set1_ps(m[8])) {}
    // The predictions of acc[0..3] into uv[0..7].
    CATPAQ_RANS_INLINE void predict(const Float4* acc, int8_t* uv) const;
};

CATPAQ_RANS_INLINE void NormalPredictor4::predict(const Float4* acc, int8_t* uv) const {
    const __m128 sign = _mm_set1_ps(-0.0f), zero = _mm_setzero_ps(), c127 = _mm_set1_ps(127.0f);
    {
        __m128 n0 = _mm_loadu_ps(acc[0].data()), n1 = _mm_loadu_ps(acc[1].data());
        __m128 n2 = _mm_loadu_ps(acc[2].data()), n3 = _mm_loadu_ps(acc[3].data());
        _MM_TRANSPOSE4_PS(n0, n1, n2, n3);  // n0: the four x, n1: y, n2: z
        const __m128 x = _mm_add_ps(_mm_add_ps(_mm_mul_ps(m0, n0), _mm_mul_ps(m1, n1)), _mm_mul_ps(m2, n2));
        const __m128 y = _mm_add_ps(_mm_add_ps(_mm_mul_ps(m3, n0), _mm_mul_ps(m4, n1)), _mm_mul_ps(m5, n2));
        const __m128 z = _mm_add_ps(_mm_add_ps(_mm_mul_ps(m6, n0), _mm_mul_ps(m7, n1)), _mm_mul_ps(m8, n2));
        const __m128 l1 = _mm_add_ps(_mm_add_ps(_mm_andnot_ps(sign, x), _mm_andnot_ps(sign, y)), _mm_andnot_ps(sign, z));
        const __m128 valid = _mm_cmpgt_ps(l1, zero);
        // Lanes without a valid sum divide by zero (or NaN) harmlessly: they are replaced below.
        const __m128 sc = _mm_div_ps(c127, l1);
        const __m128 u = _mm_mul_ps(x, sc), w = _mm_mul_ps(y, sc);
        const __m128 fu = _mm_xor_ps(_mm_sub_ps(c127, _mm_andnot_ps(sign, w)), _mm_and_ps(_mm_cmplt_ps(u, zero), sign));
        const __m128 fw = _mm_xor_ps(_mm_sub_ps(c127, _mm_andnot_ps(sign, u)), _mm_and_ps(_mm_cmplt_ps(w, zero), sign));
        const __m128 fold = _mm_cmplt_ps(z, zero);
        const __m128 ru = _mm_or_ps(_mm_and_ps(fold, fu), _mm_andnot_ps(fold, u));
        const __m128 rw = _mm_or_ps(_mm_and_ps(fold, fw), _mm_andnot_ps(fold, w));
        const __m128 half = _mm_set1_ps(128.5f);
        // Invalid lanes may hold anything: zeroed before the conversion, marked after.
        const __m128i iu = _mm_cvttps_epi32(_mm_and_ps(valid, _mm_add_ps(ru, half)));
        const __m128i iw = _mm_cvttps_epi32(_mm_and_ps(valid, _mm_add_ps(rw, half)));
        // (u0, v0, u1, v1, ...) - 128, clamped to [-127, 127], kNoPrediction where invalid.
        __m128i p = _mm_sub_epi16(_mm_packs_epi32(_mm_unpacklo_epi32(iu, iw), _mm_unpackhi_epi32(iu, iw)),
                                  _mm_set1_epi16(128));
        p = _mm_min_epi16(_mm_max_epi16(p, _mm_set1_epi16(-127)), _mm_set1_epi16(127));
        const __m128i ok = _mm_castps_si128(valid);
        const __m128i ok16 = _mm_packs_epi32(_mm_unpacklo_epi32(ok, ok), _mm_unpackhi_epi32(ok, ok));
        p = _mm_or_si128(_mm_and_si128(ok16, p), _mm_andnot_si128(ok16, _mm_set1_epi16(kNoPrediction)));
        _mm_storel_epi64(reinterpret_cast<__m128i*>(uv), _mm_packs_epi16(p, p));
    }
}
#endif

// Predictions of vertices [0, V) into uv (two per vertex), four at a time like the decoder
// (decode_geometric_normals_f), so that both run the very same code on every target. acc needs V
// rounded up to a multiple of 4 readable entries.
void predict_normals_f(const Float4* acc, uint32_t V, const std::array<int8_t, 9>& m, int8_t* uv) {
#if defined(__SSE2__)
    const NormalPredictor4 p4(m);
#endif
    for (uint32_t v = 0; v < V; v += 4) {
        int8_t block[8];
#if defined(__SSE2__)
        p4.predict(acc + v, block);
#else
        for (uint32_t k = 0; k < 4; ++k) predict_normal_f(acc[v + k], m, block + 2 * k);
#endif
        std::memcpy(uv + 2 * size_t(v), block, 2 * size_t(std::min(4u, V - v)));
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

// The colour channels of a layout in word1 (r = 0, g = 1, b = 2): `bits` each from bit `shift`;
// residuals wrap modulo 2^bits.
struct ColorField {
    int shift = 8, bits = 8;
    int top = 255;  // largest channel value
    explicit ColorField(const VertexLayout& layout)
        : shift(layout.color_shift() - 16), bits(layout.color_bits()), top((1 << layout.color_bits()) - 1) {}
    CATPAQ_RANS_INLINE int get(uint32_t word1, int c) const { return int((word1 >> (shift + bits * c)) & uint32_t(top)); }
    // A residual as the signed value in [-2^(bits-1), 2^(bits-1)) it is congruent to.
    CATPAQ_RANS_INLINE int32_t wrap(int32_t r) const {
        const int32_t half = (top + 1) >> 1;
        return ((r & top) ^ half) - half;
    }
};

// ---------------------------------------------------------------------------------------------
// Encoder
//
// The connectivity traversal collects its symbols first (ConnSymbols). The attribute coding
// modes are chosen by trial: each candidate's residuals are counted and, for positions and
// normals, kept as 16-bit values (Candidate); only the cheapest candidate goes into the rANS
// encoder (put_values; colours, only counted, are recomputed: Emitter). Keeping every
// candidate's full symbol records (12 bytes per value) instead, and copying them, was 18% of
// encode_bench's profile (bench/codec), before page faults.

// Connectivity symbols and raw bits in decode order (rANS symbols and raw bits go to separate
// streams, so their relative order does not matter).
struct ConnSymbols {
    struct Bits {
        uint32_t value, nbits;
    };
    std::vector<uint8_t> symbols;  // symbol k is coded on lane k & 3
    std::vector<Bits> bits;
    std::array<uint32_t, rans::kMaxAlphabet> counts{};

    void clear() {
        symbols.clear();
        bits.clear();
        counts.fill(0);
    }
    void put_bits(uint32_t v, int n) {
        if (n > 0) bits.push_back({v, uint32_t(n)});
    }
};

// One candidate coding of a part (positions, normals or colours): its symbol counts and raw bits
// and, when recorded, its residual values in decode order (per vertex one value of each of the
// part's streams), kept so that the chosen candidate is not computed twice (the geometric normal
// prediction is not cheap). cost() also derives the tables that would code them.
struct Candidate {
    static constexpr int kMaxStreams = 3;
    int first = 0;  // counts[k] belongs to stream first + k
    std::array<std::array<uint32_t, rans::kMaxAlphabet>, kMaxStreams> counts{};
    size_t raw_bits = 0;
    std::vector<uint16_t> values;  // residuals are below 2 * grid <= 2 * kMaxWideGrid
    size_t size = 0;
    std::array<rans::TableDesc, kMaxStreams> desc{};
    std::array<rans::FreqTable, kMaxStreams> freqs{};

    // Hot-loop view of a candidate: plain values that the compiler keeps in registers (through
    // the members, it reloaded them after every store).
    struct Recorder {
        uint32_t* counts;  // of stream `first`; stream s at counts + (s - first) * kMaxAlphabet
        int first;
        uint16_t* out;
        CATPAQ_RANS_INLINE void value(int stream, uint32_t z) {
            ++counts[size_t(stream - first) * rans::kMaxAlphabet + bucket_of(z).sym];
            *out++ = uint16_t(z);
        }
    };

    // Zero counts for streams from first_stream, no values.
    void clear(int first_stream) {
        first = first_stream;
        for (auto& c : counts) c.fill(0);
        size = 0;
    }
    // Counts and records up to value_count values with `fill(recorder)`.
    template <class Fill>
    void record(int first_stream, size_t value_count, Fill&& fill) {
        clear(first_stream);
        if (values.size() < value_count) values.resize(value_count);
        Recorder r{counts[0].data(), first, values.data()};
        fill(r);
        size = size_t(r.out - values.data());
        assert(size <= value_count);
        count_raw_bits();
    }
    // The extra bits follow from the symbols.
    void count_raw_bits() {
        raw_bits = 0;
        for (const auto& c : counts)
            for (size_t sym = 0; sym < c.size(); ++sym) raw_bits += size_t(c[sym]) * (kBucketDecode.packed[sym] & 0xff);
    }
    // Estimated coded size of `streams` streams: raw bits, then per stream symbols plus table
    // (this summation order decides near-ties between modes, so it is part of the behaviour).
    double cost(int streams) {
        double bits_total = double(raw_bits);
        for (int k = 0; k < streams; ++k) {
            double data_bits = 0;
            desc[size_t(k)] =
                rans::describe_counts(counts[size_t(k)].data(), rans::kMaxAlphabet, &freqs[size_t(k)], &data_bits);
            bits_total += data_bits + rans::table_cost_bits(desc[size_t(k)]);
        }
        return bits_total;
    }
};
static_assert(2 * kMaxWideGrid < 65536, "position residuals must fit the 16-bit values");
static_assert(2 * kMaxWideGrid < (1 << 15), "residual symbols must fit the alphabet (kMaxExtraBits)");

// Puts a candidate's values into the encoder: per vertex one value of each of the N streams in
// `order` (the decode order), each a symbol on its stream's lane plus its extra bits.
template <int N>
void put_values(rans::Encoder& enc, const Candidate& c, const std::array<rans::EncTable, kStreamCount>& tables,
                const std::array<int, N>& order) {
    const rans::EncTable* t[N];
    int lane[N];
    for (int j = 0; j < N; ++j) {
        t[j] = &tables[size_t(order[size_t(j)])];
        lane[j] = kStreamLane[order[size_t(j)]];
    }
    const uint16_t* z = c.values.data();
    for (size_t i = 0; i + N <= c.size; i += N) {
        for (int j = 0; j < N; ++j) {
            const Bucket b = bucket_of(z[i + size_t(j)]);
            enc.put(*t[j], b.sym, lane[j]);
            enc.put_bits(b.extra, int(b.nbits));
        }
    }
}

// Puts residual values straight into the encoder (for a candidate that was only counted).
struct Emitter {
    rans::Encoder& enc;
    const std::array<rans::EncTable, kStreamCount>& tables;
    CATPAQ_RANS_INLINE void value(int stream, uint32_t z) {
        const Bucket b = bucket_of(z);
        enc.put(tables[size_t(stream)], b.sym, kStreamLane[stream]);
        enc.put_bits(b.extra, int(b.nbits));
    }
};

// Version 2's joint colour coding of the values z (G, R, B per vertex): V joint symbols (vertex
// v's on lane v & 3), then the escaped vertices' values on their streams' lanes.
void put_joint_colors(rans::Encoder& enc, const uint16_t* z, uint32_t V,
                      const std::array<rans::EncTable, kStreamCount>& tables) {
    for (uint32_t v = 0; v < V; ++v)
        enc.put(tables[kStreamColJoint], joint_symbol(z[3 * v], z[3 * v + 1], z[3 * v + 2]), int(v & 3));
    Emitter escapes{enc, tables};
    for (uint32_t v = 0; v < V; ++v) {
        const uint16_t* x = z + 3 * size_t(v);
        if (joint_symbol(x[0], x[1], x[2]) != kJointEscape) continue;
        escapes.value(kStreamColG, x[0]);
        escapes.value(kStreamColR, x[1]);
        escapes.value(kStreamColB, x[2]);
    }
}

// The mesh in coding order.
struct EncoderState {
    VertexLayout layout;
    int version = kFragmentVersion;
    uint32_t V = 0;
    const PackedVertex* verts = nullptr;  // new order, plus the virtual zero vertex at V
    const Pred* pred = nullptr;           // per new vertex
};

// Position residuals. q: coordinates in the coding space (cumulative (a, b, c), or weights
// (w1, w2, w3)), index V the virtual zero vertex.
template <bool kCumulative, class Out>
void emit_positions(const EncoderState& st, const Coord* q, Out& out) {
    const int32_t kGrid = st.layout.grid;
    for (uint32_t v = 0; v < st.V; ++v) {
        const Pred p = st.pred[v];
        const Coord x = q[v], A = q[p.a], B = q[p.b], C = q[p.c];
        const int32_t hi1 = kCumulative ? x[0] : kGrid - x[0];
        const int32_t hi2 = kCumulative ? x[1] : kGrid - x[0] - x[1];
        const int32_t p0 = std::clamp(A[0] + B[0] - C[0], 0, kGrid);
        const int32_t p1 = std::clamp(A[1] + B[1] - C[1], 0, hi1);
        const int32_t p2 = std::clamp(A[2] + B[2] - C[2], 0, hi2);
        out.value(kStreamPos0, zigzag(x[0] - p0));
        out.value(kStreamPos1, zigzag(x[1] - p1));
        out.value(kStreamPos2, zigzag(x[2] - p2));
    }
}

inline int normal_u(const PackedVertex& v) { return int8_t(uint8_t(v.word0 >> 24)); }
inline int normal_v(const PackedVertex& v) { return int8_t(uint8_t(v.word1)); }
inline uint32_t wrap_residual(int actual, int pred) { return zigzag(int32_t(int8_t(uint8_t(actual - pred)))); }

// Normal residuals under predictor kMode (geometric: the predictions `guv`, two per vertex,
// kNoPrediction for the previous vertex's normal).
template <int kMode, class Out>
void emit_normals(const EncoderState& st, const int8_t* guv, Out& out) {
    const PackedVertex* verts = st.verts;
    for (uint32_t v = 0; v < st.V; ++v) {
        const Pred p = st.pred[v];
        int pu, pv;
        if constexpr (kMode == kNormalGeometric) {
            const PackedVertex& prev = verts[v == 0 ? st.V : v - 1];
            const bool none = guv[2 * size_t(v)] == kNoPrediction;
            pu = none ? normal_u(prev) : guv[2 * size_t(v)];
            pv = none ? normal_v(prev) : guv[2 * size_t(v) + 1];
        } else if constexpr (kMode == kNormalAverage) {
            pu = (normal_u(verts[p.a]) + normal_u(verts[p.b])) >> 1;
            pv = (normal_v(verts[p.a]) + normal_v(verts[p.b])) >> 1;
        } else {
            pu = std::clamp(normal_u(verts[p.a]) + normal_u(verts[p.b]) - normal_u(verts[p.c]), -127, 127);
            pv = std::clamp(normal_v(verts[p.a]) + normal_v(verts[p.b]) - normal_v(verts[p.c]), -127, 127);
        }
        out.value(kStreamNormU, wrap_residual(normal_u(verts[v]), pu));
        out.value(kStreamNormV, wrap_residual(normal_v(verts[v]), pv));
    }
}

// Colour residuals: G, then R and B (relative to G's residual when kDecorrelate).
template <bool kParallelogram, bool kDecorrelate, class Out>
void emit_colors(const EncoderState& st, Out& out) {
    const PackedVertex* verts = st.verts;
    const ColorField f(st.layout);
    for (uint32_t v = 0; v < st.V; ++v) {
        const Pred p = st.pred[v];
        const uint32_t wa = verts[p.a].word1, wb = verts[p.b].word1, wc = verts[p.c].word1, wv = verts[v].word1;
        int r[3];
        for (int c = 0; c < 3; ++c) {
            const int a = f.get(wa, c), b = f.get(wb, c);
            const int pc = kParallelogram ? std::clamp(a + b - f.get(wc, c), 0, f.top) : (a + b + 1) >> 1;
            r[c] = f.get(wv, c) - pc;
        }
        if constexpr (kDecorrelate) {
            r[0] -= r[1];
            r[2] -= r[1];
        }
        out.value(kStreamColG, zigzag(f.wrap(r[1])));
        out.value(kStreamColR, zigzag(f.wrap(r[0])));
        out.value(kStreamColB, zigzag(f.wrap(r[2])));
    }
}

template <class Out>
void emit_normals(const EncoderState& st, int mode, const int8_t* guv, Out& out) {
    if (mode == kNormalGeometric)
        emit_normals<kNormalGeometric>(st, guv, out);
    else if (mode == kNormalAverage)
        emit_normals<kNormalAverage>(st, guv, out);
    else
        emit_normals<kNormalParallelogram>(st, guv, out);
}

template <class Out>
void emit_colors(const EncoderState& st, bool parallelogram, bool decorrelate, Out& out) {
    if (parallelogram)
        decorrelate ? emit_colors<true, true>(st, out) : emit_colors<true, false>(st, out);
    else
        decorrelate ? emit_colors<false, true>(st, out) : emit_colors<false, false>(st, out);
}

// Fits M (normals ~ M * geometric normal) by least squares over unit vectors; false if
// degenerate.
template <class Sum>
bool fit_normal_matrix(const EncoderState& st, const Sum* acc, std::array<int8_t, 9>& m) {
    // Sums over the vertices of g[i][j] = n[i] n[j] (upper half; the lower half mirrors it)
    // and h[i][j] = t[i] n[j], t the vertex's decoded normal, in pairs of doubles: each lane
    // does exactly the scalar multiply and add in the same vertex order, so the sums are the
    // same bits, with half the instructions (the scalar loop spilled its 15 accumulators;
    // fit_normal_matrix was a third of choose_normals in perf; encode_bench 2% faster).
    using Double2 = double __attribute__((vector_size(16)));
    Double2 g00_01 = {0, 0}, g02_12 = {0, 0}, g11_22 = {0, 0};
    Double2 h0_01 = {0, 0}, h1_01 = {0, 0}, h2_01 = {0, 0}, h01_2 = {0, 0};  // h[i][0..1]; h[0..1][2]
    double h22 = 0;
    size_t used = 0;
    for (uint32_t v = 0; v < st.V; ++v) {
        const double x = double(acc[v][0]), y = double(acc[v][1]), z = double(acc[v][2]);
        const double len = std::sqrt(x * x + y * y + z * z);
        if (!(len > 0.0)) continue;
        const Double2 n01 = Double2{x, y} / len;
        const double n2 = z / len;
        float t[3];
        oct_decode(st.verts[v].normal(), t);
        const double t0 = double(t[0]), t1 = double(t[1]), t2 = double(t[2]);
        g00_01 += n01[0] * n01;
        g02_12 += n01 * n2;
        g11_22 += Double2{n01[1], n2} * Double2{n01[1], n2};
        h0_01 += t0 * n01;
        h1_01 += t1 * n01;
        h2_01 += t2 * n01;
        h01_2 += Double2{t0, t1} * n2;
        h22 += t2 * n2;
        ++used;
    }
    // n[i] * n[j] and n[j] * n[i] round alike, so the mirrored sums are the ones summed directly.
    const double g[3][3] = {{g00_01[0], g00_01[1], g02_12[0]},
                            {g00_01[1], g11_22[0], g02_12[1]},
                            {g02_12[0], g02_12[1], g11_22[1]}};
    const double h[3][3] = {{h0_01[0], h0_01[1], h01_2[0]}, {h1_01[0], h1_01[1], h01_2[1]}, {h2_01[0], h2_01[1], h22}};
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

// Scratch memory of the encoder, kept per thread between calls like the decoder's Workspace
// (fresh memory costs a page fault per 4 KiB page, about 13 us each on the build machine, and
// one encode used some 30 vectors). Fragments above kEncodeKeepVertices use a temporary one.
struct EncoderWorkspace {
    std::vector<uint32_t> regular, degenerate;  // triangle ids
    std::vector<uint32_t> first, fill, cursor;  // half-edge CSR
    std::vector<uint32_t> half_to, half_tri;       // target and triangle of each half-edge
    std::vector<std::pair<uint32_t, uint32_t>> group;  // scratch for sorting a large group
    std::vector<uint8_t> visited;
    std::vector<uint32_t> new_id, old_of_new, indices;
    std::vector<Pred> pred;
    std::vector<PackedVertex> verts;
    std::vector<Coord> coords, weights;
    std::vector<NormalSum> acc;  // version 1
    std::vector<Float4> fcoords, facc;  // version 2
    std::vector<int8_t> guv;  // geometric predictions
    std::array<Candidate, 2> pos;  // cumulative, weights
    std::array<Candidate, 3> nor;  // by NormalMode
    std::array<Candidate, 4> col;  // bit 0 parallelogram, bit 1 decorrelate
    Candidate col_escapes;         // joint colour coding: the escaped vertices' values
    std::vector<uint16_t> col_values;  // the chosen colour candidate's values, G R B per vertex
    rans::TableDesc joint_desc;
    rans::FreqTable joint_freqs;
    Front front;
    ConnSymbols conn;
    rans::Encoder enc;
    std::vector<size_t> section_bytes;
};
constexpr size_t kEncodeKeepVertices = size_t(1) << 16;

// The triangle of the first half-edge h in [lo, hi) with half_to[h] == to whose triangle is not
// visited, or kNone. Four targets per comparison (half_to has three readable entries past hi):
// the scalar loop's exit, at an unpredictable entry, was mispredicted about once per lookup.
CATPAQ_RANS_INLINE uint32_t first_unvisited(const uint32_t* half_to, const uint32_t* half_tri, const uint8_t* visited,
                                            uint32_t lo, uint32_t hi, uint32_t to) {
#if defined(__SSE2__)
    const __m128i key = _mm_set1_epi32(int32_t(to));
    for (uint32_t h = lo; h < hi; h += 4) {
        const __m128i targets = _mm_loadu_si128(reinterpret_cast<const __m128i*>(half_to + h));
        uint32_t match = uint32_t(_mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(targets, key))));
        if (hi - h < 4) match &= (1u << (hi - h)) - 1;
        for (; match != 0; match &= match - 1) {
            const uint32_t t = half_tri[h + uint32_t(__builtin_ctz(match))];
            if (!visited[t]) return t;
        }
    }
#else
    for (uint32_t h = lo; h < hi; ++h)
        if (half_to[h] == to && !visited[half_tri[h]]) return half_tri[h];
#endif
    return kNone;
}

// Adds the histogram of symbols[0, n) (each < kConnSymbols) to counts. Four partial
// histograms: with one, runs of the same symbol (NEW follows NEW most of the time) made every
// increment wait for the previous one's store (4.5% of encode_connectivity, in perf).
void count_symbols(const uint8_t* symbols, uint32_t n, uint32_t* counts) {
    uint32_t part[4][kConnSymbols] = {};
    uint32_t k = 0;
    for (; k + 4 <= n; k += 4)
        for (int j = 0; j < 4; ++j) ++part[j][symbols[k + uint32_t(j)]];
    for (; k < n; ++k) ++part[0][symbols[k]];
    for (uint32_t s = 0; s < kConnSymbols; ++s) counts[s] += part[0][s] + part[1][s] + part[2][s] + part[3][s];
}

// Connectivity traversal (see the top of this file): fills ws.conn, ws.pred, ws.old_of_new and
// ws.indices (new numbering, regular triangles then degenerate ones) and ws.degenerate.
void encode_connectivity(const FragmentMesh& mesh, EncoderWorkspace& ws) {
    const uint32_t V = uint32_t(mesh.vertices.size()), T = uint32_t(mesh.triangle_count());
    const uint32_t* idx = mesh.indices.data();

    // Split regular and degenerate triangles.
    std::vector<uint32_t>& regular = ws.regular;
    std::vector<uint32_t>& degenerate = ws.degenerate;
    regular.clear();
    degenerate.clear();
    // Every index must be below V (asserted here rather than in a pass of its own over the
    // indices, which was 1.6% of encode_bench's profile). The degrees of the half-edge CSR below
    // are counted in the same pass (a pass of its own over the regular triangles' indices was
    // 3.5% of encode_connectivity, in perf).
    std::vector<uint32_t>& first = ws.first;
    first.assign(size_t(V) + 1, 0);
    uint32_t* const degree = first.data() + 1;  // first[v + 1] counts v's half-edges for now
    for (uint32_t t = 0; t < T; ++t) {
        uint32_t a = idx[3 * t], b = idx[3 * t + 1], c = idx[3 * t + 2];
        assert(a < V && b < V && c < V);
        if (a == b || b == c || c == a) [[unlikely]] {
            degenerate.push_back(t);
            continue;
        }
        regular.push_back(t);
        ++degree[a], ++degree[b], ++degree[c];
    }
    const uint32_t R = uint32_t(regular.size());

    // Directed half-edges of regular triangles by origin vertex (CSR): target and triangle, in
    // triangle order. A lookup wants the first unvisited triangle with a given directed edge.
    // Vertices of degree up to kScanDegree (nearly all) are scanned linearly, four targets per
    // SSE2 comparison. Larger groups are sorted by (target, triangle): a lookup binary-searches
    // the target and scans that group from a cursor that skips visited triangles, so even
    // pathological fans and stacks of duplicate triangles cost O(log degree) amortised per
    // lookup. (Sorting every vertex's entries and binary-searching them were the traversal's
    // hottest spots, in perf.)
    constexpr uint32_t kScanDegree = 16;
    for (uint32_t v = 0; v < V; ++v) first[v + 1] += first[v];
    const uint32_t H = first[V];
    // Three entries of slack: the scan reads whole groups of four.
    ws.half_to.resize(size_t(H) + 3);
    ws.half_tri.resize(size_t(H) + 3);
    uint32_t* const half_to = ws.half_to.data();
    uint32_t* const half_tri = ws.half_tri.data();
    std::vector<uint32_t>& cursor = ws.cursor;  // at a sorted group's first entry: where to resume
    cursor.resize(H);
    {
        ws.fill.assign(first.begin(), first.begin() + V);
        uint32_t* fill = ws.fill.data();
        for (uint32_t t : regular)
            for (int k = 0; k < 3; ++k) {
                const uint32_t h = fill[idx[3 * t + k]]++;
                half_to[h] = idx[3 * t + (k + 1) % 3];
                half_tri[h] = t;
            }
        for (uint32_t v = 0; v < V; ++v) {
            if (first[v + 1] - first[v] <= kScanDegree) continue;
            std::vector<std::pair<uint32_t, uint32_t>>& group = ws.group;
            group.clear();
            for (uint32_t h = first[v]; h < first[v + 1]; ++h) group.push_back({half_to[h], half_tri[h]});
            std::sort(group.begin(), group.end());
            for (uint32_t h = first[v]; h < first[v + 1]; ++h) {
                half_to[h] = group[h - first[v]].first;
                half_tri[h] = group[h - first[v]].second;
                cursor[h] = h;
            }
        }
    }
    std::vector<uint8_t>& visited = ws.visited;
    visited.assign(T, 0);
    auto find_across = [&](uint32_t from, uint32_t to) -> uint32_t {
        const uint32_t lo = first[from], hi = first[from + 1];
        if (hi - lo <= kScanDegree) [[likely]]
            return first_unvisited(half_to, half_tri, visited.data(), lo, hi, to);
        const uint32_t g = uint32_t(std::lower_bound(half_to + lo, half_to + hi, to) - half_to);
        if (g == hi || half_to[g] != to) return kNone;
        uint32_t h = cursor[g];
        while (h < hi && half_to[h] == to && visited[half_tri[h]]) ++h;
        cursor[g] = h;
        if (h < hi && half_to[h] == to) return half_tri[h];
        return kNone;
    };

    // Outputs are sized up front and written through pointers: push_back's capacity checks, and
    // the reloads of vector internals after every byte store, cost 6% of encode_bench's time.
    ws.new_id.assign(V, kNone);
    ws.old_of_new.resize(V);
    ws.pred.resize(V);
    ws.indices.resize(size_t(T) * 3);
    // Every triangle takes one symbol (three to start a component), every BOUNDARY one of the
    // at most 3 R front edges: at most 6 R symbols (the decoder's bound).
    ws.conn.clear();
    ws.conn.symbols.resize(6 * size_t(R));
    uint32_t* const new_id = ws.new_id.data();
    uint32_t* const old_of_new = ws.old_of_new.data();
    Pred* const pred = ws.pred.data();
    uint32_t* tri = ws.indices.data();
    uint8_t* const symbols = ws.conn.symbols.data();
    uint32_t nsym = 0, seen = 0;
    auto number = [&](uint32_t old, Pred p) {
        new_id[old] = seen;
        old_of_new[seen] = old;
        pred[seen] = p;
        ++seen;
    };
    auto previous_pred = [&]() {
        uint32_t p = seen == 0 ? V : seen - 1;
        return Pred{p, p, p};
    };
    auto put_split = [&](uint32_t old) {
        symbols[nsym++] = kSplit;
        ws.conn.put_bits(new_id[old], bit_width_u32(seen - 1));
    };

    Front& front = ws.front;
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
                    symbols[nsym++] = kNew;
                    number(x, previous_pred());
                } else {
                    put_split(x);
                }
            }
            front.start(c[0], c[1], c[2]);
            for (uint32_t x : c) *tri++ = new_id[x];
            ++done;
            continue;
        }
        const FrontEdge ei = front.e[i];
        uint32_t t = find_across(ei.v1, ei.v0);
        if (t == kNone) {
            symbols[nsym++] = kBoundary;
            continue;
        }
        visited[t] = 1;
        ++done;
        uint32_t w = idx[3 * t] ^ idx[3 * t + 1] ^ idx[3 * t + 2] ^ ei.v0 ^ ei.v1;
        if (new_id[w] == kNone) {
            symbols[nsym++] = kNew;
            number(w, Pred{new_id[ei.v0], new_id[ei.v1], new_id[ei.opp]});
            front.add_vertex(i, ei, w);
        } else {
            bool left = front.e[ei.next].v1 == w, right = front.e[ei.prev].v0 == w;
            if (left && right) {
                symbols[nsym++] = kEnd;
                front.end(i, ei);
            } else if (left) {
                symbols[nsym++] = kLeft;
                front.left(i, ei, w);
            } else if (right) {
                symbols[nsym++] = kRight;
                front.right(i, ei, w);
            } else {
                put_split(w);
                front.add_vertex(i, ei, w);
            }
        }
        tri[0] = new_id[ei.v1];
        tri[1] = new_id[ei.v0];
        tri[2] = new_id[w];
        tri += 3;
    }
    assert(nsym <= ws.conn.symbols.size());
    ws.conn.symbols.resize(nsym);
    count_symbols(symbols, nsym, ws.conn.counts.data());
    // Vertices outside regular triangles, in original order.
    for (uint32_t v = 0; v < V; ++v)
        if (new_id[v] == kNone) number(v, previous_pred());
    // Degenerate triangles, explicit.
    const int index_bits = V > 0 ? bit_width_u32(V - 1) : 0;
    for (uint32_t t : degenerate)
        for (int k = 0; k < 3; ++k) {
            uint32_t n = new_id[idx[3 * t + k]];
            ws.conn.put_bits(n, index_bits);
            *tri++ = n;
        }
    assert(tri == ws.indices.data() + ws.indices.size());
}

// The attribute modes chosen by trial and the chosen candidates (in the workspace).
struct AttributeChoice {
    int pos_mode = kPosRaw;
    int normal_mode = kNormalAverage;
    std::array<int8_t, 9> matrix{};
    bool color_parallelogram = false, color_decorrelate = false;
    bool color_joint = false;  // version 2: col holds the escapes' tables, ws.joint_* the joint table
    const Candidate *pos = nullptr, *nor = nullptr, *col = nullptr;
};

// Positions: fills ws.coords (cumulative (a, b, c), index V zero) and, when every index is valid,
// picks the cheaper of the cumulative and weight codings (else raw indices).
void choose_positions(const EncoderState& st, EncoderWorkspace& ws, AttributeChoice& choice) {
    const uint32_t V = st.V;
    ws.coords.resize(size_t(V) + 1);
    Coord* coords = ws.coords.data();
    coords[V] = Coord{0, 0, 0, 0};
    for (uint32_t v = 0; v < V; ++v) {
        BaryWeights w;
        if (!vertex_weights(st.verts[v], st.layout, w)) {
            choice.pos_mode = kPosRaw;
            return;
        }
        coords[v] = {w[1] + w[2] + w[3], w[2] + w[3], w[3], 0};
    }
    ws.weights.resize(size_t(V) + 1);
    Coord* weights = ws.weights.data();
    for (uint32_t v = 0; v <= V; ++v)
        weights[v] = {coords[v][0] - coords[v][1], coords[v][1] - coords[v][2], coords[v][2], 0};
    Candidate &cumulative = ws.pos[0], &by_weight = ws.pos[1];
    cumulative.record(kStreamPos0, 3 * size_t(V), [&](auto& r) { emit_positions<true>(st, coords, r); });
    by_weight.record(kStreamPos0, 3 * size_t(V), [&](auto& r) { emit_positions<false>(st, weights, r); });
    const double c0 = cumulative.cost(3), c1 = by_weight.cost(3);
    choice.pos_mode = c1 < c0 ? kPosWeights : kPosCumulative;
    choice.pos = c1 < c0 ? &by_weight : &cumulative;
}

// Normals: the cheapest of the gate average, the parallelogram and (when positions are coded and
// a matrix fits) the geometric predictor, which costs 72 bits more for its matrix.
void choose_normals(const EncoderState& st, EncoderWorkspace& ws, AttributeChoice& choice) {
    const uint32_t V = st.V;
    bool geometric = false;
    if (choice.pos_mode != kPosRaw && V > 0) {
        ws.guv.resize(2 * size_t(V));
        const size_t T = ws.indices.size() / 3;
        if (st.version >= 2) {
            ws.fcoords.resize(V);
            for (uint32_t v = 0; v < V; ++v) ws.fcoords[v] = to_float4(ws.coords[v]);
            ws.facc.assign((size_t(V) + 3) & ~size_t(3), Float4{});
            for (size_t t = 0; t < T; ++t) accumulate_triangle_f(ws.indices.data() + 3 * t, ws.fcoords.data(), ws.facc.data());
            geometric = fit_normal_matrix(st, ws.facc.data(), choice.matrix);
            if (geometric) predict_normals_f(ws.facc.data(), V, choice.matrix, ws.guv.data());
        } else {
            ws.acc.assign(V, NormalSum{0, 0, 0, 0});
            accumulate_normals(ws.indices.data(), T, ws.coords.data(), ws.acc.data());
            geometric = fit_normal_matrix(st, ws.acc.data(), choice.matrix);
            if (geometric)
                for (uint32_t v = 0; v < V; ++v) {
                    int pu = kNoPrediction, pv = kNoPrediction;
                    geometric_prediction(ws.acc[v], choice.matrix, kNoPrediction, kNoPrediction, pu, pv);
                    ws.guv[2 * size_t(v)] = int8_t(pu);
                    ws.guv[2 * size_t(v) + 1] = int8_t(pv);
                }
        }
    }
    double best = 1e300;
    for (int mode : {kNormalAverage, kNormalParallelogram, kNormalGeometric}) {
        if (mode == kNormalGeometric && !geometric) continue;
        Candidate& c = ws.nor[size_t(mode)];
        c.record(kStreamNormU, 2 * size_t(V),
                 [&](auto& r) { emit_normals(st, mode, ws.guv.data(), r); });
        const double bits = c.cost(2) + (mode == kNormalGeometric ? 72 : 0);
        if (bits < best) {
            best = bits;
            choice.normal_mode = mode;
            choice.nor = &c;
        }
    }
}

// The values a part's emit function produces, in order.
struct ValueRecorder {
    uint16_t* out;
    CATPAQ_RANS_INLINE void value(int, uint32_t z) { *out++ = uint16_t(z); }
};

// Version 2: the chosen colour prediction's values coded jointly (kJointEscape) unless that costs
// more than kJointColourAllowance times the `separate` bits. The allowance buys decoding speed:
// the 1M-triangle scan's dataset decoded 2% faster with the joint coding where it is the smaller
// (60% of the vertices) and 4% faster with it everywhere (all of its fragments are within 1.3x,
// and its colours still took 4% fewer bytes than separately coded). Noisy colours (mostly
// escapes, and then slower too: four symbols per escaped vertex, the last three on the decoder's
// checked path) keep the separate coding: the joint one needs at most a quarter of escapes.
constexpr double kJointColourAllowance = 1.25;
void choose_joint_colors(const EncoderState& st, EncoderWorkspace& ws, AttributeChoice& choice, double separate) {
    const uint32_t V = st.V;
    ws.col_values.resize(3 * size_t(V));
    ValueRecorder recorder{ws.col_values.data()};
    emit_colors(st, choice.color_parallelogram, choice.color_decorrelate, recorder);
    Candidate& esc = ws.col_escapes;
    esc.clear(kStreamColR);
    std::array<uint32_t, rans::kMaxAlphabet> joint{};
    uint32_t escapes = 0;
    const uint16_t* z = ws.col_values.data();
    for (uint32_t v = 0; v < V; ++v, z += 3) {
        const uint32_t j = joint_symbol(z[0], z[1], z[2]);
        ++joint[j];
        if (j == kJointEscape) {
            ++escapes;
            ++esc.counts[1][bucket_of(z[0]).sym];  // G
            ++esc.counts[0][bucket_of(z[1]).sym];  // R
            ++esc.counts[2][bucket_of(z[2]).sym];  // B
        }
    }
    esc.count_raw_bits();
    double joint_bits = 0;
    ws.joint_desc = rans::describe_counts(joint.data(), kJointSymbols, &ws.joint_freqs, &joint_bits);
    const double bits = esc.cost(3) + joint_bits + rans::table_cost_bits(ws.joint_desc);
    if (4 * uint64_t(escapes) <= V && bits < kJointColourAllowance * separate) {
        choice.color_joint = true;
        choice.col = &esc;
    }
}

// Colours: the cheapest of {gate average, parallelogram} x {plain, R and B relative to G}
// (candidate k: bit 0 parallelogram, bit 1 relative). The four are counted in one pass: they
// share the predictions, and the plain and relative codings share the G residual. The chosen
// one is emitted later, recomputed (cheap). Four recording passes took twice as long.
void choose_colors(const EncoderState& st, EncoderWorkspace& ws, AttributeChoice& choice) {
    for (Candidate& c : ws.col) c.clear(kStreamColR);
    // counts of candidate k, stream R, G or B (r = 0, g = 1, b = 2)
    auto counts = [&](int k, int channel) { return ws.col[size_t(k)].counts[size_t(channel)].data(); };
    uint32_t *g_avg = counts(0, 1), *r_avg = counts(0, 0), *b_avg = counts(0, 2);
    uint32_t *g_par = counts(1, 1), *r_par = counts(1, 0), *b_par = counts(1, 2);
    uint32_t *g_avg_rel = counts(2, 1), *r_avg_rel = counts(2, 0), *b_avg_rel = counts(2, 2);
    uint32_t *g_par_rel = counts(3, 1), *r_par_rel = counts(3, 0), *b_par_rel = counts(3, 2);
    const ColorField f(st.layout);
    auto sym = [&f](int residual) { return bucket_of(zigzag(f.wrap(residual))).sym; };
    const PackedVertex* verts = st.verts;
    for (uint32_t v = 0; v < st.V; ++v) {
        const Pred p = st.pred[v];
        const uint32_t wa = verts[p.a].word1, wb = verts[p.b].word1, wc = verts[p.c].word1, wv = verts[v].word1;
        int avg[3], par[3];  // residuals against the gate average and the parallelogram
        for (int c = 0; c < 3; ++c) {
            const int a = f.get(wa, c), b = f.get(wb, c), x = f.get(wv, c);
            avg[c] = x - ((a + b + 1) >> 1);
            par[c] = x - std::clamp(a + b - f.get(wc, c), 0, f.top);
        }
        const uint32_t ga = sym(avg[1]), gp = sym(par[1]);
        ++g_avg[ga], ++g_avg_rel[ga], ++g_par[gp], ++g_par_rel[gp];
        ++r_avg[sym(avg[0])], ++b_avg[sym(avg[2])];
        ++r_par[sym(par[0])], ++b_par[sym(par[2])];
        ++r_avg_rel[sym(avg[0] - avg[1])], ++b_avg_rel[sym(avg[2] - avg[1])];
        ++r_par_rel[sym(par[0] - par[1])], ++b_par_rel[sym(par[2] - par[1])];
    }
    double best = 1e300;
    for (int k = 0; k < 4; ++k) {
        Candidate& c = ws.col[size_t(k)];
        c.count_raw_bits();
        const double bits = c.cost(3);
        if (bits < best) {
            best = bits;
            choice.color_parallelogram = k & 1;
            choice.color_decorrelate = k & 2;
            choice.col = &c;
        }
    }
    if (st.version >= 2) choose_joint_colors(st, ws, choice, best);
}

// Encodes into `out` (appending); returns the bytes appended.
size_t encode_fragment(const FragmentMesh& mesh, std::vector<uint8_t>& out, FragmentEncodeStats* stats,
                       int version, EncoderWorkspace& ws) {
    const size_t V_size = mesh.vertices.size(), T_size = mesh.triangle_count();
    assert(mesh.indices.size() % 3 == 0);
    assert(V_size <= kFragmentMaxVertices && T_size <= kFragmentMaxTriangles);
    const uint32_t V = uint32_t(V_size), T = uint32_t(T_size);
    assert(mesh.layout.valid());
    const bool colors = mesh.layout.has_color();
    // Indices are checked (asserted) by encode_connectivity, which reads them all anyway.

    encode_connectivity(mesh, ws);
    ws.verts.resize(size_t(V) + 1);
    for (uint32_t v = 0; v < V; ++v) ws.verts[v] = mesh.vertices[ws.old_of_new[v]];
    ws.verts[V] = PackedVertex{};
    const EncoderState st{mesh.layout, version, V, ws.verts.data(), ws.pred.data()};

    AttributeChoice choice;
    choose_positions(st, ws, choice);
    choose_normals(st, ws, choice);
    if (colors) choose_colors(st, ws, choice);

    // Tables, then everything in decode order. Sections (for the size report): tables of each
    // part, then the symbols of each part.
    rans::Encoder& enc = ws.enc;
    enc.reset();
    std::array<rans::EncTable, kStreamCount> tables;
    const Candidate* parts[4] = {nullptr, choice.pos, choice.nor, choice.col};
    const int stream_part[kStreamCount] = {0, 1, 1, 1, 2, 2, 3, 3, 3, 3};
    int section_part[8];
    int sections = 0;
    for (int s = 0; s < kStreamCount; ++s) {
        if (stream_part[s] == 1 && choice.pos_mode == kPosRaw) continue;
        if (stream_part[s] == 3 && !colors) continue;
        if (s == kStreamColJoint && !choice.color_joint) continue;
        if (sections == 0 || section_part[sections - 1] != stream_part[s]) {
            enc.begin_section();
            section_part[sections++] = stream_part[s];
        }
        rans::TableDesc d;
        rans::FreqTable f;
        if (s == kStreamConn) {
            d = rans::describe_counts(ws.conn.counts.data(), int(kConnSymbols));
            bool ok = rans::build_freqs(d, f);
            assert(ok);
            (void)ok;
        } else if (s == kStreamColJoint) {
            d = ws.joint_desc;
            f = ws.joint_freqs;
        } else {
            // The part's cost() already described and built the table.
            const Candidate& p = *parts[stream_part[s]];
            d = p.desc[size_t(s - p.first)];
            f = p.freqs[size_t(s - p.first)];
        }
        tables[size_t(s)].build(f);
        enc.put_table(d);
    }
    // Connectivity.
    enc.begin_section();
    section_part[sections++] = 0;
    const rans::EncTable& conn_table = tables[kStreamConn];
    for (size_t k = 0; k < ws.conn.symbols.size(); ++k) enc.put(conn_table, ws.conn.symbols[k], int(k & 3));
    for (const ConnSymbols::Bits& b : ws.conn.bits) enc.put_bits(b.value, int(b.nbits));
    // Positions.
    enc.begin_section();
    section_part[sections++] = 1;
    if (choice.pos_mode == kPosRaw) {
        const int high_bits = mesh.layout.color_shift() - 24;  // position bits above the first 24
        for (uint32_t v = 0; v < V; ++v) {
            const uint64_t payload = st.verts[v].payload();
            enc.put_bits(uint32_t(payload & 0xffffff), 24);
            enc.put_bits(uint32_t(payload >> 24) & ((1u << high_bits) - 1), high_bits);
        }
    } else {
        put_values<3>(enc, *choice.pos, tables, {kStreamPos0, kStreamPos1, kStreamPos2});
    }
    // Normals.
    enc.begin_section();
    section_part[sections++] = 2;
    put_values<2>(enc, *choice.nor, tables, {kStreamNormU, kStreamNormV});
    // Colours.
    if (colors) {
        enc.begin_section();
        section_part[sections++] = 3;
        if (choice.color_joint) {
            put_joint_colors(enc, ws.col_values.data(), V, tables);
        } else {
            Emitter emitter{enc, tables};
            emit_colors(st, choice.color_parallelogram, choice.color_decorrelate, emitter);
        }
    }

    // Assemble: header, then the payload straight after it in `out`.
    const size_t base = out.size();
    out.resize(base + kHeaderBytes, 0);
    uint8_t* header = out.data() + base;
    std::memcpy(header, kMagicBytes, 4);
    header[4] = uint8_t(version);
    header[5] = uint8_t(mesh.layout.kind);
    const bool legacy_grid = mesh.layout.kind == VertexLayoutKind::Rgb24 && mesh.layout.grid == kBaryGrid;
    const uint16_t grid_field = legacy_grid ? 0 : uint16_t(mesh.layout.grid);
    header[6] = uint8_t(grid_field);
    header[7] = uint8_t(grid_field >> 8);
    for (int i = 0; i < 4; ++i) {
        header[8 + i] = uint8_t(V >> (8 * i));
        header[12 + i] = uint8_t(T >> (8 * i));
    }
    const size_t payload_at = out.size();
    put_u16(out, header_fold(out.data() + base));
    out.push_back(kCodingCompressed);
    out.push_back(uint8_t(choice.pos_mode | (choice.normal_mode << 2) | (choice.color_parallelogram << 4) |
                          (choice.color_decorrelate << 5) | (choice.color_joint << 6)));
    if (choice.normal_mode == kNormalGeometric)
        for (int8_t x : choice.matrix) out.push_back(uint8_t(x));
    put_varint(out, ws.degenerate.size());
    put_varint(out, ws.conn.symbols.size());
    const size_t prefix_bytes = out.size() - payload_at;
    std::vector<size_t>& section_bytes = ws.section_bytes;
    enc.finish(out, &section_bytes);

    FragmentEncodeStats s;
    const size_t stored_payload = 3 + 8 * size_t(V) + 12 * size_t(T);
    if (out.size() - payload_at >= stored_payload) {
        out.resize(payload_at + 2);
        out.push_back(kCodingStored);
        for (const PackedVertex& v : mesh.vertices) {
            put_u32(out, v.word0);
            put_u32(out, v.word1);
        }
        for (uint32_t i : mesh.indices) put_u32(out, i);
        s.header_bytes = kHeaderBytes + 3;
        s.connectivity_bytes = 12 * size_t(T);
        s.position_bytes = size_t(mesh.layout.color_shift()) * V / 8;
        s.normal_bytes = 2 * size_t(V);
        s.color_bytes = size_t(3 * mesh.layout.color_bits()) * V / 8;
    } else {
        s.header_bytes = kHeaderBytes + prefix_bytes - (choice.normal_mode == kNormalGeometric ? 9 : 0);
        s.normal_bytes = choice.normal_mode == kNormalGeometric ? 9 : 0;
        size_t* target[4] = {&s.connectivity_bytes, &s.position_bytes, &s.normal_bytes, &s.color_bytes};
        for (size_t i = 0; i < section_bytes.size(); ++i) *target[section_part[i]] += section_bytes[i];
    }
    const uint64_t sum = checksum64(out.data() + payload_at, out.size() - payload_at);
    header = out.data() + base;  // `out` may have moved
    for (int i = 0; i < 8; ++i) header[kChecksumOffset + size_t(i)] = uint8_t(sum >> (8 * i));
    if (stats) *stats = s;
    return out.size() - base;
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

size_t fragment_encode(const FragmentMesh& mesh, std::vector<uint8_t>& out, FragmentEncodeStats* stats, int version) {
    assert(version >= kFragmentOldestVersion && version <= kFragmentVersion);
    if (mesh.vertices.size() <= kEncodeKeepVertices) {
        thread_local EncoderWorkspace ws;
        return encode_fragment(mesh, out, stats, version, ws);
    }
    EncoderWorkspace ws;
    return encode_fragment(mesh, out, stats, version, ws);
}

FragmentStatus fragment_peek(const uint8_t* data, size_t size, uint32_t& vertex_count, uint32_t& triangle_count) {
    if (size < kHeaderBytes) return FragmentStatus::Truncated;
    if (std::memcmp(data, kMagicBytes, 4) != 0) return FragmentStatus::BadMagic;
    if (data[4] < kFragmentOldestVersion || data[4] > kFragmentVersion || data[5] > uint8_t(VertexLayoutKind::Rgb18)) return FragmentStatus::UnsupportedVersion;
    if (!fragment_layout(data).valid()) return FragmentStatus::Corrupt;
    vertex_count = read_u32(data + 8);
    triangle_count = read_u32(data + 12);
    if (vertex_count > kFragmentMaxVertices || triangle_count > kFragmentMaxTriangles) return FragmentStatus::TooLarge;
    return FragmentStatus::Ok;
}

VertexLayout fragment_layout(const uint8_t* data) {
    VertexLayout layout;
    layout.kind = VertexLayoutKind(data[5]);
    const uint16_t grid = read_u16(data + 6);
    // 0 is the first datasets' Rgb24 grid of 463; for Position48 it is invalid.
    layout.grid = grid != 0 ? int32_t(grid) : layout.kind == VertexLayoutKind::Rgb24 ? kBaryGrid : 0;
    return layout;
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

// Triangles decoded between two checks of the front's capacity.
constexpr uint32_t kFrontBlock = 4096;

// The decoder's front edge: FrontEdge with prev and next as byte offsets into the edge array
// (index * kEdgeBytes), so that following a link costs no address arithmetic.
struct DecEdge {
    uint32_t v0, v1, opp, prev, next;  // prev == kDead: consumed
};
constexpr uint32_t kEdgeBytes = sizeof(DecEdge);
static_assert(kEdgeBytes == 20 && uint64_t(3) * kFragmentMaxTriangles * kEdgeBytes < kDead);

// The fields of an edge, loaded one by one: the compiler merged them into one 16-byte load,
// which the processor cannot forward from the previous steps' 4-byte stores to the same edge
// (the edge popped next is usually one whose link a step before just rewrote), a stall that took
// about a fifth of the traversal's time. Relaxed atomic loads are plain loads the compiler does
// not merge.
CATPAQ_RANS_INLINE DecEdge load_edge(const DecEdge& e) {
    return {__atomic_load_n(&e.v0, __ATOMIC_RELAXED), __atomic_load_n(&e.v1, __ATOMIC_RELAXED),
            __atomic_load_n(&e.opp, __ATOMIC_RELAXED), __atomic_load_n(&e.prev, __ATOMIC_RELAXED),
            __atomic_load_n(&e.next, __ATOMIC_RELAXED)};
}

// s == K ? a : b as one compare and one conditional move. The traversal selects a dozen values
// by its unpredictable symbol; GCC compiled the same selections written as ternaries or masks
// to branches or to and/xor sequences of three to four instructions each.
template <uint32_t K>
CATPAQ_RANS_INLINE uint32_t select_if(uint32_t s, uint32_t a, uint32_t b) {
#if defined(__x86_64__) && defined(__GNUC__)
    asm("cmpl %[k], %[s]\n\tcmove %[a], %[b]" : [b] "+r"(b) : [s] "r"(s), [k] "i"(K), [a] "r"(a) : "cc");
    return b;
#else
    return s == K ? a : b;
#endif
}

// Scratch memory of the decoder, kept per thread between calls (fragments are small and
// decoded by the thousand); fragments above kWorkspaceKeepVertices use a temporary one.
struct Workspace {
    std::vector<DecEdge> edges;  // the front (decode_connectivity)
    std::vector<Pred> pred;
    std::vector<uint8_t> symbols;
    std::vector<Coord> coords;
    std::vector<int8_t> nu, nv;
    std::vector<NormalSum> acc;  // version 1
    std::vector<Float4> fcoords, facc;  // version 2
    std::vector<int32_t> residuals;  // of the attribute being decoded (decode_residuals)
    std::vector<uint32_t> rgb;
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
    return unzigzag(kBucketDecode.base[s] | d.take_bits(kBucketDecode.nbits[s]));
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

// Decodes n items of K residuals, residual j of item v on lane j with table t[j], into
// r[K v + j]. The attribute passes decode their residuals first with this and predict after:
// sharing one loop with the predictions, the compiler kept the rANS states, the byte pointer and
// the bit buffer on the stack (a store and reload on every symbol's dependency chain); alone,
// they stay in registers.
// (Without SLP vectorisation: GCC kept two of the lane states packed in an SSE register,
// unpacking and repacking them on every item.)
template <int K>
__attribute__((optimize("no-tree-slp-vectorize"))) void decode_residuals(rans::Decoder& io, const rans::TableView* t,
                                                                         uint32_t n, int32_t* r) {
    static_assert(K >= 1 && K <= 3);
    rans::Decoder dec = io;
    const rans::TableView t0 = t[0], t1 = t[K > 1 ? 1 : 0], t2 = t[K > 2 ? 2 : 0];
    for_each_item(dec, n, K, [&]<bool kFast>(uint32_t v) __attribute__((always_inline)) {
        int32_t* out = r + size_t(K) * v;
        out[0] = dresidual<kFast, 0>(dec, t0);
        if constexpr (K > 1) out[1] = dresidual<kFast, 1>(dec, t1);
        if constexpr (K > 2) out[2] = dresidual<kFast, 2>(dec, t2);
    });
    io = dec;
}

// Decodes n symbols of one table, symbol k on lane k & 3, into out: four per step while the
// stream surely holds them, then one at a time with its bounds checks. The connectivity and the
// joint colours are such runs.
__attribute__((always_inline)) inline void decode_symbols_on_four_lanes(rans::Decoder& io, const rans::TableView& table,
                                                                        uint32_t n, uint8_t* out) {
    rans::Decoder dec = io;
    uint32_t k = 0;
    while (n - k >= 4 && dec.rans_bytes_left() >= 4 * rans::Decoder::kMaxBytesPerSymbol) {
        out[k] = uint8_t(dec.sym<0>(table));
        out[k + 1] = uint8_t(dec.sym<1>(table));
        out[k + 2] = uint8_t(dec.sym<2>(table));
        out[k + 3] = uint8_t(dec.sym<3>(table));
        k += 4;
    }
    for (; k < n; ++k) {
        switch (k & 3) {
            case 0: out[k] = uint8_t(dec.get<0>(table)); break;
            case 1: out[k] = uint8_t(dec.get<1>(table)); break;
            case 2: out[k] = uint8_t(dec.get<2>(table)); break;
            default: out[k] = uint8_t(dec.get<3>(table)); break;
        }
    }
    io = dec;
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
    decode_symbols_on_four_lanes(io, rans::TableView(conn_table), nsym, sym);
    sym[nsym] = 0xff;  // sentinel: running out of symbols reads an invalid one
    rans::Decoder dec = io;
    Pred* pred = ws.pred.data();
    // The front's state lives in locals (as members of the workspace's Front the compiler
    // stored and reloaded them at every step), edges are linked by byte offsets (DecEdge), the
    // capacity is checked once per block of triangles (a step adds at most 3 edges), and the slot
    // past the last edge is kept live (prev != kDead) so that skipping consumed edges needs no
    // bound check. The edits are Front's.
    std::vector<DecEdge>& store = ws.edges;
    uint32_t size = 0, head = 0, seen = 0;  // size and head: byte offsets
    // Whether edge `head` is consumed, known before the step that precedes its pop has stored
    // anything (see the fast path): popping it no longer waits for that step's stores (measured:
    // 2-3% less decoding CPU on the 1M scan's CATP dataset).
    bool head_dead = false;
    const uint8_t* next = sym;
    uint32_t* const tri_end = tri + 3 * size_t(R);
    while (tri != tri_end) {
        const uint32_t block = std::min(uint32_t((tri_end - tri) / 3), kFrontBlock);
        const size_t need = size / kEdgeBytes + 3 * size_t(block) + 2;
        if (store.size() < need) store.resize(std::max(need, 2 * store.size()));
        uint8_t* const base = reinterpret_cast<uint8_t*>(store.data());
        auto E = [base](uint32_t off) __attribute__((always_inline)) -> DecEdge& {
            return *reinterpret_cast<DecEdge*>(base + off);
        };
        E(size).prev = 0;
        for (uint32_t* const stop = tri + 3 * size_t(block); tri != stop;) {
            // One consumed edge skipped without a branch (the common case), longer runs by one.
            uint32_t i = head + (kEdgeBytes & (0u - uint32_t(head_dead)));
            while (E(i).prev == kDead) [[unlikely]]
                i += kEdgeBytes;
            if (i == size) [[unlikely]] {
                // The queue is exhausted: a new component, three vertices, each NEW or SPLIT.
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
                const uint32_t i1 = i + kEdgeBytes, i2 = i1 + kEdgeBytes;
                E(i) = {c[0], c[1], c[2], i2, i1};
                E(i1) = {c[1], c[2], c[0], i, i2};
                E(i2) = {c[2], c[0], c[1], i1, i};
                size = i2 + kEdgeBytes;
                E(size).prev = 0;
                head = i;
                head_dead = false;
                tri[0] = c[0], tri[1] = c[1], tri[2] = c[2];
                tri += 3;
                continue;
            }
            head = i + kEdgeBytes;
            const DecEdge ei = load_edge(E(i));
            const uint32_t s = *next++;
            uint32_t v;
            if (s <= kRight) [[likely]] {
                // NEW, LEFT and RIGHT without branches (they are the bulk and unpredictable), by
                // conditional moves: the first new edge A = (v0 -> v) at f, the second
                // B = (v -> v1) at f + 1 (NEW; a spare slot for LEFT) or at f over A (RIGHT).
                const uint32_t p = ei.prev, n = ei.next;
                const uint32_t vl = E(n).v1, nn = E(n).next, vr = E(p).v0, pp = E(p).prev;
                // The next head's state, loaded before this step's stores and updated below by
                // comparing offsets: loaded after them, the next pop waited for the stores
                // (that edge is often this step's `n`, whose prev it rewrites).
                const bool head_was_dead = E(head).prev == kDead;
                v = select_if<kNew>(s, seen, select_if<kLeft>(s, vl, vr));
                // (v0, v1) of the prediction and (v1, v0) of the triangle as 8-byte stores from
                // one 8-byte load (the loop is bound by its stores as much as by anything).
                uint64_t v01;
                std::memcpy(&v01, &E(i).v0, 8);
                Pred* const q = pred + select_if<kNew>(s, seen, V);  // slot V: scratch
                std::memcpy(&q->a, &v01, 8);
                q->c = ei.opp;
                seen += s == kNew;
                if ((seen > V) | (v == ei.v0) | (v == ei.v1)) [[unlikely]]
                    return FragmentStatus::Corrupt;
                const uint32_t left_anchor = select_if<kRight>(s, pp, p);
                const uint32_t right_anchor = select_if<kLeft>(s, nn, n);
                const uint32_t f = size, f1 = size + kEdgeBytes;
                const uint32_t last = select_if<kNew>(s, f1, f);
                E(f) = DecEdge{ei.v0, v, ei.v1, p, select_if<kNew>(s, f1, right_anchor)};
                E(select_if<kRight>(s, f, f1)) = DecEdge{v, ei.v1, ei.v0, select_if<kNew>(s, f, left_anchor), right_anchor};
                E(left_anchor).next = f;
                E(right_anchor).prev = last;
                // Edge i itself is not marked: it is behind head, and no link points to it now.
                const uint32_t consumed = select_if<kLeft>(s, n, select_if<kRight>(s, p, i));
                E(consumed).prev = kDead;
                size = last + kEdgeBytes;
                E(size).prev = 0;
                // The stores above that can change edge head's prev (head <= f: at f it was
                // the live slot past the last edge, and the new edge written there is live too;
                // live edges link only to live edges, so a consumed head is no anchor).
                head_dead = (head == consumed) | (head_was_dead & (head != right_anchor));
                const uint64_t v10 = (v01 >> 32) | (v01 << 32);
                std::memcpy(tri, &v10, 8);
                tri[2] = v;
                tri += 3;
                continue;
            }
            switch (s) {
                case kBoundary:  // the edge stays in its loop (a neighbour's LEFT or RIGHT may use it)
                    head_dead = E(head).prev == kDead;
                    continue;
                case kEnd: {
                    v = E(ei.next).v1;
                    if (v == ei.v0 || v == ei.v1 || E(ei.prev).v0 != v) return FragmentStatus::Corrupt;
                    // prev, i and next are removed (Front::end).
                    const uint32_t p = ei.prev, n = ei.next, pp = E(p).prev, nn = E(n).next;
                    E(i).prev = kDead;
                    E(p).prev = kDead;
                    E(n).prev = kDead;
                    if (pp != n) {
                        E(pp).next = nn;
                        E(nn).prev = pp;
                    }
                    break;
                }
                case kSplit: {
                    if (seen == 0) return FragmentStatus::Corrupt;
                    v = dec.get_bits(uint32_t(bit_width_u32(seen - 1)));
                    if (v >= seen || v == ei.v0 || v == ei.v1) return FragmentStatus::Corrupt;
                    // Edge i is replaced by (v0 -> v), (v -> v1) (Front::add_vertex).
                    const uint32_t a = size, b = a + kEdgeBytes;
                    E(a) = {ei.v0, v, ei.v1, ei.prev, b};
                    E(b) = {v, ei.v1, ei.v0, a, ei.next};
                    E(ei.prev).next = a;
                    E(ei.next).prev = b;
                    E(i).prev = kDead;
                    size = b + kEdgeBytes;
                    E(size).prev = 0;
                    break;
                }
                default:
                    return FragmentStatus::Corrupt;
            }
            head_dead = E(head).prev == kDead;
            tri[0] = ei.v1, tri[1] = ei.v0, tri[2] = v;
            tri += 3;
        }
    }
    if (next != sym + nsym) return FragmentStatus::Corrupt;  // symbols left over
    seen_out = seen;
    io = dec;
    return FragmentStatus::Ok;
}

// Positions: sets each vertex's position bits (word1 = 0 for Rgb24, which holds no position
// there) and ws.coords (cumulative coordinates, index V = 0). False on a coordinate out of range.
bool decode_positions(rans::Decoder& io, Workspace& ws, const VertexLayout& layout, int pos_mode, uint32_t V, const Pred* pred, PackedVertex* vert) {
    rans::Decoder dec = io;
    const int32_t kGrid = layout.grid;
    const bool wide = layout.kind == VertexLayoutKind::Position48;
    // The position bits of weights (w1, w2, w3), w1 + w2 + w3 <= grid: three 16-bit weights, or
    // the index (below 2^30, so the colour bits of word1 stay zero).
    auto set_position = [&](PackedVertex& out, int32_t w1, int32_t w2, int32_t w3) __attribute__((always_inline)) {
        const uint64_t p = wide ? uint64_t(w1) | (uint64_t(w2) << 16) | (uint64_t(w3) << 32)
                                : uint64_t(kBaryTables.tet[size_t(w1 + w2 + w3)] + kBaryTables.tri[size_t(w2 + w3)] +
                                           uint32_t(w3));
        out.word0 = uint32_t(p & 0xffffff);
        out.word1 = uint32_t(p >> 24) << 8;
    };
    Coord* s = ws.coords.data();
    s[V] = {0, 0, 0, 0};
    uint32_t bad = 0;  // accumulated range violations, checked once
    const rans::TableView tables[3] = {rans::TableView(ws.tables[kStreamPos0]), rans::TableView(ws.tables[kStreamPos1]),
                                       rans::TableView(ws.tables[kStreamPos2])};
    grow(ws.residuals, 3 * size_t(V));
    int32_t* res = ws.residuals.data();
    if (pos_mode == kPosRaw) {
        const uint32_t high_bits = uint32_t(layout.color_shift() - 24);
        for (uint32_t v = 0; v < V; ++v) {
            vert[v].word0 = dec.get_bits(24);
            vert[v].word1 = dec.get_bits(high_bits) << 8;
        }
    } else if (pos_mode == kPosCumulative) {
        decode_residuals<3>(dec, tables, V, res);
        for (uint32_t v = 0; v < V; ++v) {
            const Pred q = pred[v];
            const Coord A = s[q.a], B = s[q.b], C = s[q.c];
            const int32_t* r = res + 3 * size_t(v);
            int32_t a = std::clamp(A[0] + B[0] - C[0], 0, kGrid) + r[0];
            const int32_t rb = r[1], rc = r[2];
            bad |= uint32_t(a) > uint32_t(kGrid);
            a = std::clamp(a, 0, kGrid);
            int32_t b = std::clamp(A[1] + B[1] - C[1], 0, a) + rb;
            bad |= uint32_t(b) > uint32_t(a);
            b = std::clamp(b, 0, a);
            int32_t c = std::clamp(A[2] + B[2] - C[2], 0, b) + rc;
            bad |= uint32_t(c) > uint32_t(b);
            c = std::clamp(c, 0, b);
            s[v] = {a, b, c, 0};
            set_position(vert[v], a - b, b - c, c);
        }
    } else {
        // Weight space: (w1, w2, w3) kept in s during the pass, converted after.
        decode_residuals<3>(dec, tables, V, res);
        for (uint32_t v = 0; v < V; ++v) {
            const Pred q = pred[v];
            const Coord A = s[q.a], B = s[q.b], C = s[q.c];
            const int32_t* r = res + 3 * size_t(v);
            int32_t w1 = std::clamp(A[0] + B[0] - C[0], 0, kGrid) + r[0];
            const int32_t r2 = r[1], r3 = r[2];
            bad |= uint32_t(w1) > uint32_t(kGrid);
            w1 = std::clamp(w1, 0, kGrid);
            int32_t w2 = std::clamp(A[1] + B[1] - C[1], 0, kGrid - w1) + r2;
            bad |= uint32_t(w2) > uint32_t(kGrid - w1);
            w2 = std::clamp(w2, 0, kGrid - w1);
            int32_t w3 = std::clamp(A[2] + B[2] - C[2], 0, kGrid - w1 - w2) + r3;
            bad |= uint32_t(w3) > uint32_t(kGrid - w1 - w2);
            w3 = std::clamp(w3, 0, kGrid - w1 - w2);
            s[v] = {w1, w2, w3, 0};
            set_position(vert[v], w1, w2, w3);
        }
        for (uint32_t v = 0; v < V; ++v) s[v] = {s[v][0] + s[v][1] + s[v][2], s[v][1] + s[v][2], s[v][2], 0};
    }
    io = dec;
    return bad == 0;
}

// u into bits 24..31 of word0, v into bits 0..7 of word1 (signed bytes).
CATPAQ_RANS_INLINE void set_normal(PackedVertex& out, int u, int v) {
    out.word0 |= uint32_t(uint8_t(u)) << 24;
    out.word1 |= uint8_t(v);
}

// accumulate_normals with the normals' rANS symbols (u on lane 0, v on lane 1, one vertex's pair
// per triangle) decoded in the same loop into syms: the accumulation waits on the read-modify-
// writes of neighbouring triangles' shared corners, the symbols on their states, and each fills
// the other's idle slots (about 2% of the decoding time on a scan's CATP dataset, where the
// geometric predictor is the rule). Their raw bits are read later, in order, by
// decode_geometric_normals.
// Sums and coordinates: NormalSum and Coord with accumulate_triangle (version 1), Float4 with
// accumulate_triangle_f (version 2).
template <class Sum, class C, void (*kAccumulate)(const uint32_t*, const C*, Sum*)>
void accumulate_normals_decoding(const uint32_t* indices, uint32_t T, const C* s, Sum* acc,
                                 rans::Decoder& io, const rans::TableView* tables, uint32_t V, uint8_t* syms) {
    rans::Decoder dec = io;
    const rans::TableView tu = tables[0], tv = tables[1];
    // Vertices whose two symbols can be decoded unchecked (2 bytes at most per symbol).
    const uint32_t fast = uint32_t(std::min<size_t>(V, dec.rans_bytes_left() / (2 * rans::Decoder::kMaxBytesPerSymbol)));
    uint32_t v = 0;
    for (uint32_t t = 0; t < T; ++t) {
        kAccumulate(indices + 3 * size_t(t), s, acc);
        if (v < fast) {
            syms[2 * size_t(v)] = uint8_t(dec.sym<0>(tu));
            syms[2 * size_t(v) + 1] = uint8_t(dec.sym<1>(tv));
            ++v;
        }
    }
    for (; v < V; ++v) {
        syms[2 * size_t(v)] = uint8_t(dec.get<0>(tu));
        syms[2 * size_t(v) + 1] = uint8_t(dec.get<1>(tv));
    }
    io = dec;
}

// A residual from its bucket symbol and the raw bits that follow (need_bits(kMaxExtraBits) first).
CATPAQ_RANS_INLINE int32_t bucket_residual(rans::Decoder& d, uint32_t s) {
    return unzigzag(kBucketDecode.base[s] | d.take_bits(kBucketDecode.nbits[s]));
}

// Geometric normals from the sums, the bucket symbols (u, v per vertex) and their raw bits. The
// predictions depend on no decoded value (but for the rare fallback to the previous normal), so
// this loop pipelines freely.
void decode_geometric_normals(rans::Decoder& io, const NormalSum* acc, const std::array<int8_t, 9>& matrix,
                              uint32_t V, const uint8_t* syms, PackedVertex* vert) {
    rans::Decoder dec = io;
#if defined(__SSE2__)
    const NormalMatrix m(matrix);
#endif
    int prev_u = 0, prev_v = 0;
    for (uint32_t v = 0; v < V; ++v) {
        dec.need_bits(2 * kMaxExtraBits);
        const int32_t ru = bucket_residual(dec, syms[2 * size_t(v)]);
        const int32_t rv = bucket_residual(dec, syms[2 * size_t(v) + 1]);
        int pu, pv;
#if defined(__SSE2__)
        if (!geometric_prediction_sse2(acc[v], m, pu, pv)) [[unlikely]] {
            pu = prev_u;
            pv = prev_v;
        }
#else
        geometric_prediction(acc[v], matrix, prev_u, prev_v, pu, pv);
#endif
        prev_u = int8_t(uint8_t(pu + ru));
        prev_v = int8_t(uint8_t(pv + rv));
        set_normal(vert[v], prev_u, prev_v);
    }
    io = dec;
}

// Version 2's geometric normals from the sums (predict_normals_f, four vertices at a time into a
// local block rather than a pass of its own), the bucket symbols (u, v per vertex) and their raw
// bits. acc needs V rounded up to a multiple of 4 readable entries.
void decode_geometric_normals_f(rans::Decoder& io, const Float4* acc, const std::array<int8_t, 9>& matrix, uint32_t V,
                                const uint8_t* syms, PackedVertex* vert) {
    rans::Decoder dec = io;
#if defined(__SSE2__)
    const NormalPredictor4 p4(matrix);
#endif
    int prev_u = 0, prev_v = 0;
    for (uint32_t v = 0; v < V; v += 4) {
        alignas(8) int8_t uv[8];
#if defined(__SSE2__)
        p4.predict(acc + v, uv);
#else
        for (uint32_t k = 0; k < 4; ++k) predict_normal_f(acc[v + k], matrix, uv + 2 * k);
#endif
        for (uint32_t k = 0; k < std::min(4u, V - v); ++k) {
            dec.need_bits(2 * kMaxExtraBits);
            const int32_t ru = bucket_residual(dec, syms[2 * size_t(v + k)]);
            const int32_t rv = bucket_residual(dec, syms[2 * size_t(v + k) + 1]);
            const bool none = uv[2 * k] == kNoPrediction;
            prev_u = int8_t(uint8_t((none ? prev_u : uv[2 * k]) + ru));
            prev_v = int8_t(uint8_t((none ? prev_v : uv[2 * k + 1]) + rv));
            set_normal(vert[v + k], prev_u, prev_v);
        }
    }
    io = dec;
}

// Normals: ORs u into word0 and v into word1 (signed bytes; index V is the virtual zero vertex).
void decode_normals(rans::Decoder& io, Workspace& ws, int version, int normal_mode, const std::array<int8_t, 9>& matrix,
                    uint32_t V, uint32_t T, const Pred* pred, const uint32_t* indices, PackedVertex* vert) {
    const rans::TableView tables[2] = {rans::TableView(ws.tables[kStreamNormU]), rans::TableView(ws.tables[kStreamNormV])};
    if (normal_mode == kNormalGeometric && version >= 2) {
        grow(ws.fcoords, V);
        for (uint32_t v = 0; v < V; ++v) ws.fcoords[v] = to_float4(ws.coords[v]);
        ws.facc.assign((size_t(V) + 3) & ~size_t(3), Float4{});
        grow(ws.symbols, 2 * size_t(V));
        accumulate_normals_decoding<Float4, Float4, accumulate_triangle_f>(indices, T, ws.fcoords.data(), ws.facc.data(),
                                                                           io, tables, V, ws.symbols.data());
        decode_geometric_normals_f(io, ws.facc.data(), matrix, V, ws.symbols.data(), vert);
        return;
    }
    if (normal_mode == kNormalGeometric) {
        ws.acc.assign(V, NormalSum{0, 0, 0, 0});
        grow(ws.symbols, 2 * size_t(V));
        accumulate_normals_decoding<NormalSum, Coord, accumulate_triangle>(indices, T, ws.coords.data(), ws.acc.data(),
                                                                           io, tables, V, ws.symbols.data());
        decode_geometric_normals(io, ws.acc.data(), matrix, V, ws.symbols.data(), vert);
        return;
    }
    grow(ws.residuals, 2 * size_t(V));
    int32_t* res = ws.residuals.data();
    decode_residuals<2>(io, tables, V, res);
    grow(ws.nu, size_t(V) + 1);
    grow(ws.nv, size_t(V) + 1);
    int8_t *nu = ws.nu.data(), *nv = ws.nv.data();
    nu[V] = nv[V] = 0;
    if (normal_mode == kNormalAverage) {
        for (uint32_t v = 0; v < V; ++v) {
            const Pred q = pred[v];
            const int ru = res[2 * size_t(v)], rv = res[2 * size_t(v) + 1];
            nu[v] = int8_t(uint8_t(((nu[q.a] + nu[q.b]) >> 1) + ru));
            nv[v] = int8_t(uint8_t(((nv[q.a] + nv[q.b]) >> 1) + rv));
            set_normal(vert[v], nu[v], nv[v]);
        }
    } else {
        for (uint32_t v = 0; v < V; ++v) {
            const Pred q = pred[v];
            const int ru = res[2 * size_t(v)], rv = res[2 * size_t(v) + 1];
            nu[v] = int8_t(uint8_t(std::clamp(nu[q.a] + nu[q.b] - nu[q.c], -127, 127) + ru));
            nv[v] = int8_t(uint8_t(std::clamp(nv[q.a] + nv[q.b] - nv[q.c], -127, 127) + rv));
            set_normal(vert[v], nu[v], nv[v]);
        }
    }
}

// Version 2's joint colour coding: the V joint symbols in a tight loop on the four lanes (vertex
// v's on lane v & 3), then the residuals, G R B per vertex into r, from the symbol or, after an
// escape, from the stream (lanes 0, 1, 2; t: the G, R and B tables).
void decode_joint_colour_residuals(rans::Decoder& io, const rans::TableView& joint, const rans::TableView* t,
                                   uint32_t V, uint8_t* js, int32_t* r) {
    decode_symbols_on_four_lanes(io, joint, V, js);
    rans::Decoder dec = io;
    // Symbols are below the table's alphabet, at most kJointSymbols (checked with the table).
    for (uint32_t v = 0; v < V; ++v) {
        const uint32_t j = js[v];
        int32_t* out = r + 3 * size_t(v);
        if (j < kJointEscape) [[likely]] {
            const std::array<int32_t, 4>& x = kJointResiduals.rgb[j];
            out[0] = x[0], out[1] = x[1], out[2] = x[2];
            continue;
        }
        dec.need_bits(3 * kMaxExtraBits);
        out[0] = dresidual<false, 0>(dec, t[0]);
        out[1] = dresidual<false, 1>(dec, t[1]);
        out[2] = dresidual<false, 2>(dec, t[2]);
    }
    io = dec;
}

// Colours: ORs R, G, B into word1.
template <bool kParallelogram>
void decode_colors_with(rans::Decoder& io, Workspace& ws, const ColorField& f, bool decorrelate, bool joint, uint32_t V,
                        const Pred* pred, PackedVertex* vert) {
    // Channel values packed R | G << 8 | B << 16: one 4-byte store per vertex, which the next
    // vertices' 4-byte loads of it are forwarded from.
    grow(ws.rgb, size_t(V) + 1);
    uint32_t* rgb = ws.rgb.data();
    rgb[V] = 0;
    // G first (lane 0), then R (lane 1) and B (lane 2).
    const rans::TableView tables[3] = {rans::TableView(ws.tables[kStreamColG]), rans::TableView(ws.tables[kStreamColR]),
                                       rans::TableView(ws.tables[kStreamColB])};
    grow(ws.residuals, 3 * size_t(V));
    int32_t* res = ws.residuals.data();
    if (joint) {
        grow(ws.symbols, V);
        decode_joint_colour_residuals(io, rans::TableView(ws.tables[kStreamColJoint]), tables, V, ws.symbols.data(), res);
    } else {
        decode_residuals<3>(io, tables, V, res);
    }
    const int32_t dmask = decorrelate ? -1 : 0;
    const int top = f.top, shift = f.shift, bits = f.bits;
    auto predict = [top](int a, int b, int c) {
        if constexpr (kParallelogram)
            return std::clamp(a + b - c, 0, top);
        else
            return (a + b + 1) >> 1;
    };
    for (uint32_t v = 0; v < V; ++v) {
        const Pred q = pred[v];
        const int32_t* rv = res + 3 * size_t(v);
        const int32_t rg = rv[0];
        const int32_t rr = rv[1] + (rg & dmask);
        const int32_t rb = rv[2] + (rg & dmask);
        const uint32_t A = rgb[q.a], B = rgb[q.b], C = rgb[q.c];
        auto channel = [](uint32_t w, int k) { return int((w >> (8 * k)) & 0xffu); };
        const uint32_t r = uint32_t(predict(channel(A, 0), channel(B, 0), channel(C, 0)) + rr) & uint32_t(top);
        const uint32_t g = uint32_t(predict(channel(A, 1), channel(B, 1), channel(C, 1)) + rg) & uint32_t(top);
        const uint32_t bl = uint32_t(predict(channel(A, 2), channel(B, 2), channel(C, 2)) + rb) & uint32_t(top);
        rgb[v] = r | g << 8 | bl << 16;
        vert[v].word1 |= r << shift | g << (shift + bits) | bl << (shift + 2 * bits);
    }
}

void decode_colors(rans::Decoder& io, Workspace& ws, const VertexLayout& layout, bool parallelogram, bool decorrelate,
                   bool joint, uint32_t V, const Pred* pred, PackedVertex* vert) {
    const ColorField f(layout);
    if (parallelogram)
        decode_colors_with<true>(io, ws, f, decorrelate, joint, V, pred, vert);
    else
        decode_colors_with<false>(io, ws, f, decorrelate, joint, V, pred, vert);
}

FragmentStatus decode_compressed(const uint8_t* p, size_t size, int version, uint32_t V, uint32_t T, FragmentMesh& out,
                                 Workspace& ws) {

    const bool colors = out.layout.has_color();
    if (size < 1) return FragmentStatus::Corrupt;
    const uint8_t modes = *p++;
    --size;
    const int pos_mode = modes & 3, normal_mode = (modes >> 2) & 3;
    const bool color_parallelogram = (modes >> 4) & 1, color_decorrelate = (modes >> 5) & 1;
    const bool color_joint = (modes >> 6) & 1;  // version 2
    if (pos_mode > kPosRaw || normal_mode > kNormalGeometric || (modes >> 7) != 0) return FragmentStatus::Corrupt;
    if (color_joint && (version < 2 || !colors)) return FragmentStatus::Corrupt;
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
        if (!colors && s >= kStreamColR) continue;
        if (s == kStreamColJoint && !color_joint) continue;
        rans::FreqTable f;
        if (!dec.get_table(f, ws.tables[size_t(s)])) return FragmentStatus::Corrupt;
        if (s == kStreamConn && f.nsym > int(kConnSymbols)) return FragmentStatus::Corrupt;
        if (s == kStreamColJoint && f.nsym > kJointSymbols) return FragmentStatus::Corrupt;
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
    if (!decode_positions(dec, ws, out.layout, pos_mode, V, pred, out.vertices.data())) return FragmentStatus::Corrupt;
    decode_normals(dec, ws, version, normal_mode, matrix, V, T, pred, out.indices.data(), out.vertices.data());
    if (colors) {
        decode_colors(dec, ws, out.layout, color_parallelogram, color_decorrelate, color_joint, V, pred, out.vertices.data());
    } else if (color_parallelogram || color_decorrelate) {
        return FragmentStatus::Corrupt;
    }
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
    out.layout = fragment_layout(data);
    if (coding == kCodingStored) return decode_stored(payload + 3, payload_size - 3, V, T, out);
    if (coding != kCodingCompressed) return FragmentStatus::Corrupt;
    if (V <= kWorkspaceKeepVertices) {
        thread_local Workspace ws;
        return decode_compressed(payload + 3, payload_size - 3, data[4], V, T, out, ws);
    }
    Workspace ws;
    return decode_compressed(payload + 3, payload_size - 3, data[4], V, T, out, ws);
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
