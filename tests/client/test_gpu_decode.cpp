// The vertex shader's decode (shaders/catp_decode.glsl + catp.vert), captured with transform
// feedback, against the CPU mirror decode_packed_vertex (common_codec/packed_vertex.h).
//
// Positions must be bit-identical in every vertex layout: the shader does exact integer sums and
// the same few float operations as the CPU. Normals (a division, abs, sqrt) are compared with a
// tolerance and the number of bit-identical ones is reported: positions are what makes cuts
// crack-free.
#include <gtest/gtest.h>
#include <epoxy/gl.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <map>
#include <memory>
#include <random>
#include <set>

#include "base/error.h"
#include "catp/cut.h"
#include "catp/dataset.h"
#include "catp_client/catp_gpu.h"
#include "catp_client/static_render.h"
#include "client/gl_program.h"
#include "common_codec/octahedral.h"
#include "common_codec/packed_vertex.h"
#include "gl_support.h"

using namespace catpaq;

namespace {

// The real vertex shader, linked with its outputs captured by transform feedback.
class FeedbackDecoder {
public:
    // A surfaceless context has no default framebuffer, and draws (even with rasterizer discard)
    // need a complete one: bind a 1x1 target.
    FeedbackDecoder() : target_(1, 1) {
        target_.bind();
        bool gles = current_context_is_gles();
        program_ = GlProgram(catp_shader_source(CatpShader::PackedVertex, gles), catp_shader_source(CatpShader::Fragment, gles),
                             {"v_position", "v_normal", "v_color"});
        glGenBuffers(1, &buffer_);
        glGenQueries(1, &query_);
    }
    ~FeedbackDecoder() {
        glDeleteBuffers(1, &buffer_);
        glDeleteQueries(1, &query_);
    }

