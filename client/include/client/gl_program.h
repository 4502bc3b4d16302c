#pragma once
// GLSL programs built from the shaders embedded at build time (shaders/ in the source tree).
// Needs a current GL context (client/gl_context.h). No GL header is included here.
#include <string>
#include <vector>

namespace catpaq {

enum class ShaderKind {
    CatpVertex,   // shaders/catp_decode.glsl + shaders/catp.vert: decodes the 64-bit vertex
    FloatVertex,  // shaders/float.vert: the float comparison path
    Fragment,     // shaders/catp.frag: Lambert + ambient, or flat colour
};

// The complete source for the current context: a version preamble (#version 330 core, with
// `precise` from ARB_gpu_shader5 when available; or #version 300 es with highp defaults), then
// the embedded files.
std::string shader_source(ShaderKind kind, bool gles);
// True if the current context is OpenGL ES.
bool current_context_is_gles();

class GlProgram {
public:
    GlProgram() = default;
    // Compiles and links; `feedback_varyings` are captured interleaved by transform feedback.
    // Throws Error with the compiler's log.
    GlProgram(const std::string& vertex_source, const std::string& fragment_source,
              const std::vector<std::string>& feedback_varyings = {});
    ~GlProgram();
    GlProgram(GlProgram&& other) noexcept;
    GlProgram& operator=(GlProgram&& other) noexcept;
    GlProgram(const GlProgram&) = delete;
    GlProgram& operator=(const GlProgram&) = delete;

    unsigned id() const { return id_; }
    int uniform(const char* name) const;  // location, -1 if the program has no such active uniform

private:
    unsigned id_ = 0;
};

}  // namespace catpaq
