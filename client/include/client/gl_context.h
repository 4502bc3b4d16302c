#pragma once
// Headless OpenGL: an EGL context without any window system, and an offscreen framebuffer.
//
// HeadlessGlContext tries, in order, the surfaceless Mesa platform
// (eglGetPlatformDisplay(EGL_PLATFORM_SURFACELESS_MESA)), the device platform
// (EGL_PLATFORM_DEVICE_EXT on each device eglQueryDevicesEXT lists) and finally the default
// display, and makes a desktop OpenGL 3.3 core context current with no surface
// (EGL_KHR_surfaceless_context); if no desktop GL context can be created it tries OpenGL ES 3.0.
// GL functions are then loaded through libepoxy. If no display or context can be made it throws
// catpaq::Error saying what each attempt returned; it never aborts the process.
//
// The context is current on the constructing thread. GL objects (Framebuffer, FragmentStore,
// ...) must be destroyed while it is current, before the context itself.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace catpaq {

enum class EglPlatform { Auto, Surfaceless, Device, Default };

// Auto: desktop OpenGL 3.3 core, else OpenGL ES 3.0. Desktop / Gles: only that API.
enum class GlApi { Auto, Desktop, Gles };

struct GlContextOptions {
    EglPlatform platform = EglPlatform::Auto;  // Auto: surfaceless, then device, then default
    GlApi api = GlApi::Auto;
    bool debug = false;                        // request a debug context
};

class HeadlessGlContext {
public:
    explicit HeadlessGlContext(const GlContextOptions& options = {});  // throws Error
    ~HeadlessGlContext();
    HeadlessGlContext(const HeadlessGlContext&) = delete;
    HeadlessGlContext& operator=(const HeadlessGlContext&) = delete;

    void make_current();  // throws Error if EGL refuses
    bool is_gles() const;
    const std::string& platform() const;  // "surfaceless", "device 0", "default"
    std::string renderer() const;         // GL_RENDERER
    std::string version() const;          // GL_VERSION

    // True if a context can be created; otherwise false with the reason (for GTEST_SKIP).
    static bool available(std::string* why = nullptr);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// An offscreen render target: RGBA8 colour and 24-bit depth renderbuffers, optionally
// multisampled (resolved on read). Needs a current GL context.
class Framebuffer {
public:
    Framebuffer(int width, int height, int samples = 0);  // throws Error if incomplete
    ~Framebuffer();
    Framebuffer(const Framebuffer&) = delete;
    Framebuffer& operator=(const Framebuffer&) = delete;

    void bind();  // binds for drawing and sets the viewport to the whole target
    // Copies the image (resolved, when multisampled) to the window's framebuffer (object 0),
    // whose size must be the same.
    void blit_to_window();
    // The colour buffer as RGBA8, rows top-down (row 0 is the top of the image).
    std::vector<uint8_t> read_pixels();

    int width() const { return width_; }
    int height() const { return height_; }
    int samples() const { return samples_; }

private:
    int width_, height_, samples_;
    unsigned fbo_ = 0, color_ = 0, depth_ = 0;
    unsigned resolve_fbo_ = 0, resolve_color_ = 0;  // when multisampled
};

}  // namespace catpaq
