// The GPU fragment store (VAOs with the packed 64-bit vertices, LRU under a byte budget) and
// the renderer (one draw call per fragment, canonical corners as uniforms).
#include "client/catp_gpu.h"

#include <epoxy/gl.h>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstddef>
#include <cstring>

#include <glm/gtc/type_ptr.hpp>

#include "base/error.h"
#include "catp/lattice.h"
#include "common_codec/packed_vertex.h"

namespace catpaq {

namespace {

// Checks that (key, slot) names an existing tetrahedron and returns its canonical corners.
std::array<LatticePoint, 4> slot_corners(uint64_t diamond_key, int slot) {
    DiamondId id{diamond_key};
    if (diamond_key >> 63 || !is_valid_diamond_centre(id.centre()))
        fail("diamond key %llu is not a valid diamond", (unsigned long long)diamond_key);
    if (slot < 0 || slot > 7) fail("slot %d of diamond %llu is out of range", slot, (unsigned long long)diamond_key);
    DiamondInfo info = diamond_info(id);
    if (!(existing_slots(info) & (1u << slot)))
        fail("slot %d of diamond %llu does not exist", slot, (unsigned long long)diamond_key);
    Tetrahedron t = canonical_tetrahedron(diamond_tetrahedron(info, slot));
    return {t[0], t[1], t[2], t[3]};
}

void validate_fragment(uint64_t diamond_key, int slot, const FragmentMesh& f) {
    if (f.vertices.size() > kFragmentMaxVertices || f.indices.size() / 3 > kFragmentMaxTriangles)
        fail("fragment %llu/%d is too large (%zu vertices, %zu indices)", (unsigned long long)diamond_key, slot,
             f.vertices.size(), f.indices.size());
    if (f.indices.size() % 3 != 0)
        fail("fragment %llu/%d has %zu indices, not a multiple of 3", (unsigned long long)diamond_key, slot, f.indices.size());
    const uint32_t n = uint32_t(f.vertices.size());
    for (uint32_t i : f.indices)
        if (i >= n) fail("fragment %llu/%d has index %u >= %u vertices", (unsigned long long)diamond_key, slot, i, n);
    if (!f.layout.valid()) fail("fragment %llu/%d has an invalid vertex layout", (unsigned long long)diamond_key, slot);
    for (size_t i = 0; i < f.vertices.size(); ++i) {
        BaryWeights w;
        if (!vertex_weights(f.vertices[i], f.layout, w))
            fail("fragment %llu/%d has a corrupt position in vertex %zu", (unsigned long long)diamond_key, slot, i);
    }
}

// Creates the VAO with an index buffer; the caller then describes the vertex attributes.
void create_buffers(GpuFragment& g, const void* vertices, size_t vertex_bytes, const std::vector<uint32_t>& indices) {
    glGenVertexArrays(1, &g.vao);
    glBindVertexArray(g.vao);
    glGenBuffers(1, &g.vbo);
    glBindBuffer(GL_ARRAY_BUFFER, g.vbo);
    glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(vertex_bytes), vertices, GL_STATIC_DRAW);
    glGenBuffers(1, &g.ibo);
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, g.ibo);
    g.index32 = g.vertex_count >= 65536;
    size_t index_bytes;
    if (g.index32) {
        index_bytes = indices.size() * 4;
        glBufferData(GL_ELEMENT_ARRAY_BUFFER, GLsizeiptr(index_bytes), indices.data(), GL_STATIC_DRAW);
    } else {
        std::vector<uint16_t> narrow(indices.begin(), indices.end());
        index_bytes = narrow.size() * 2;
        glBufferData(GL_ELEMENT_ARRAY_BUFFER, GLsizeiptr(index_bytes), narrow.data(), GL_STATIC_DRAW);
    }
    g.index_count = uint32_t(indices.size());
    g.bytes = vertex_bytes + index_bytes;
}

