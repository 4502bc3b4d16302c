// The EGL side of HeadlessGlContext: display, config, context, surfaceless make-current.
// EGL is called directly (libEGL from glvnd/Mesa); GL functions go through libepoxy.
#include "client/gl_context.h"

#include <EGL/egl.h>
#include <EGL/eglext.h>

#include <cstring>
#include <map>
#include <mutex>
#include <vector>

#include "base/error.h"
#include "gl_query.h"

namespace catpaq {

namespace {

const char* egl_error_name(EGLint e) {
    switch (e) {
    case EGL_SUCCESS: return "EGL_SUCCESS";
    case EGL_NOT_INITIALIZED: return "EGL_NOT_INITIALIZED";
    case EGL_BAD_ACCESS: return "EGL_BAD_ACCESS";
    case EGL_BAD_ALLOC: return "EGL_BAD_ALLOC";
    case EGL_BAD_ATTRIBUTE: return "EGL_BAD_ATTRIBUTE";
    case EGL_BAD_CONFIG: return "EGL_BAD_CONFIG";
    case EGL_BAD_CONTEXT: return "EGL_BAD_CONTEXT";
    case EGL_BAD_CURRENT_SURFACE: return "EGL_BAD_CURRENT_SURFACE";
    case EGL_BAD_DISPLAY: return "EGL_BAD_DISPLAY";
    case EGL_BAD_MATCH: return "EGL_BAD_MATCH";
    case EGL_BAD_NATIVE_PIXMAP: return "EGL_BAD_NATIVE_PIXMAP";
    case EGL_BAD_NATIVE_WINDOW: return "EGL_BAD_NATIVE_WINDOW";
    case EGL_BAD_PARAMETER: return "EGL_BAD_PARAMETER";
    case EGL_BAD_SURFACE: return "EGL_BAD_SURFACE";
    case EGL_CONTEXT_LOST: return "EGL_CONTEXT_LOST";
    default: return "unknown EGL error";
    }
}

std::string last_egl_error() {
    EGLint e = eglGetError();
    return strprintf("%s (0x%x)", egl_error_name(e), unsigned(e));
}

bool has_extension(const char* list, const char* name) {
    if (!list) return false;
    size_t n = std::strlen(name);
    for (const char* p = list; (p = std::strstr(p, name)) != nullptr; p += n) {
        bool starts = p == list || p[-1] == ' ';
        bool ends = p[n] == ' ' || p[n] == '\0';
        if (starts && ends) return true;
    }
    return false;
}

// EGL displays are per-process singletons: eglTerminate would kill every context on the same
// display, so displays are reference-counted across HeadlessGlContext objects.
std::mutex g_display_mutex;
std::map<EGLDisplay, int> g_display_users;

void acquire_display(EGLDisplay dpy) {
    std::lock_guard<std::mutex> lock(g_display_mutex);
    ++g_display_users[dpy];
}

void release_display(EGLDisplay dpy) {
    std::lock_guard<std::mutex> lock(g_display_mutex);
    auto it = g_display_users.find(dpy);
    if (it == g_display_users.end()) return;
    if (--it->second == 0) {
        g_display_users.erase(it);
        eglTerminate(dpy);
    }
}

struct Candidate {
    std::string name;
    EGLDisplay display;
};

}  // namespace

struct HeadlessGlContext::Impl {
    EGLDisplay display = EGL_NO_DISPLAY;
    EGLContext context = EGL_NO_CONTEXT;
    std::string platform;
    bool gles = false;
};

// Creates a context of the requested API on an initialized display; EGL_NO_CONTEXT on failure
// with the reason appended to `log`.
static EGLContext create_context(EGLDisplay dpy, bool gles, bool debug, std::string& log) {
    if (!eglBindAPI(gles ? EGL_OPENGL_ES_API : EGL_OPENGL_API)) {
        log += strprintf(" eglBindAPI(%s): %s;", gles ? "ES" : "GL", last_egl_error().c_str());
        return EGL_NO_CONTEXT;
    }
    const char* extensions = eglQueryString(dpy, EGL_EXTENSIONS);
    EGLint renderable = gles ? EGL_OPENGL_ES3_BIT_KHR : EGL_OPENGL_BIT;
    EGLConfig config = nullptr;
    EGLint count = 0;
    // Surfaceless displays may have no window-capable configs: ask for any surface type.
    const EGLint config_attribs[] = {EGL_RENDERABLE_TYPE, renderable, EGL_SURFACE_TYPE, 0,
                                     EGL_RED_SIZE, 8, EGL_GREEN_SIZE, 8, EGL_BLUE_SIZE, 8, EGL_NONE};
    bool have_config = eglChooseConfig(dpy, config_attribs, &config, 1, &count) && count > 0;
    if (!have_config) {
        if (!has_extension(extensions, "EGL_KHR_no_config_context")) {
            log += strprintf(" no EGL config for %s;", gles ? "OpenGL ES 3" : "OpenGL");
            return EGL_NO_CONTEXT;
        }
        config = EGL_NO_CONFIG_KHR;
    }
    std::vector<EGLint> attribs;
    if (gles) {
        attribs = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 0};
    } else {
        attribs = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 3, EGL_CONTEXT_OPENGL_PROFILE_MASK,
                   EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT};
    }
    if (debug) attribs.insert(attribs.end(), {EGL_CONTEXT_OPENGL_DEBUG, EGL_TRUE});
    attribs.push_back(EGL_NONE);
    EGLContext ctx = eglCreateContext(dpy, config, EGL_NO_CONTEXT, attribs.data());
    if (ctx == EGL_NO_CONTEXT)
        log += strprintf(" eglCreateContext(%s): %s;", gles ? "OpenGL ES 3.0" : "OpenGL 3.3 core", last_egl_error().c_str());
    return ctx;
}

