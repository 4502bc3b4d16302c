#pragma once
// GLSL programs.
// Needs a current GL context (client/gl_context.h). No GL header is included here.
#include <string>
#include <vector>

namespace catpaq {

// The start of every shader source for the current context: the version line (#version 330
// core, with `precise` from ARB_gpu_shader5 when available, defined as PRECISE; or #version 300
// es with highp defaults). Formats append their shaders (CATP: catp_shader_source,
// catp_client/catp_gpu.h, from the files in shaders/ embedded at build time).
std::string shader_preamble(bool gles);
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