void delete_buffers(GpuFragment& g) {
    if (g.vao) glDeleteVertexArrays(1, &g.vao);
    GLuint buffers[2] = {g.vbo, g.ibo};
    glDeleteBuffers(2, buffers);
    g.vao = g.vbo = g.ibo = 0;
}

// Finishes an upload: unbinds, and turns a GL error (out of memory) into Error.
void finish_upload(GpuFragment& g, uint64_t diamond_key, int slot) {
    glBindVertexArray(0);
    glBindBuffer(GL_ARRAY_BUFFER, 0);
    GLenum error = glGetError();
    if (error != GL_NO_ERROR) {
        delete_buffers(g);
        fail("uploading fragment %llu/%d failed (GL error 0x%x%s)", (unsigned long long)diamond_key, slot, unsigned(error),
             error == GL_OUT_OF_MEMORY ? ": out of GPU memory" : "");
    }
}

void clear_gl_errors() {
    for (int i = 0; i < 16 && glGetError() != GL_NO_ERROR; ++i) {
    }
}

}  // namespace

// ---- FragmentStore ------------------------------------------------------------------------

FragmentStore::FragmentStore() = default;

FragmentStore::~FragmentStore() { clear(); }

void FragmentStore::upload(uint64_t diamond_key, int slot, const FragmentMesh& fragment) {
    std::array<LatticePoint, 4> corners = slot_corners(diamond_key, slot);
    validate_fragment(diamond_key, slot, fragment);
    clear_gl_errors();
    GpuFragment g;
    g.format = VertexFormat::Packed;
    g.corners = corners;
    g.vertex_count = uint32_t(fragment.vertices.size());
    static_assert(sizeof(PackedVertex) == kPackedVertexBytes, "uploaded as is");
    create_buffers(g, fragment.vertices.data(), fragment.vertices.size() * sizeof(PackedVertex), fragment.indices);
    // The 64-bit vertex is one uvec2: word0 = .x, word1 = .y (integer attribute, no conversion).
    glEnableVertexAttribArray(0);
    glVertexAttribIPointer(0, 2, GL_UNSIGNED_INT, kPackedVertexBytes, nullptr);
    finish_upload(g, diamond_key, slot);
    insert(Key{diamond_key, slot}, std::move(g));
}

void FragmentStore::upload_float(uint64_t diamond_key, int slot, const FragmentMesh& fragment, const CatpMeta& meta) {
    std::array<LatticePoint, 4> corners = slot_corners(diamond_key, slot);
    validate_fragment(diamond_key, slot, fragment);
    // Positions relative to the dataset origin in world units: anchor 0, scale cell / grid.
    VertexDecodeParams params;
    params.offsets = corners;
    params.layout = meta.layout;
    params.scale = float(meta.cell / meta.layout.grid);
    struct FloatVertex {
        float position[3];
        float normal[3];
        uint8_t color[4];
    };
    static_assert(sizeof(FloatVertex) == kFloatVertexBytes, "28 bytes per float vertex");
    std::vector<FloatVertex> vertices(fragment.vertices.size());
    for (size_t i = 0; i < vertices.size(); ++i) {
        DecodedVertex d;
        const PackedVertex& p = fragment.vertices[i];
        if (!decode_packed_vertex(p, params, d))
            fail("fragment %llu/%d has a corrupt vertex", (unsigned long long)diamond_key, slot);
        FloatVertex& v = vertices[i];
        std::memcpy(v.position, d.position, sizeof v.position);
        std::memcpy(v.normal, d.normal, sizeof v.normal);
        for (int k = 0; k < 3; ++k) v.color[k] = uint8_t(std::lround(d.color[k] * 255.0f));
        v.color[3] = 255;
    }
    clear_gl_errors();
    GpuFragment g;
    g.format = VertexFormat::Float;
    g.corners = corners;
    g.vertex_count = uint32_t(vertices.size());
    create_buffers(g, vertices.data(), vertices.size() * sizeof(FloatVertex), fragment.indices);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, kFloatVertexBytes, reinterpret_cast<const void*>(offsetof(FloatVertex, position)));
    glEnableVertexAttribArray(1);
    glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, kFloatVertexBytes, reinterpret_cast<const void*>(offsetof(FloatVertex, normal)));
    glEnableVertexAttribArray(2);
    glVertexAttribPointer(2, 4, GL_UNSIGNED_BYTE, GL_TRUE, kFloatVertexBytes, reinterpret_cast<const void*>(offsetof(FloatVertex, color)));
    finish_upload(g, diamond_key, slot);
    insert(Key{diamond_key, slot}, std::move(g));
}