HeadlessGlContext::HeadlessGlContext(const GlContextOptions& options) : impl_(new Impl) {
    std::string log;
    const char* client_extensions = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
    if (!client_extensions) eglGetError();  // EGL < 1.5 without client extensions: not an error for us
    auto get_platform_display = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(
        has_extension(client_extensions, "EGL_EXT_platform_base") ? eglGetProcAddress("eglGetPlatformDisplayEXT") : nullptr);

    // Displays to try, in order, created lazily.
    auto try_display = [&](const std::string& name, EGLDisplay dpy) -> bool {
        if (dpy == EGL_NO_DISPLAY) {
            log += strprintf(" %s: no display (%s);", name.c_str(), last_egl_error().c_str());
            return false;
        }
        EGLint major = 0, minor = 0;
        if (!eglInitialize(dpy, &major, &minor)) {
            log += strprintf(" %s: eglInitialize: %s;", name.c_str(), last_egl_error().c_str());
            return false;
        }
        acquire_display(dpy);
        const char* extensions = eglQueryString(dpy, EGL_EXTENSIONS);
        if (!has_extension(extensions, "EGL_KHR_surfaceless_context")) {
            log += strprintf(" %s: no EGL_KHR_surfaceless_context;", name.c_str());
            release_display(dpy);
            return false;
        }
        bool gles = false;
        EGLContext ctx = EGL_NO_CONTEXT;
        if (options.api != GlApi::Gles) ctx = create_context(dpy, false, options.debug, log);
        if (ctx == EGL_NO_CONTEXT && options.api != GlApi::Desktop) {
            ctx = create_context(dpy, true, options.debug, log);
            gles = ctx != EGL_NO_CONTEXT;
        }
        if (ctx == EGL_NO_CONTEXT) {
            log += strprintf(" (on %s);", name.c_str());
            release_display(dpy);
            return false;
        }
        if (!eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx)) {
            log += strprintf(" %s: eglMakeCurrent: %s;", name.c_str(), last_egl_error().c_str());
            eglDestroyContext(dpy, ctx);
            release_display(dpy);
            return false;
        }
        // Check what we got through epoxy (which now resolves GL through this EGL context).
        bool desktop = false;
        int version = detail::current_gl_version(desktop);
        if ((desktop && version < 33) || (!desktop && version < 30) || desktop == gles) {
            log += strprintf(" %s: context is %s %d.%d;", name.c_str(), desktop ? "OpenGL" : "OpenGL ES", version / 10,
                             version % 10);
            eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
            eglDestroyContext(dpy, ctx);
            release_display(dpy);
            return false;
        }
        impl_->display = dpy;
        impl_->context = ctx;
        impl_->platform = name;
        impl_->gles = gles || !desktop;
        return true;
    };

    bool want_all = options.platform == EglPlatform::Auto;
    if (want_all || options.platform == EglPlatform::Surfaceless) {
        if (get_platform_display && has_extension(client_extensions, "EGL_MESA_platform_surfaceless")) {
            if (try_display("surfaceless", get_platform_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr)))
                return;
        } else {
            log += " surfaceless: EGL_MESA_platform_surfaceless not supported;";
        }
    }
    if (want_all || options.platform == EglPlatform::Device) {
        auto query_devices = reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(
            has_extension(client_extensions, "EGL_EXT_device_enumeration") || has_extension(client_extensions, "EGL_EXT_device_base")
                ? eglGetProcAddress("eglQueryDevicesEXT")
                : nullptr);
        if (get_platform_display && query_devices && has_extension(client_extensions, "EGL_EXT_platform_device")) {
            EGLDeviceEXT devices[16];
            EGLint device_count = 0;
            if (!query_devices(16, devices, &device_count)) {
                log += strprintf(" device: eglQueryDevicesEXT: %s;", last_egl_error().c_str());
            } else if (device_count == 0) {
                log += " device: no EGL devices;";
            }
            for (EGLint i = 0; i < device_count; ++i)
                if (try_display(strprintf("device %d", int(i)), get_platform_display(EGL_PLATFORM_DEVICE_EXT, devices[i], nullptr)))
                    return;
        } else {
            log += " device: EGL_EXT_platform_device not supported;";
        }
    }
    if (want_all || options.platform == EglPlatform::Default) {
        if (try_display("default", eglGetDisplay(EGL_DEFAULT_DISPLAY))) return;
    }
    if (!log.empty() && log.back() == ';') log.pop_back();
    fail("cannot create a headless OpenGL 3.3 / ES 3.0 context:%s", log.c_str());
}

