// Offscreen framebuffer: RGBA8 + depth 24 renderbuffers, optional MSAA resolved on read.
#include <epoxy/gl.h>

#include <cstring>

#include "base/error.h"
#include "client/gl_context.h"

namespace catpaq {

static const char* framebuffer_status_name(GLenum status) {
    switch (status) {
    case GL_FRAMEBUFFER_COMPLETE: return "complete";
    case GL_FRAMEBUFFER_INCOMPLETE_ATTACHMENT: return "incomplete attachment";
    case GL_FRAMEBUFFER_INCOMPLETE_MISSING_ATTACHMENT: return "missing attachment";
    case GL_FRAMEBUFFER_UNSUPPORTED: return "unsupported";
    case GL_FRAMEBUFFER_INCOMPLETE_MULTISAMPLE: return "incomplete multisample";
    default: return "incomplete";
    }
}

static void make_target(int width, int height, int samples, bool with_depth, GLuint& fbo, GLuint& color, GLuint& depth) {
    glGenFramebuffers(1, &fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    glGenRenderbuffers(1, &color);
    glBindRenderbuffer(GL_RENDERBUFFER, color);
    if (samples > 0)
        glRenderbufferStorageMultisample(GL_RENDERBUFFER, samples, GL_RGBA8, width, height);
    else
        glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, width, height);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, color);
    if (with_depth) {
        glGenRenderbuffers(1, &depth);
        glBindRenderbuffer(GL_RENDERBUFFER, depth);
        if (samples > 0)
            glRenderbufferStorageMultisample(GL_RENDERBUFFER, samples, GL_DEPTH_COMPONENT24, width, height);
        else
            glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, width, height);
        glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth);
    }
}

Framebuffer::Framebuffer(int width, int height, int samples) : width_(width), height_(height), samples_(samples) {
    GLint max_size = 0;
    glGetIntegerv(GL_MAX_RENDERBUFFER_SIZE, &max_size);
    if (width <= 0 || height <= 0 || width > max_size || height > max_size)
        fail("framebuffer size %dx%d is out of range (1..%d)", width, height, int(max_size));
    if (samples < 0) fail("framebuffer samples must be >= 0, not %d", samples);
    if (samples > 0) {
        GLint max_samples = 0;
        glGetIntegerv(GL_MAX_SAMPLES, &max_samples);
        if (samples > max_samples) samples_ = samples = max_samples;
    }
    GLint previous = 0;
    glGetIntegerv(GL_FRAMEBUFFER_BINDING, &previous);
    make_target(width, height, samples, true, fbo_, color_, depth_);
    GLenum status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
    if (status == GL_FRAMEBUFFER_COMPLETE && samples > 0) {
        GLuint unused = 0;
        make_target(width, height, 0, false, resolve_fbo_, resolve_color_, unused);
        status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
    }
    glBindFramebuffer(GL_FRAMEBUFFER, GLuint(previous));
    if (status != GL_FRAMEBUFFER_COMPLETE) {
        GLuint fbos[2] = {fbo_, resolve_fbo_}, rbs[3] = {color_, depth_, resolve_color_};
        glDeleteFramebuffers(2, fbos);
        glDeleteRenderbuffers(3, rbs);
        fail("framebuffer %dx%d (%d samples) is %s", width, height, samples, framebuffer_status_name(status));
    }
}

Framebuffer::~Framebuffer() {
    GLuint fbos[2] = {fbo_, resolve_fbo_}, rbs[3] = {color_, depth_, resolve_color_};
    glDeleteFramebuffers(2, fbos);
    glDeleteRenderbuffers(3, rbs);
}

void Framebuffer::bind() {
    glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
    glViewport(0, 0, width_, height_);
}

void Framebuffer::blit_to_window() {
    glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo_);
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, 0);
    glBlitFramebuffer(0, 0, width_, height_, 0, 0, width_, height_, GL_COLOR_BUFFER_BIT, GL_NEAREST);
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
}

std::vector<uint8_t> Framebuffer::read_pixels() {
    GLuint source = fbo_;
    if (samples_ > 0) {
        glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo_);
        glBindFramebuffer(GL_DRAW_FRAMEBUFFER, resolve_fbo_);
        glBlitFramebuffer(0, 0, width_, height_, 0, 0, width_, height_, GL_COLOR_BUFFER_BIT, GL_NEAREST);
        source = resolve_fbo_;
    }
    glBindFramebuffer(GL_READ_FRAMEBUFFER, source);
    glReadBuffer(GL_COLOR_ATTACHMENT0);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    const size_t row = size_t(width_) * 4;
    std::vector<uint8_t> bottom_up(row * size_t(height_));
    for (int i = 0; i < 16 && glGetError() != GL_NO_ERROR; ++i) {
    }  // drop errors left by earlier calls
    glReadPixels(0, 0, width_, height_, GL_RGBA, GL_UNSIGNED_BYTE, bottom_up.data());
    GLenum error = glGetError();
    glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
    if (error != GL_NO_ERROR) fail("glReadPixels failed (GL error 0x%x)", unsigned(error));
    std::vector<uint8_t> top_down(bottom_up.size());
    for (int y = 0; y < height_; ++y)
        std::memcpy(top_down.data() + size_t(y) * row, bottom_up.data() + size_t(height_ - 1 - y) * row, row);
    return top_down;
}

}  // namespace catpaq