void FragmentStore::insert(const Key& key, GpuFragment&& gpu) {
    auto it = entries_.find(key);
    if (it != entries_.end()) {
        gpu.pins = it->second.gpu.pins;  // replacing keeps the pins
        bytes_ -= it->second.gpu.bytes;
        destroy(it->second.gpu);
        lru_.erase(it->second.lru);
        entries_.erase(it);
    }
    gpu.last_used = frame_;
    bytes_ += gpu.bytes;
    Entry e;
    e.gpu = gpu;
    e.lru = lru_.insert(lru_.end(), key);
    entries_.emplace(key, std::move(e));
    evict_to_budget();
}

void FragmentStore::destroy(GpuFragment& gpu) { delete_buffers(gpu); }

void FragmentStore::touch(Entry& e) {
    e.gpu.last_used = frame_;
    lru_.splice(lru_.end(), lru_, e.lru);  // most recently used at the back
}

bool FragmentStore::resident(uint64_t diamond_key, int slot) const { return entries_.count(Key{diamond_key, slot}) != 0; }

const GpuFragment* FragmentStore::find(uint64_t diamond_key, int slot) const {
    auto it = entries_.find(Key{diamond_key, slot});
    return it == entries_.end() ? nullptr : &it->second.gpu;
}

bool FragmentStore::release(uint64_t diamond_key, int slot) {
    auto it = entries_.find(Key{diamond_key, slot});
    if (it == entries_.end()) return false;
    bytes_ -= it->second.gpu.bytes;
    destroy(it->second.gpu);
    lru_.erase(it->second.lru);
    entries_.erase(it);
    return true;
}

void FragmentStore::clear() {
    for (auto& [key, e] : entries_) destroy(e.gpu);
    entries_.clear();
    lru_.clear();
    bytes_ = 0;
}

void FragmentStore::set_budget(uint64_t bytes) {
    budget_ = bytes;
    evict_to_budget();
}

void FragmentStore::pin(uint64_t diamond_key, int slot) {
    auto it = entries_.find(Key{diamond_key, slot});
    if (it != entries_.end()) ++it->second.gpu.pins;
}

void FragmentStore::unpin(uint64_t diamond_key, int slot) {
    auto it = entries_.find(Key{diamond_key, slot});
    if (it != entries_.end() && it->second.gpu.pins > 0) --it->second.gpu.pins;
}

void FragmentStore::unpin_all() {
    for (auto& [key, e] : entries_) e.gpu.pins = 0;
}

void FragmentStore::mark_used(uint64_t diamond_key, int slot) {
    auto it = entries_.find(Key{diamond_key, slot});
    if (it != entries_.end()) touch(it->second);
}

size_t FragmentStore::evict_to_budget() {
    size_t evicted = 0;
    auto it = lru_.begin();
    while (over_budget() && it != lru_.end()) {
        Key key = *it++;
        Entry& e = entries_.at(key);
        if (e.gpu.pins > 0) continue;
        if (e.gpu.last_used >= frame_) break;  // the rest of the list was used this frame too
        bytes_ -= e.gpu.bytes;
        destroy(e.gpu);
        lru_.erase(e.lru);
        entries_.erase(key);
        ++evicted;
        if (on_evict_) {
            on_evict_(key.diamond, key.slot);
            // The callback may release other entries (the session drops a node's other slots
            // with it), the one `it` points to among them: start again from the oldest.
            it = lru_.begin();
        }
    }
    return evicted;
}