    // Runs every vertex of `g` through the shader with the decode inputs `p` (offsets: g's
    // corners minus the anchor); 9 floats per vertex (position, normal, colour).
    std::vector<float> decode(const GpuFragment& g, const VertexDecodeParams& p) {
        target_.bind();
        glUseProgram(program_.id());
        glUniform3iv(program_.uniform("corners"), 4, p.offsets[0].data());
        glUniform1i(program_.uniform("vertex_layout"), int(p.layout.kind));
        glUniform1i(program_.uniform("grid"), p.layout.grid);
        glUniform1f(program_.uniform("scale"), p.scale);
        glUniform3fv(program_.uniform("default_color"), 1, p.default_color.data());
        const float identity[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
        glUniformMatrix4fv(program_.uniform("mvp"), 1, GL_FALSE, identity);
        const size_t bytes = size_t(g.vertex_count) * 9 * sizeof(float);
        glBindBuffer(GL_TRANSFORM_FEEDBACK_BUFFER, buffer_);
        glBufferData(GL_TRANSFORM_FEEDBACK_BUFFER, GLsizeiptr(bytes), nullptr, GL_STREAM_READ);
        glBindBufferBase(GL_TRANSFORM_FEEDBACK_BUFFER, 0, buffer_);
        glBindVertexArray(g.vao);
        glEnable(GL_RASTERIZER_DISCARD);
        glBeginQuery(GL_TRANSFORM_FEEDBACK_PRIMITIVES_WRITTEN, query_);
        glBeginTransformFeedback(GL_POINTS);
        glDrawArrays(GL_POINTS, 0, GLsizei(g.vertex_count));
        glEndTransformFeedback();
        glEndQuery(GL_TRANSFORM_FEEDBACK_PRIMITIVES_WRITTEN);
        glDisable(GL_RASTERIZER_DISCARD);
        glBindVertexArray(0);
        GLuint written = 0;
        glGetQueryObjectuiv(query_, GL_QUERY_RESULT, &written);
        EXPECT_EQ(written, g.vertex_count);
        std::vector<float> out(size_t(g.vertex_count) * 9);
        if (bytes) {
            const void* p = glMapBufferRange(GL_TRANSFORM_FEEDBACK_BUFFER, 0, GLsizeiptr(bytes), GL_MAP_READ_BIT);
            EXPECT_NE(p, nullptr);
            if (p) std::memcpy(out.data(), p, bytes);
            glUnmapBuffer(GL_TRANSFORM_FEEDBACK_BUFFER);
        }
        glBindBufferBase(GL_TRANSFORM_FEEDBACK_BUFFER, 0, 0);
        glUseProgram(0);
        EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
        return out;
    }

private:
    Framebuffer target_;
    GlProgram program_;
    GLuint buffer_ = 0, query_ = 0;
};

uint32_t bits(float f) {
    uint32_t u;
    std::memcpy(&u, &f, 4);
    return u;
}

struct Comparison {
    size_t vertices = 0, position_mismatches = 0, normal_exact = 0, color_exact = 0;
    double max_normal_error = 0, max_color_error = 0;
};

// The decode inputs of fragment `g` for an anchor, a cell and the fragment's layout.
VertexDecodeParams params_for(const GpuFragment& g, const VertexLayout& layout, const LatticePoint& anchor, double cell) {
    VertexDecodeParams p;
    for (size_t i = 0; i < 4; ++i)
        for (size_t k = 0; k < 3; ++k) p.offsets[i][k] = g.corners[i][k] - anchor[k];
    p.layout = layout;
    p.scale = float(cell / layout.grid);
    p.default_color = {0.25f, 0.5f, 0.75f};
    return p;
}

// Compares GPU output with decode_packed_vertex for every vertex of the fragment.
void compare(const FragmentMesh& f, const std::vector<float>& gpu, const VertexDecodeParams& params, Comparison& c) {
    for (size_t v = 0; v < f.vertices.size(); ++v) {
        DecodedVertex cpu;
        ASSERT_TRUE(decode_packed_vertex(f.vertices[v], params, cpu));
        const float* out = &gpu[v * 9];
        ++c.vertices;
        bool same = true;
        for (int k = 0; k < 3; ++k) same = same && bits(out[k]) == bits(cpu.position[k]);
        if (!same) {
            if (c.position_mismatches < 5)
                ADD_FAILURE() << "vertex " << v << " payload " << f.vertices[v].payload() << " (" << params.layout.name()
                              << "): GPU (" << out[0]
                              << ", " << out[1] << ", " << out[2] << ") CPU (" << cpu.position[0] << ", "
                              << cpu.position[1] << ", " << cpu.position[2] << ")";
            ++c.position_mismatches;
        }
        bool normal_exact = true, color_exact = true;
        for (int k = 0; k < 3; ++k) {
            c.max_normal_error = std::max(c.max_normal_error, double(std::fabs(out[3 + k] - cpu.normal[k])));
            c.max_color_error = std::max(c.max_color_error, double(std::fabs(out[6 + k] - cpu.color[k])));
            normal_exact = normal_exact && bits(out[3 + k]) == bits(cpu.normal[k]);
            color_exact = color_exact && bits(out[6 + k]) == bits(cpu.color[k]);
        }
        c.normal_exact += normal_exact;
        c.color_exact += color_exact;
    }
}

void report(const char* what, const Comparison& c) {
    std::printf("%s: %zu vertices, positions bit-identical %zu/%zu; normals bit-identical %zu (max error %.3g); "
                "colours bit-identical %zu (max error %.3g)\n",
                what, c.vertices, c.vertices - c.position_mismatches, c.vertices, c.normal_exact, c.max_normal_error,
                c.color_exact, c.max_color_error);
}

// Anchors to decode with: zero, a far corner of the lattice, one near the middle, and a random one.
std::vector<LatticePoint> test_anchors() {
    return {LatticePoint{0, 0, 0}, LatticePoint{kLatticeSize, kLatticeSize, kLatticeSize},
            LatticePoint{kLatticeSize / 2 + 3, kLatticeSize / 2 - 7, kLatticeSize / 2 + 1},
            LatticePoint{123457, 987651, 555557}};
}

// Every layout at its finest grid, and one coarser grid.
const VertexLayout kLayouts[] = {{VertexLayoutKind::Rgb24, kBaryGrid},
                                 {VertexLayoutKind::Rgb18, kMaxIndexGrid},
                                 {VertexLayoutKind::Position48, kMaxWideGrid},
                                 {VertexLayoutKind::Position48, 3001}};

// Random valid weights of a grid.
BaryWeights random_weights(std::mt19937_64& rng, int32_t grid) {
    BaryWeights w{0, int32_t(rng() % uint64_t(grid + 1)), 0, 0};
    w[2] = int32_t(rng() % uint64_t(grid - w[1] + 1));
    w[3] = int32_t(rng() % uint64_t(grid - w[1] - w[2] + 1));
    w[0] = grid - w[1] - w[2] - w[3];
    return w;
}

// Every normal code, the extreme positions (the corners and their neighbours) and 60k random
// ones, every weight on the edge C0-C3 (the face rule's zero weights), several anchors and
// scales, in a tetrahedron at the far corner of the lattice (largest coordinates), decoded by
// the current context in `layout`.
Comparison decode_synthetic_vertices(const VertexLayout& layout) {
    // A fine diamond near (2^20, 2^20, 2^20): the largest corner coordinates, the largest sums.
    DiamondId id = DiamondId::from_centre({kLatticeSize - 1, kLatticeSize - 2, kLatticeSize - 2});
    EXPECT_TRUE(is_valid_diamond_centre(id.centre()));
    DiamondInfo info = diamond_info(id);
    int slot = 0;
    while (!(existing_slots(info) & (1 << slot))) ++slot;

    FragmentMesh f;
    f.layout = layout;
    const int32_t grid = layout.grid;
    std::mt19937_64 rng(7);
    for (uint32_t n = 0; n < 65536; ++n) {
        BaryWeights w;
        if (n < 64)
            w = {grid - int32_t(n % 4), int32_t(n % 4), 0, 0};  // corner C0 and neighbours
        else if (n < 128)
            w = {0, 0, int32_t(n % 4), grid - int32_t(n % 4)};  // corner C3 and neighbours
        else
            w = random_weights(rng, grid);
        const uint8_t rgb[3] = {uint8_t(n * 7), uint8_t(n >> 3), uint8_t(255 - n)};
        f.vertices.push_back(pack_vertex(layout, w, uint16_t(n), rgb));
    }
    const uint8_t rgb[3] = {1, 2, 3};
    for (int32_t w = 0; w <= grid; ++w) f.vertices.push_back(pack_vertex(layout, {grid - w, 0, 0, w}, 0, rgb));
    for (uint32_t i = 0; i < f.vertices.size(); ++i) f.indices.push_back(i);
    while (f.indices.size() % 3) f.indices.push_back(0);

    FragmentStore store;
    store.upload(id.bits, slot, f);
    const GpuFragment* g = store.find(id.bits, slot);
    EXPECT_NE(g, nullptr);
    Comparison c;
    if (!g) return c;
    FeedbackDecoder decoder;
    for (const LatticePoint& anchor : test_anchors())
        for (double cell : {std::ldexp(1.0, -19), 1.0, std::ldexp(1.0, 12), std::ldexp(1.0, -40), 0.3}) {
            const VertexDecodeParams params = params_for(*g, layout, anchor, cell);
            compare(f, decoder.decode(*g, params), params, c);
        }
    return c;
}

}  // namespace

TEST(GpuDecode, PositionsAreBitIdenticalToTheCpuMirrorForSyntheticVertices) {
    GL_TEST_CONTEXT();
    for (const VertexLayout& layout : kLayouts) {
        Comparison c = decode_synthetic_vertices(layout);
        report((std::string("synthetic ") + layout.name() + "/" + std::to_string(layout.grid)).c_str(), c);
        EXPECT_GT(c.vertices, 1000000u);
        EXPECT_EQ(c.position_mismatches, 0u) << layout.name();
        EXPECT_LE(c.max_normal_error, 2e-7);  // a couple of float ulps at most
        EXPECT_LE(c.max_color_error, 1e-7) << layout.name();
    }
}

// The same through an OpenGL ES 3.0 context (#version 300 es shaders, no `precise`).
TEST(GpuDecode, PositionsAreBitIdenticalToTheCpuMirrorOnGles) {
    GL_TEST_CONTEXT();
    GlContextOptions options;
    options.api = GlApi::Gles;
    std::unique_ptr<HeadlessGlContext> es;
    try {
        es = std::make_unique<HeadlessGlContext>(options);
    } catch (const Error& e) {
        test::gl_context(nullptr);
        GTEST_SKIP() << "no OpenGL ES context: " << e.what();
    }
    EXPECT_TRUE(es->is_gles());
    EXPECT_TRUE(current_context_is_gles());
    std::printf("ES context: %s\n", es->version().c_str());
    for (const VertexLayout& layout : kLayouts) {
        Comparison c = decode_synthetic_vertices(layout);  // its GL objects die before the context
        report((std::string("synthetic, OpenGL ES, ") + layout.name()).c_str(), c);
        EXPECT_EQ(c.position_mismatches, 0u) << layout.name();
        EXPECT_LE(c.max_normal_error, 2e-7);
    }
    es.reset();
    test::gl_context(nullptr);
}

// The vertex shader's bary_unpack must be exact on every position index of both enumerated
// layouts. By default the test covers the boundaries of the enumeration, where the float
// estimates and the integer correction loops meet (24-bit: the first and last index of every
// (a, b) row and their neighbours, for all 464 values of a; 30-bit: the same for b in
// {0, 1, a/2, a - 1, a}, for all 1859 values of a) plus a million random indices each; with
// CATPAQ_EXHAUSTIVE=1 it checks all 16,757,360 indices of the 24-bit layout (about 10 s on
// llvmpipe, whose vertex shading is single-threaded).
TEST(GpuDecode, PositionIndicesUnpackExactly) {
    GL_TEST_CONTEXT();
    const bool exhaustive = std::getenv("CATPAQ_EXHAUSTIVE") != nullptr;
    for (const VertexLayout layout : {VertexLayout{VertexLayoutKind::Rgb24, kBaryGrid},
                                      VertexLayout{VertexLayoutKind::Rgb18, kMaxIndexGrid}}) {
        const uint32_t count = bary_index_count(layout.grid);
        std::vector<uint32_t> indices;
        if (exhaustive && layout.kind == VertexLayoutKind::Rgb24) {
            indices.resize(count);
            for (uint32_t i = 0; i < count; ++i) indices[i] = i;
        } else {
            auto tet = [](uint64_t a) { return uint32_t(a * (a + 1) * (a + 2) / 6); };
            auto tri = [](uint32_t b) { return b * (b + 1) / 2; };
            const bool all_rows = layout.kind == VertexLayoutKind::Rgb24;
            for (uint32_t a = 0; a <= uint32_t(layout.grid); ++a) {
                std::set<uint32_t> rows;  // the values of b
                if (all_rows)
                    for (uint32_t b = 0; b <= a; ++b) rows.insert(b);
                else
                    for (uint32_t b : {0u, 1u, a / 2, a > 0 ? a - 1 : 0u, a})
                        if (b <= a) rows.insert(b);
                for (uint32_t b : rows) {
                    uint32_t row = tet(a) + tri(b);  // c = 0 .. b
                    for (uint32_t c : {0u, 1u, b > 0 ? b - 1 : 0u, b})
                        if (c <= b) indices.push_back(row + c);
                }
            }
            std::mt19937_64 rng(11);
            for (int i = 0; i < (1 << 20); ++i) indices.push_back(uint32_t(rng() % count));
        }
        // Corners chosen so that the decoded position is the weights (w1, w2, w3): C0 = 0 and the
        // unit vectors, anchor 0, scale 1. The store insists on real tetrahedra, so the corners
        // are overridden in a copy of the GPU record.
        DiamondId id = root_diamond();
        FragmentStore store;
        FeedbackDecoder decoder;
        const size_t chunk = size_t(1) << 20;
        size_t mismatches = 0;
        for (size_t start = 0; start < indices.size(); start += chunk) {
            size_t n = std::min(chunk, indices.size() - start);
            FragmentMesh f;
            f.layout = layout;
            f.vertices.resize(n);
            for (size_t i = 0; i < n; ++i)
                f.vertices[i] = PackedVertex::from_payload(indices[start + i], 0);  // the index, colour 0
            store.upload(id.bits, 0, f);
            GpuFragment g = *store.find(id.bits, 0);
            g.corners = {LatticePoint{0, 0, 0}, LatticePoint{1, 0, 0}, LatticePoint{0, 1, 0}, LatticePoint{0, 0, 1}};
            VertexDecodeParams params = params_for(g, layout, {0, 0, 0}, double(layout.grid));
            std::vector<float> gpu = decoder.decode(g, params);
            for (size_t i = 0; i < n; ++i) {
                BaryWeights w;
                ASSERT_TRUE(bary_unpack(indices[start + i], layout.grid, w));
                const float* p = &gpu[i * 9];
                if (p[0] != float(w[1]) || p[1] != float(w[2]) || p[2] != float(w[3])) {
                    if (mismatches++ < 5)
                        ADD_FAILURE() << layout.name() << " index " << indices[start + i] << ": GPU weights (" << p[0]
                                      << ", " << p[1] << ", " << p[2] << ") CPU (" << w[1] << ", " << w[2] << ", "
                                      << w[3] << ")";
                }
            }
        }
        std::printf("%s: %zu position indices checked%s, %zu mismatches\n", layout.name(), indices.size(),
                    exhaustive && layout.kind == VertexLayoutKind::Rgb24 ? " (all)" : "", mismatches);
        EXPECT_EQ(mismatches, 0u);
    }
}

// The layouts a dataset can be converted to.
const LayoutChoice kDatasetLayouts[] = {LayoutChoice::Rgb24, LayoutChoice::Rgb18, LayoutChoice::Position48};

// Real fragments of a sphere dataset in every layout: every vertex of the finest cut, at several
// anchors.
TEST(GpuDecode, PositionsAreBitIdenticalToTheCpuMirrorForDatasetFragments) {
    GL_TEST_CONTEXT();
    for (LayoutChoice choice : kDatasetLayouts) {
    CatpFile file(test::dataset_path(test::Model::Sphere, 20000, 5, choice));
    const CatpMeta& meta = file.index().meta();
    SCOPED_TRACE(meta.layout.name());
    StaticRenderer renderer(file);
    std::vector<DrawItem> items = renderer.draw_items(finest_cut(file.index()));
    ASSERT_GT(items.size(), 20u);
    renderer.upload(items);
    FeedbackDecoder decoder;
    Comparison c;
    std::map<uint64_t, DiamondFragments> nodes;
    for (const DrawItem& item : items) {
        auto it = nodes.find(item.diamond_key);
        if (it == nodes.end()) it = nodes.emplace(item.diamond_key, file.decode(*file.index().find(DiamondId{item.diamond_key}))).first;
        const FragmentMesh& f = it->second.slots[size_t(item.slot)];
        const GpuFragment* g = renderer.store().find(item.diamond_key, item.slot);
        ASSERT_NE(g, nullptr);
        for (const LatticePoint& anchor : test_anchors()) {
            const VertexDecodeParams params = params_for(*g, meta.layout, anchor, meta.cell);
            compare(f, decoder.decode(*g, params), params, c);
        }
    }
    report((std::string("sphere finest cut, ") + meta.layout.name()).c_str(), c);
    EXPECT_GT(c.vertices, 10000u);
    EXPECT_EQ(c.position_mismatches, 0u);
    EXPECT_LE(c.max_normal_error, 2e-7);
    }
}

// A vertex on a face shared by two tetrahedra (of different slots, diamonds and levels) has
// different weights in each, yet decodes to the same bits through the GPU path from both.
TEST(GpuDecode, SharedFaceVerticesAreBitIdenticalFromBothTetrahedra) {
    GL_TEST_CONTEXT();
    for (LayoutChoice choice : kDatasetLayouts) {
    CatpFile file(test::dataset_path(test::Model::Sphere, 40000, 6, choice));
    const CatpIndex& index = file.index();
    const CatpMeta& meta = index.meta();
    SCOPED_TRACE(meta.layout.name());

    // The finest cut and a mixed one (refined near a point on the surface), so shared faces
    // join tetrahedra of equal and of different levels.
    std::vector<RefinedSet> cuts{finest_cut(index)};
    {
        RefinedSet mixed;
        LatticePoint focus{kLatticeSize / 2, kLatticeSize / 2, int32_t(kLatticeSize * 0.75)};
        for (const ArchiveEntry& e : index.entries()) {
            if (e.flags & kCatpLeafFlag) continue;
            LatticePoint c = DiamondId{e.key}.centre();
            double d2 = 0;
            for (int i = 0; i < 3; ++i) d2 += double(c[i] - focus[i]) * double(c[i] - focus[i]);
            if (int(e.level) < int(meta.leaf_level) - 3 || d2 < double(kLatticeSize) * kLatticeSize * 0.01)
                mixed.refine(DiamondId{e.key});
        }
        cuts.push_back(mixed);
    }
    StaticRenderer renderer(file);
    FeedbackDecoder decoder;
    std::map<uint64_t, DiamondFragments> nodes;
    // Anchor: the lattice point nearest a camera close to the surface (what the renderer uses).
    const LatticePoint anchor{int32_t(kLatticeSize / 2), int32_t(kLatticeSize / 2), int32_t(kLatticeSize * 0.8)};
    size_t shared = 0, shared_other_diamond = 0, shared_other_level = 0, different_weights = 0, mismatches = 0;
    for (size_t ci = 0; ci < cuts.size(); ++ci) {
        std::vector<DrawItem> items = renderer.draw_items(cuts[ci]);
        renderer.upload(items);
        std::map<int, size_t> levels;
        for (const DrawItem& item : items) levels[diamond_level(DiamondId{item.diamond_key})]++;
        std::printf("cut %zu: %zu fragments, levels", ci, items.size());
        for (auto [level, n] : levels) std::printf(" %d:%zu", level, n);
        std::printf("\n");
        struct Seen {
            uint32_t x, y, z;
            uint64_t key;
            int slot;
            int level;
            BaryWeights w;
        };
        std::map<std::array<int64_t, 3>, Seen> first;
        for (const DrawItem& item : items) {
            auto it = nodes.find(item.diamond_key);
            if (it == nodes.end()) it = nodes.emplace(item.diamond_key, file.decode(*index.find(DiamondId{item.diamond_key}))).first;
            const FragmentMesh& f = it->second.slots[size_t(item.slot)];
            DiamondInfo info = diamond_info(DiamondId{item.diamond_key});
            std::vector<std::array<int64_t, 3>> exact;
            ASSERT_TRUE(decode_fragment_integer_positions(f, info, item.slot, exact));
            const GpuFragment* g = renderer.store().find(item.diamond_key, item.slot);
            ASSERT_NE(g, nullptr);
            std::vector<float> gpu = decoder.decode(*g, params_for(*g, meta.layout, anchor, meta.cell));
            for (size_t v = 0; v < exact.size(); ++v) {
                Seen s{bits(gpu[v * 9]), bits(gpu[v * 9 + 1]), bits(gpu[v * 9 + 2]), item.diamond_key, item.slot, info.level, {}};
                vertex_weights(f.vertices[v], f.layout, s.w);
                auto [at, inserted] = first.emplace(exact[v], s);
                if (inserted) continue;
                const Seen& o = at->second;
                if (o.key == s.key && o.slot == s.slot) continue;  // duplicate inside one fragment
                ++shared;
                shared_other_diamond += o.key != s.key;
                shared_other_level += o.level != s.level;
                different_weights += o.w != s.w;
                if (o.x != s.x || o.y != s.y || o.z != s.z) {
                    if (mismatches++ < 5)
                        ADD_FAILURE() << "shared vertex decodes differently from " << o.key << "/" << o.slot << " and "
                                      << s.key << "/" << s.slot;
                }
            }
        }
    }
    std::printf("%s: shared vertices compared: %zu (across diamonds %zu, across levels %zu, with different weights "
                "%zu), mismatches %zu\n",
                meta.layout.name(), shared, shared_other_diamond, shared_other_level, different_weights, mismatches);
    EXPECT_EQ(mismatches, 0u);
    EXPECT_GT(shared, 1000u);
    EXPECT_GT(shared_other_diamond, 100u);
    EXPECT_GT(shared_other_level, 10u);
    EXPECT_GT(different_weights, shared / 2);  // the same point, different corners and weights
    }
}
