// Headless contexts and framebuffers.
#include <gtest/gtest.h>
#include <epoxy/gl.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>

#include "base/error.h"
#include "catp_client/catp_gpu.h"
#include "client/gl_context.h"
#include "client/gl_program.h"
#include "gl_support.h"

using namespace catpaq;

TEST(HeadlessGl, CreatesACoreContext) {
    GL_TEST_CONTEXT();
    HeadlessGlContext* ctx = test::gl_context(nullptr);
    std::printf("platform %s, renderer %s, version %s\n", ctx->platform().c_str(), ctx->renderer().c_str(),
                ctx->version().c_str());
    EXPECT_FALSE(ctx->renderer().empty());
    if (!ctx->is_gles()) {
        EXPECT_GE(epoxy_gl_version(), 33);
        GLint mask = 0;
        glGetIntegerv(GL_CONTEXT_PROFILE_MASK, &mask);
        EXPECT_TRUE(mask & GL_CONTEXT_CORE_PROFILE_BIT);
    }
    EXPECT_TRUE(HeadlessGlContext::available());
}

TEST(HeadlessGl, DevicePlatformWorksOrFailsWithAnError) {
    GL_TEST_CONTEXT();
    GlContextOptions options;
    options.platform = EglPlatform::Device;
    try {
        HeadlessGlContext device(options);
        EXPECT_EQ(device.platform().rfind("device", 0), 0u) << device.platform();
        Framebuffer fb(8, 8);
        fb.bind();
        glClearColor(0, 1, 0, 1);
        glClear(GL_COLOR_BUFFER_BIT);
        std::vector<uint8_t> px = fb.read_pixels();
        EXPECT_EQ(px[1], 255);
    } catch (const Error& e) {
        std::printf("device platform unavailable: %s\n", e.what());  // allowed: it is a fallback
    }
    test::gl_context(nullptr);  // the shared context is current again
}

TEST(Framebuffer, ReadsRowsTopDown) {
    GL_TEST_CONTEXT();
    Framebuffer fb(16, 12);
    fb.bind();
    glDisable(GL_SCISSOR_TEST);
    glClearColor(1, 0, 0, 1);
    glClear(GL_COLOR_BUFFER_BIT);
    glEnable(GL_SCISSOR_TEST);
    glScissor(0, 12 - 3, 16, 3);  // GL's origin is bottom-left: this is the top 3 rows
    glClearColor(0, 0, 1, 1);
    glClear(GL_COLOR_BUFFER_BIT);
    glDisable(GL_SCISSOR_TEST);
    std::vector<uint8_t> px = fb.read_pixels();
    ASSERT_EQ(px.size(), 16u * 12 * 4);
    for (int y = 0; y < 12; ++y) {
        const uint8_t* p = &px[size_t(y) * 16 * 4 + 5 * 4];
        bool top = y < 3;
        EXPECT_EQ(p[0], top ? 0 : 255) << "row " << y;
        EXPECT_EQ(p[2], top ? 255 : 0) << "row " << y;
        EXPECT_EQ(p[3], 255);
    }
}

TEST(Framebuffer, MultisampledTargetResolvesOnRead) {
    GL_TEST_CONTEXT();
    Framebuffer fb(32, 16, 4);
    EXPECT_GE(fb.samples(), 0);
    fb.bind();
    glClearColor(0.5f, 0.25f, 1, 1);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    std::vector<uint8_t> px = fb.read_pixels();
    EXPECT_NEAR(px[0], 128, 1);
    EXPECT_NEAR(px[1], 64, 1);
    EXPECT_EQ(px[2], 255);
}

TEST(Framebuffer, RefusesBadSizes) {
    GL_TEST_CONTEXT();
    EXPECT_THROW(Framebuffer(0, 10), Error);
    EXPECT_THROW(Framebuffer(10, -1), Error);
    EXPECT_THROW(Framebuffer(1 << 20, 4), Error);
}

TEST(Shaders, EmbeddedSourcesCompile) {
    GL_TEST_CONTEXT();
    bool gles = current_context_is_gles();
    std::string vs = catp_shader_source(CatpShader::PackedVertex, gles);
    EXPECT_NE(vs.find("bary_unpack"), std::string::npos);  // catp_decode.glsl is included
    EXPECT_NE(vs.find("in uvec2 a_packed"), std::string::npos);
    GlProgram packed(vs, catp_shader_source(CatpShader::Fragment, gles));
    GlProgram floats(catp_shader_source(CatpShader::FloatVertex, gles), catp_shader_source(CatpShader::Fragment, gles));
    EXPECT_GE(packed.uniform("corners"), 0);
    for (const char* name : {"vertex_layout", "grid", "scale", "default_color"}) EXPECT_GE(packed.uniform(name), 0) << name;
    EXPECT_GE(floats.uniform("mvp"), 0);
    // A broken shader reports the compiler's log.
    try {
        GlProgram broken(catp_shader_source(CatpShader::FloatVertex, gles) + "\nthis is not glsl;\n",
                         catp_shader_source(CatpShader::Fragment, gles));
        ADD_FAILURE() << "compiled garbage";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("vertex shader does not compile"), std::string::npos) << e.what();
    }
}

// Without any EGL driver (glvnd pointed at no vendor library) contexts fail with an Error that
// names every attempt, and GL tests would skip: checked in a child process, because the EGL
// library reads its vendor list once per process.
TEST(HeadlessGl, NoDriverGivesAClearError) {
    if (std::getenv("CATPAQ_EGL_CHILD")) {
        try {
            HeadlessGlContext context;
            std::printf("CHILD: unexpectedly created a context on %s\n", context.platform().c_str());
        } catch (const Error& e) {
            std::printf("CHILD ERROR: %s\n", e.what());
        }
        std::string why;
        std::printf("CHILD AVAILABLE: %d\n", int(HeadlessGlContext::available(&why)));
        return;
    }
    std::string command =
        "__EGL_VENDOR_LIBRARY_FILENAMES=/nonexistent/vendor.json __EGL_VENDOR_LIBRARY_DIRS=/nonexistent "
        "CATPAQ_EGL_CHILD=1 /proc/" +
        std::to_string(getpid()) + "/exe --gtest_filter=HeadlessGl.NoDriverGivesAClearError 2>&1";
    FILE* pipe = popen(command.c_str(), "r");
    ASSERT_NE(pipe, nullptr);
    std::string output;
    char buffer[4096];
    size_t n;
    while ((n = fread(buffer, 1, sizeof buffer, pipe)) > 0) output.append(buffer, n);
    int status = pclose(pipe);
    EXPECT_EQ(status, 0) << output;
    EXPECT_NE(output.find("CHILD ERROR: cannot create a headless OpenGL"), std::string::npos) << output;
    EXPECT_NE(output.find("CHILD AVAILABLE: 0"), std::string::npos) << output;
    std::printf("%s", output.substr(output.find("CHILD ERROR"), output.find('\n', output.find("CHILD ERROR")) - output.find("CHILD ERROR") + 1).c_str());
}