// ---- rendering ----------------------------------------------------------------------------

FrameTransform frame_transform(const Camera& camera, const CatpMeta& meta) {
    assert(camera.has_clip_planes());
    FrameTransform t;
    const glm::dvec3 origin(meta.origin[0], meta.origin[1], meta.origin[2]);
    // The lattice point nearest the eye, clamped to the lattice cube: anchor-relative sums stay
    // small near the camera, where precision matters.
    for (int i = 0; i < 3; ++i) {
        double l = std::nearbyint((camera.eye[i] - origin[i]) / meta.cell);
        if (!(l >= 0)) l = 0;  // also NaN
        if (l > kLatticeSize) l = kLatticeSize;
        t.anchor[i] = int32_t(l);
        t.anchor_world[i] = origin[i] + double(t.anchor[i]) * meta.cell;
    }
    t.scale = float(meta.cell / meta.layout.grid);
    t.decode.layout = meta.layout;
    t.decode.scale = t.scale;
    for (int k = 0; k < 3; ++k) t.decode.default_color[size_t(k)] = float((meta.default_rgb >> (8 * k)) & 0xff) / 255.0f;
    glm::dmat4 projection = camera.projection();
    t.mvp_packed = glm::mat4(projection * camera.view_relative(t.anchor_world));
    t.mvp_float = glm::mat4(projection * camera.view_relative(origin));
    return t;
}

VertexDecodeParams FrameTransform::params(const std::array<LatticePoint, 4>& corners) const {
    VertexDecodeParams p = decode;
    for (size_t i = 0; i < 4; ++i)
        for (size_t k = 0; k < 3; ++k) p.offsets[i][k] = corners[i][k] - anchor[k];
    return p;
}

static void find_uniforms(const GlProgram& p, int& corners, int& layout, int& grid, int& scale, int& default_color,
                          int& mvp, int& flat_mode, int& flat_color, int& light, int& ambient) {
    corners = p.uniform("corners");
    layout = p.uniform("vertex_layout");
    grid = p.uniform("grid");
    scale = p.uniform("scale");
    default_color = p.uniform("default_color");
    mvp = p.uniform("mvp");
    flat_mode = p.uniform("flat_mode");
    flat_color = p.uniform("flat_color");
    light = p.uniform("light_direction");
    ambient = p.uniform("ambient");
}

CatpRenderer::CatpRenderer(FragmentStore& store) : store_(store) {
    bool gles = current_context_is_gles();
    packed_ = GlProgram(shader_source(ShaderKind::CatpVertex, gles), shader_source(ShaderKind::Fragment, gles));
    float_ = GlProgram(shader_source(ShaderKind::FloatVertex, gles), shader_source(ShaderKind::Fragment, gles));
    for (auto [program, u] : {std::pair{&packed_, &packed_u_}, std::pair{&float_, &float_u_}})
        find_uniforms(*program, u->corners, u->layout, u->grid, u->scale, u->default_color, u->mvp, u->flat_mode,
                      u->flat_color, u->light, u->ambient);
    if (packed_u_.corners < 0 || packed_u_.layout < 0 || packed_u_.grid < 0 || packed_u_.scale < 0 ||
        packed_u_.default_color < 0 || packed_u_.mvp < 0)
        fail("the CATP vertex shader lacks its decode uniforms");
}

CatpRenderer::~CatpRenderer() = default;

void CatpRenderer::set_shading(const GlProgram&, const Uniforms& u, const RenderSettings& settings, const glm::vec3& light) const {
    glUniform1i(u.flat_mode, settings.flat ? 1 : 0);
    glUniform3f(u.flat_color, settings.flat_color[0], settings.flat_color[1], settings.flat_color[2]);
    glUniform3f(u.light, light.x, light.y, light.z);
    glUniform1f(u.ambient, settings.ambient);
}

