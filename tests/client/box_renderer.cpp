#include "box_renderer.h"

#include <epoxy/gl.h>

#include <list>
#include <unordered_map>

#include <glm/gtc/type_ptr.hpp>

#include "base/error.h"
#include "client/gl_program.h"
#include "client/hierarchy.h"

namespace catpaq::test {

namespace {

const char* kVertex = R"(
layout(location = 0) in vec3 position;
uniform mat4 mvp;
void main() { gl_Position = mvp * vec4(position, 1.0); }
)";

const char* kFragment = R"(
uniform vec3 color;
out vec4 frag_color;
void main() { frag_color = vec4(color, 1.0); }
)";

class BoxRenderer : public NodeRenderer {
public:
    explicit BoxRenderer(const BoxFormat& format) : bounds_(format.world_bounds()) {
        bool gles = current_context_is_gles();
        program_ = GlProgram(shader_preamble(gles) + kVertex, shader_preamble(gles) + kFragment);
        mvp_ = program_.uniform("mvp");
        color_ = program_.uniform("color");
    }
    ~BoxRenderer() override {
        for (auto& [key, e] : entries_) destroy(e);
    }

    void upload(const HierarchyNode& node, const DecodedNode& decoded) override {
        const auto& box = dynamic_cast<const BoxNode&>(decoded);
        if (box.corners.empty()) return;
        release(node.key, 0);
        Entry e;
        glGenVertexArrays(1, &e.vao);
        glBindVertexArray(e.vao);
        glGenBuffers(1, &e.vbo);
        glBindBuffer(GL_ARRAY_BUFFER, e.vbo);
        glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(box.corners.size() * sizeof(float)), box.corners.data(), GL_STATIC_DRAW);
        glEnableVertexAttribArray(0);
        glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 12, nullptr);
        glBindVertexArray(0);
        glBindBuffer(GL_ARRAY_BUFFER, 0);
        e.vertices = GLsizei(box.corners.size() / 3);
        e.bytes = box.corners.size() * sizeof(float);
        e.last_used = frame_;
        e.lru = lru_.insert(lru_.end(), node.key);
        bytes_ += e.bytes;
        entries_.emplace(node.key, e);
        evict_to_budget();
    }
    bool resident(uint64_t key, uint8_t part) const override { return part == 0 && entries_.count(key); }
    void release(uint64_t key, uint8_t) override {
        auto it = entries_.find(key);
        if (it == entries_.end()) return;
        destroy(it->second);
        entries_.erase(it);
    }
    void begin_frame() override { ++frame_; }
    void unpin_all() override {
        for (auto& [key, e] : entries_) e.pinned = false;
    }
    void pin(uint64_t key, uint8_t) override {
        if (auto it = entries_.find(key); it != entries_.end()) it->second.pinned = true;
    }
    void mark_used(uint64_t key, uint8_t) override {
        if (auto it = entries_.find(key); it != entries_.end()) {
            it->second.last_used = frame_;
            lru_.splice(lru_.end(), lru_, it->second.lru);
        }
    }
    size_t evict_to_budget() override {
        size_t evicted = 0;
        for (auto it = lru_.begin(); budget_ && bytes_ > budget_ && it != lru_.end();) {
            uint64_t key = *it++;
            Entry& e = entries_.at(key);
            if (e.pinned) continue;
            if (e.last_used >= frame_) break;  // the rest were used this frame too
            destroy(e);
            entries_.erase(key);
            ++evicted;
            if (on_evict_) {
                on_evict_(key, 0);
                it = lru_.begin();  // the callback may release others
            }
        }
        return evicted;
    }
    void set_budget(uint64_t bytes) override {
        budget_ = bytes;
        evict_to_budget();
    }
    uint64_t gpu_bytes() const override { return bytes_; }
    void set_eviction_callback(std::function<void(uint64_t key, uint8_t part)> callback) override {
        on_evict_ = std::move(callback);
    }

    RenderStats draw(const Camera& camera_in, const std::vector<DrawnPart>& parts, const RenderSettings& settings) override {
        Camera camera = camera_in;
        if (!camera.has_clip_planes())
            camera.fit_clip_planes({bounds_.min[0], bounds_.min[1], bounds_.min[2]}, {bounds_.max[0], bounds_.max[1], bounds_.max[2]});
        glViewport(0, 0, camera.width, camera.height);
        if (settings.clear) {
            glClearColor(settings.background[0], settings.background[1], settings.background[2], settings.background[3]);
            glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
        }
        glEnable(GL_DEPTH_TEST);
        glDisable(GL_CULL_FACE);
        glUseProgram(program_.id());
        const glm::mat4 mvp(camera.projection() * camera.view());
        glUniformMatrix4fv(mvp_, 1, GL_FALSE, glm::value_ptr(mvp));
        glUniform3f(color_, kBoxColor[0] / 255.0f, kBoxColor[1] / 255.0f, kBoxColor[2] / 255.0f);
        RenderStats stats;
        for (const DrawnPart& p : parts) {
            auto it = entries_.find(p.key);
            if (it == entries_.end() || p.part != 0) {
                ++stats.missing;
                continue;
            }
            mark_used(p.key, 0);
            glBindVertexArray(it->second.vao);
            glDrawArrays(GL_TRIANGLES, 0, it->second.vertices);
            ++stats.draws;
            stats.triangles += size_t(it->second.vertices / 3);
            stats.vertices += size_t(it->second.vertices);
        }
        glBindVertexArray(0);
        glUseProgram(0);
        return stats;
    }

private:
    struct Entry {
        unsigned vao = 0, vbo = 0;
        GLsizei vertices = 0;
        uint64_t bytes = 0;
        bool pinned = false;
        uint64_t last_used = 0;
        std::list<uint64_t>::iterator lru;  // front: least recently used
    };
    void destroy(Entry& e) {
        glDeleteVertexArrays(1, &e.vao);
        glDeleteBuffers(1, &e.vbo);
        bytes_ -= e.bytes;
        lru_.erase(e.lru);
    }

    Aabb bounds_;
    GlProgram program_;
    int mvp_ = -1, color_ = -1;
    std::unordered_map<uint64_t, Entry> entries_;
    std::list<uint64_t> lru_;
    uint64_t bytes_ = 0, budget_ = 0, frame_ = 1;
    std::function<void(uint64_t, uint8_t)> on_evict_;
};

}  // namespace

std::unique_ptr<NodeRenderer> create_box_renderer(const DatasetFormat& format) {
    return std::make_unique<BoxRenderer>(dynamic_cast<const BoxFormat&>(format));
}

FormatModule box_format_module_with_renderer() {
    FormatModule m = box_format_module();
    m.create_renderer = create_box_renderer;
    return m;
}

}  // namespace catpaq::test
