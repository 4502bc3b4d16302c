// GLSL programs: the preamble every shader starts with, compiling and linking.
#include "client/gl_program.h"

#include <epoxy/gl.h>

#include <algorithm>
#include <cstring>

#include "base/error.h"

namespace catpaq {

bool current_context_is_gles() { return !epoxy_is_desktop_gl(); }

std::string shader_preamble(bool gles) {
    if (gles) {
        return "#version 300 es\n"
               "precision highp float;\n"
               "precision highp int;\n"
               "#define PRECISE\n";
    }
    // `precise` (ARB_gpu_shader5, core in 4.0) keeps the decoded position's multiply from
    // being fused or reassociated; without it the decode is still exact in practice (integer
    // sums and one multiply feeding the invariant gl_Position).
    return "#version 330 core\n"
           "#extension GL_ARB_gpu_shader5 : enable\n"
           "#ifdef GL_ARB_gpu_shader5\n"
           "#define PRECISE precise\n"
           "#else\n"
           "#define PRECISE\n"
           "#endif\n";
}

static std::string shader_log(GLuint shader) {
    GLint length = 0;
    glGetShaderiv(shader, GL_INFO_LOG_LENGTH, &length);
    std::string log(size_t(std::max(length, 1)), '\0');
    glGetShaderInfoLog(shader, GLsizei(log.size()), nullptr, log.data());
    log.resize(std::strlen(log.c_str()));
    return log;
}

static std::string program_log(GLuint program) {
    GLint length = 0;
    glGetProgramiv(program, GL_INFO_LOG_LENGTH, &length);
    std::string log(size_t(std::max(length, 1)), '\0');
    glGetProgramInfoLog(program, GLsizei(log.size()), nullptr, log.data());
    log.resize(std::strlen(log.c_str()));
    return log;
}

static GLuint compile(GLenum type, const std::string& source) {
    GLuint shader = glCreateShader(type);
    const char* text = source.c_str();
    glShaderSource(shader, 1, &text, nullptr);
    glCompileShader(shader);
    GLint ok = 0;
    glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
    if (!ok) {
        std::string log = shader_log(shader);
        glDeleteShader(shader);
        fail("%s shader does not compile (file numbers: 1 catp_decode.glsl, 2 catp.vert, 3 float.vert, 4 catp.frag):\n%s",
             type == GL_VERTEX_SHADER ? "vertex" : "fragment", log.c_str());
    }
    return shader;
}

GlProgram::GlProgram(const std::string& vertex_source, const std::string& fragment_source,
                     const std::vector<std::string>& feedback_varyings) {
    GLuint vs = compile(GL_VERTEX_SHADER, vertex_source);
    GLuint fs = 0;
    try {
        fs = compile(GL_FRAGMENT_SHADER, fragment_source);
    } catch (...) {
        glDeleteShader(vs);
        throw;
    }
    id_ = glCreateProgram();
    glAttachShader(id_, vs);
    glAttachShader(id_, fs);
    if (!feedback_varyings.empty()) {
        std::vector<const char*> names;
        for (const std::string& v : feedback_varyings) names.push_back(v.c_str());
        glTransformFeedbackVaryings(id_, GLsizei(names.size()), names.data(), GL_INTERLEAVED_ATTRIBS);
    }
    glLinkProgram(id_);
    glDetachShader(id_, vs);
    glDetachShader(id_, fs);
    glDeleteShader(vs);
    glDeleteShader(fs);
    GLint ok = 0;
    glGetProgramiv(id_, GL_LINK_STATUS, &ok);
    if (!ok) {
        std::string log = program_log(id_);
        glDeleteProgram(id_);
        id_ = 0;
        fail("GLSL program does not link:\n%s", log.c_str());
    }
}

GlProgram::~GlProgram() {
    if (id_) glDeleteProgram(id_);
}

GlProgram::GlProgram(GlProgram&& other) noexcept : id_(other.id_) { other.id_ = 0; }

GlProgram& GlProgram::operator=(GlProgram&& other) noexcept {
    if (this != &other) {
        if (id_) glDeleteProgram(id_);
        id_ = other.id_;
        other.id_ = 0;
    }
    return *this;
}

int GlProgram::uniform(const char* name) const { return glGetUniformLocation(id_, name); }

}  // namespace catpaq