RenderStats CatpRenderer::render(const Camera& camera_in, const CatpMeta& meta, const std::vector<DrawItem>& items,
                                 const RenderSettings& settings) {
    Camera camera = camera_in;
    if (!camera.has_clip_planes())
        camera.fit_clip_planes(glm::dvec3(meta.bounds_min[0], meta.bounds_min[1], meta.bounds_min[2]),
                               glm::dvec3(meta.bounds_max[0], meta.bounds_max[1], meta.bounds_max[2]));
    const FrameTransform t = frame_transform(camera, meta);
    const bool gles = current_context_is_gles();

    glViewport(0, 0, camera.width, camera.height);
    if (settings.clear) {
        glClearColor(settings.background[0], settings.background[1], settings.background[2], settings.background[3]);
        if (gles)
            glClearDepthf(1.0f);
        else
            glClearDepth(1.0);  // glClearDepthf is GL 4.1
        glDepthMask(GL_TRUE);
        glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    }
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LESS);
    glDisable(GL_BLEND);
    if (settings.cull_back_faces) {
        glEnable(GL_CULL_FACE);
        glCullFace(GL_BACK);
        glFrontFace(GL_CCW);
    } else {
        glDisable(GL_CULL_FACE);
    }
    if (!gles) glPolygonMode(GL_FRONT_AND_BACK, settings.wireframe ? GL_LINE : GL_FILL);

    glm::dvec3 light(settings.light_direction[0], settings.light_direction[1], settings.light_direction[2]);
    if (glm::length(light) > 0)
        light = glm::normalize(light);
    else
        light = -camera.forward();  // headlight
    const glm::vec3 light_f(light);

    RenderStats stats;
    std::vector<const GpuFragment*> float_items;
    glUseProgram(packed_.id());
    glUniform1i(packed_u_.layout, int(meta.layout.kind));
    glUniform1i(packed_u_.grid, meta.layout.grid);
    glUniform1f(packed_u_.scale, t.scale);
    glUniform3fv(packed_u_.default_color, 1, t.decode.default_color.data());
    glUniformMatrix4fv(packed_u_.mvp, 1, GL_FALSE, glm::value_ptr(t.mvp_packed));
    set_shading(packed_, packed_u_, settings, light_f);
    for (const DrawItem& item : items) {
        const GpuFragment* g = store_.find(item.diamond_key, item.slot);
        if (!g) {
            ++stats.missing;
            continue;
        }
        store_.mark_used(item.diamond_key, item.slot);
        if (g->format == VertexFormat::Float) {
            float_items.push_back(g);
            continue;
        }
        if (g->index_count == 0) continue;
        const VertexDecodeParams params = t.params(g->corners);
        glUniform3iv(packed_u_.corners, 4, params.offsets[0].data());
        glBindVertexArray(g->vao);
        glDrawElements(GL_TRIANGLES, GLsizei(g->index_count), g->index32 ? GL_UNSIGNED_INT : GL_UNSIGNED_SHORT, nullptr);
        ++stats.draws;
        stats.triangles += g->index_count / 3;
        stats.vertices += g->vertex_count;
    }
    if (!float_items.empty()) {
        glUseProgram(float_.id());
        glUniformMatrix4fv(float_u_.mvp, 1, GL_FALSE, glm::value_ptr(t.mvp_float));
        set_shading(float_, float_u_, settings, light_f);
        for (const GpuFragment* g : float_items) {
            if (g->index_count == 0) continue;
            glBindVertexArray(g->vao);
            glDrawElements(GL_TRIANGLES, GLsizei(g->index_count), g->index32 ? GL_UNSIGNED_INT : GL_UNSIGNED_SHORT, nullptr);
            ++stats.draws;
            stats.triangles += g->index_count / 3;
            stats.vertices += g->vertex_count;
        }
    }
    glBindVertexArray(0);
    glUseProgram(0);
    if (!gles && settings.wireframe) glPolygonMode(GL_FRONT_AND_BACK, GL_FILL);
    return stats;
}

}  // namespace catpaq