HeadlessGlContext::~HeadlessGlContext() {
    if (impl_->display == EGL_NO_DISPLAY) return;
    if (eglGetCurrentContext() == impl_->context)
        eglMakeCurrent(impl_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    eglDestroyContext(impl_->display, impl_->context);
    release_display(impl_->display);
}

void HeadlessGlContext::make_current() {
    eglBindAPI(impl_->gles ? EGL_OPENGL_ES_API : EGL_OPENGL_API);
    if (!eglMakeCurrent(impl_->display, EGL_NO_SURFACE, EGL_NO_SURFACE, impl_->context))
        fail("eglMakeCurrent: %s", last_egl_error().c_str());
}

bool HeadlessGlContext::is_gles() const { return impl_->gles; }
const std::string& HeadlessGlContext::platform() const { return impl_->platform; }

std::string HeadlessGlContext::renderer() const { return detail::current_gl_string(true); }

std::string HeadlessGlContext::version() const { return detail::current_gl_string(false); }

bool HeadlessGlContext::available(std::string* why) {
    // Remember the answer: creating a context costs tens of milliseconds.
    static std::mutex mutex;
    static int known = -1;
    static std::string reason;
    std::lock_guard<std::mutex> lock(mutex);
    if (known < 0) {
        EGLDisplay previous_display = eglGetCurrentDisplay();
        EGLContext previous = eglGetCurrentContext();
        EGLSurface draw = eglGetCurrentSurface(EGL_DRAW), read = eglGetCurrentSurface(EGL_READ);
        try {
            HeadlessGlContext probe;
            known = 1;
        } catch (const Error& e) {
            known = 0;
            reason = e.what();
        }
        if (previous != EGL_NO_CONTEXT) eglMakeCurrent(previous_display, draw, read, previous);
    }
    if (why) *why = reason;
    return known == 1;
}

}  // namespace catpaq
