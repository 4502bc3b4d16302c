#include "client/viewer.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <unistd.h>

#include <epoxy/gl.h>
// epoxy first: GLFW must not include the system GL header.
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_opengl3.h>
#include <imgui.h>

#include "base/error.h"
#include "client/gl_context.h"
#include "client/image.h"

namespace catpaq {

namespace {
constexpr double kPi = 3.14159265358979323846;
constexpr double kMaxElevation = 89.0 * kPi / 180.0;
}  // namespace

// ---------------------------------------------------------------------------------------------
// OrbitController

OrbitController::OrbitController(int up_axis) {
    if (up_axis == 1)
        basis_ = {glm::dvec3(0, 0, 1), glm::dvec3(1, 0, 0), glm::dvec3(0, 1, 0)};  // z, x, y (z x x = y)
    else
        basis_ = {glm::dvec3(1, 0, 0), glm::dvec3(0, 1, 0), glm::dvec3(0, 0, 1)};
}

glm::dvec3 OrbitController::direction(double azimuth, double elevation) const {
    return std::cos(elevation) * std::cos(azimuth) * basis_[0] + std::cos(elevation) * std::sin(azimuth) * basis_[1] +
           std::sin(elevation) * basis_[2];
}

glm::dvec3 OrbitController::eye_offset() const { return distance_ * direction(azimuth_, elevation_); }

void OrbitController::set_distance_limits(double min_distance, double max_distance) {
    min_distance_ = std::max(min_distance, 1e-300);
    max_distance_ = std::max(max_distance, min_distance_);
    distance_ = std::clamp(distance_, min_distance_, max_distance_);
}

void OrbitController::frame_box(const glm::dvec3& bmin, const glm::dvec3& bmax, double fov_y, double aspect) {
    fov_y_degrees = fov_y;
    target_ = (bmin + bmax) * 0.5;
    double radius = std::max(glm::length(bmax - bmin) * 0.5, 1e-12);
    double half_fov = fov_y * kPi / 360.0;
    double half_fov_x = std::atan(std::tan(half_fov) * aspect);
    distance_ = radius / std::sin(std::min(half_fov, half_fov_x)) * 1.1;
    set_distance_limits(radius * 1e-6, radius * 1e3);
    fly_.reset();
}

void OrbitController::orbit(double dx_px, double dy_px) {
    fly_.reset();
    azimuth_ = std::remainder(azimuth_ - dx_px * 0.006, 2 * kPi);
    elevation_ = std::clamp(elevation_ + dy_px * 0.006, -kMaxElevation, kMaxElevation);
}

void OrbitController::pan(double dx_px, double dy_px, double height_px) {
    fly_.reset();
    glm::dvec3 forward = -direction(azimuth_, elevation_);
    glm::dvec3 right = glm::normalize(glm::cross(forward, basis_[2]));
    glm::dvec3 cam_up = glm::cross(right, forward);
    double units_per_px = 2.0 * distance_ * std::tan(fov_y_degrees * kPi / 360.0) / std::max(height_px, 1.0);
    target_ += (-dx_px * right + dy_px * cam_up) * units_per_px;
}

void OrbitController::dolly(double steps) {
    fly_.reset();
    distance_ = std::clamp(distance_ * std::pow(0.85, steps), min_distance_, max_distance_);
}

void OrbitController::fly_to(const glm::dvec3& point, double seconds, double distance_factor) {
    glm::dvec3 eye = target_ + eye_offset();
    Fly f;
    f.from_target = target_;
    f.to_target = point;
    f.from_distance = distance_;
    f.to_distance = std::clamp(glm::length(point - eye) * distance_factor, min_distance_, max_distance_);
    f.seconds = std::max(seconds, 1e-6);
    fly_ = f;
}

void OrbitController::update(double now) {
    if (!fly_) return;
    if (fly_->start < 0) fly_->start = now;
    double u = std::clamp((now - fly_->start) / fly_->seconds, 0.0, 1.0);
    double s = u * u * (3 - 2 * u);  // smoothstep
    target_ = fly_->from_target + (fly_->to_target - fly_->from_target) * s;
    // Geometric interpolation of the distance: a steady zoom.
    distance_ = fly_->from_distance * std::pow(fly_->to_distance / fly_->from_distance, s);
    if (u >= 1) fly_.reset();
}

Camera OrbitController::camera(int width, int height) const {
    Camera c;
    c.target = target_;
    c.eye = target_ + eye_offset();
    c.up = basis_[2];
    c.fov_y_degrees = fov_y_degrees;
    c.width = std::max(width, 1);
    c.height = std::max(height, 1);
    return c;
}

// ---------------------------------------------------------------------------------------------
// Picking

Ray pixel_ray(const Camera& camera, double px, double py) {
    glm::dvec3 forward = camera.forward();
    glm::dvec3 right = glm::normalize(glm::cross(forward, camera.up));
    glm::dvec3 cam_up = glm::cross(right, forward);
    double t = std::tan(camera.fov_y_degrees * kPi / 360.0);
    double x = (2.0 * px / camera.width - 1.0) * t * camera.aspect();
    double y = (1.0 - 2.0 * py / camera.height) * t;
    return {camera.eye, forward + x * right + y * cam_up};
}

std::optional<double> intersect_triangle(const Ray& ray, const glm::dvec3& a, const glm::dvec3& b,
                                         const glm::dvec3& c, double t_min) {
    glm::dvec3 e1 = b - a, e2 = c - a;
    glm::dvec3 p = glm::cross(ray.direction, e2);
    double det = glm::dot(e1, p);
    double scale = glm::length(e1) * glm::length(e2) * glm::length(ray.direction);
    if (!(std::abs(det) > scale * 1e-14)) return std::nullopt;  // parallel or degenerate
    double inv = 1.0 / det;
    glm::dvec3 s = ray.origin - a;
    double u = glm::dot(s, p) * inv;
    if (u < 0 || u > 1) return std::nullopt;
    glm::dvec3 q = glm::cross(s, e1);
    double v = glm::dot(ray.direction, q) * inv;
    if (v < 0 || u + v > 1) return std::nullopt;
    double t = glm::dot(e2, q) * inv;
    if (!(t > t_min)) return std::nullopt;
    return t;
}

std::optional<glm::dvec3> pick_cut(const StreamingSession& session, const Camera& camera, const Ray& ray) {
    // The drawn triangles relative to a point near the eye (the format's frame), so large
    // coordinates keep their precision.
    DrawnGeometry geometry = session.drawn_geometry({camera.eye.x, camera.eye.y, camera.eye.z});
    const glm::dvec3 origin(geometry.origin[0], geometry.origin[1], geometry.origin[2]);
    const Ray local{ray.origin - origin, ray.direction};
    const Mesh& mesh = geometry.mesh;
    double best = std::numeric_limits<double>::infinity();
    auto position = [&](uint32_t v) { return glm::dvec3(mesh.positions[v][0], mesh.positions[v][1], mesh.positions[v][2]); };
    if (mesh.indices.empty()) {
        // Geometry without triangles (point sets): the drawn point nearest the eye among those
        // within kPickPointPixels of the ray (as an angle: pixels at the centre of the view).
        constexpr double kPickPointPixels = 3;
        const double limit = kPickPointPixels * 2 * std::tan(camera.fov_y_degrees * kPi / 360) / camera.height;
        const glm::dvec3 d = glm::normalize(ray.direction);
        for (uint32_t v = 0; v < mesh.positions.size(); ++v) {
            const glm::dvec3 to = position(v) - local.origin;
            const double t = glm::dot(to, d);
            if (t > 0 && t < best && glm::length(to - t * d) <= limit * t) best = t;
        }
        if (!std::isfinite(best)) return std::nullopt;
        return ray.origin + best * d;
    }
    for (size_t i = 0; i + 2 < mesh.indices.size(); i += 3) {
        std::optional<double> t =
            intersect_triangle(local, position(mesh.indices[i]), position(mesh.indices[i + 1]), position(mesh.indices[i + 2]));
        if (t && *t < best) best = *t;
    }
    if (!std::isfinite(best)) return std::nullopt;
    return ray.origin + best * ray.direction;
}

// ---------------------------------------------------------------------------------------------
// DesktopViewer

namespace {

std::string glfw_error_text;

void glfw_error_callback(int code, const char* description) {
    char buf[512];
    std::snprintf(buf, sizeof buf, "%s (GLFW error 0x%x)", description ? description : "?", code);
    glfw_error_text = buf;
}

std::string human_bytes(uint64_t bytes) {
    const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
    double v = double(bytes);
    int u = 0;
    while (v >= 1024 && u < 4) {
        v /= 1024;
        ++u;
    }
    char buf[32];
    std::snprintf(buf, sizeof buf, u ? "%.1f %s" : "%.0f %s", v, units[u]);
    return buf;
}

}  // namespace

struct DesktopViewer::Impl {
    ViewerSettings settings;
    bool glfw_initialised = false;
    GLFWwindow* window = nullptr;
    bool imgui_glfw = false, imgui_gl = false;
    std::unique_ptr<StreamingSession> session;
    std::unique_ptr<Framebuffer> framebuffer;  // the scene, multisampled with --msaa
    OrbitController controller;
    RenderSettings render;
    float tolerance = 1.5f;
    bool headlight = true;
    float light_azimuth = 45, light_elevation = 45;  // degrees, in the model frame
    bool show_overlay = true;

    // Input state.
    enum class Drag { None, Orbit, Pan } drag = Drag::None;
    double last_x = 0, last_y = 0;
    double last_click_time = -1, last_click_x = 0, last_click_y = 0;
    bool pick_pending = false;
    double pick_x = 0, pick_y = 0;  // window coordinates
    // Measuring: a left press in measure mode that is released within kClickPixels is a pick.
    bool measure_mode = false;
    Measurement measurement;
    bool press_may_pick = false;
    double press_x = 0, press_y = 0;  // window coordinates of that press
    std::vector<glm::dvec2> measure_picks_pending;  // window coordinates
    bool scripted_picks_made = false;
    int exit_status = 0;
    bool screenshot_requested = false;
    std::string message;  // last status line (screenshot saved, nothing picked, ...)
    double message_time = -1;
    // Drawing on demand: events seen by the callbacks, frames still to draw after the last
    // change (Dear ImGui settles hover states over a few frames), when anything last changed.
    uint64_t events = 0, events_drawn = 0;
    int frames_owed = 2;
    double last_change = 0;
    bool message_shown = false;
    size_t failures_reported = 0;

    Camera last_camera;
    SessionFrameStats stats;
    RenderStats render_stats;
    double frame_ms = 0;

    explicit Impl(const ViewerSettings& s) : settings(s), controller(s.up_axis) {}
    ~Impl();

    void open();
    // One iteration: events, the session's step, and a frame drawn if anything changed (or
    // `force`). Returns whether it drew.
    bool loop_frame(bool last, bool force);
    // Seconds to sleep in the event queue before the next iteration when nothing changed.
    double idle_wait() const;
    void overlay();
    // Picks the point under window position (x, y) for the measurement and prints the result;
    // returns false (and says so) when nothing is there.
    bool measure_pick(const Camera& camera, double x, double y, double sx, double sy);
    void clear_measurement();
    // The measurement's markers, segments and label on ImGui's foreground draw list (window
    // coordinates: framebuffer pixels / (sx, sy)).
    void draw_measurement(const Camera& camera, double sx, double sy);
    void save_screenshot(const std::string& path, int width, int height);
    void set_message(const std::string& m) {
        message = m;
        message_time = glfwGetTime();
        std::fprintf(stderr, "view: %s\n", m.c_str());
    }

    static Impl& of(GLFWwindow* w) { return *static_cast<Impl*>(glfwGetWindowUserPointer(w)); }
    static void on_mouse_button(GLFWwindow* w, int button, int action, int mods);
    static void on_scroll(GLFWwindow* w, double dx, double dy);
    static void on_key(GLFWwindow* w, int key, int scancode, int action, int mods);
    // Events that change nothing of ours but need a frame (hovering the overlay, a resize).
    static void on_cursor(GLFWwindow* w, double, double) { of(w).events++; }
    static void on_char(GLFWwindow* w, unsigned) { of(w).events++; }
    static void on_refresh(GLFWwindow* w) { of(w).events++; }
    static void on_size(GLFWwindow* w, int, int) { of(w).events++; }
};

DesktopViewer::Impl::~Impl() {
    if (window) glfwMakeContextCurrent(window);
    framebuffer.reset();  // GL objects go while the context is current
    session.reset();
    if (imgui_gl) ImGui_ImplOpenGL3_Shutdown();
    if (imgui_glfw) ImGui_ImplGlfw_Shutdown();
    if (ImGui::GetCurrentContext()) ImGui::DestroyContext();
    if (window) glfwDestroyWindow(window);
    if (glfw_initialised) glfwTerminate();
}

void DesktopViewer::Impl::on_mouse_button(GLFWwindow* w, int button, int action, int mods) {
    Impl& v = of(w);
    v.events++;
    double x, y;
    glfwGetCursorPos(w, &x, &y);
    // Measure picks are clicks, not drags: a release near its press (the few pixels a hand moves
    // while clicking; they orbit a little, which the pick then sees).
    constexpr double kClickPixels = 4;
    if (action == GLFW_RELEASE) {
        v.drag = Drag::None;
        if (button == GLFW_MOUSE_BUTTON_LEFT && v.press_may_pick && std::abs(x - v.press_x) < kClickPixels &&
            std::abs(y - v.press_y) < kClickPixels)
            v.measure_picks_pending.push_back({x, y});
        v.press_may_pick = false;
        return;
    }
    if (action != GLFW_PRESS) return;
    if (ImGui::GetCurrentContext() && ImGui::GetIO().WantCaptureMouse) return;
    v.last_x = x;
    v.last_y = y;
    if (button == GLFW_MOUSE_BUTTON_LEFT && v.measure_mode) {
        // In measure mode single clicks pick, so a double click is two picks, not a fly-to.
        v.press_may_pick = !(mods & GLFW_MOD_SHIFT);
        v.press_x = x;
        v.press_y = y;
        v.drag = (mods & GLFW_MOD_SHIFT) ? Drag::Pan : Drag::Orbit;
        return;
    }
    if (button == GLFW_MOUSE_BUTTON_LEFT) {
        double now = glfwGetTime();
        if (now - v.last_click_time < 0.35 && std::abs(x - v.last_click_x) < 5 && std::abs(y - v.last_click_y) < 5) {
            v.pick_pending = true;
            v.pick_x = x;
            v.pick_y = y;
            v.last_click_time = -1;
            v.drag = Drag::None;
            return;
        }
        v.last_click_time = now;
        v.last_click_x = x;
        v.last_click_y = y;
        v.drag = (mods & GLFW_MOD_SHIFT) ? Drag::Pan : Drag::Orbit;
    } else if (button == GLFW_MOUSE_BUTTON_RIGHT || button == GLFW_MOUSE_BUTTON_MIDDLE) {
        v.drag = Drag::Pan;
    }
}

void DesktopViewer::Impl::on_scroll(GLFWwindow* w, double, double dy) {
    of(w).events++;
    if (ImGui::GetCurrentContext() && ImGui::GetIO().WantCaptureMouse) return;
    of(w).controller.dolly(dy);
}

void DesktopViewer::Impl::on_key(GLFWwindow* w, int key, int, int action, int) {
    of(w).events++;
    if (action != GLFW_PRESS) return;
    Impl& v = of(w);
    if (key == GLFW_KEY_ESCAPE) {
        // A measurement on screen is cleared first: Escape quits only an uncluttered view.
        if (!v.measurement.empty()) v.clear_measurement();
        else glfwSetWindowShouldClose(w, GLFW_TRUE);
        return;
    }
    if (ImGui::GetCurrentContext() && ImGui::GetIO().WantCaptureKeyboard) return;
    if (key == GLFW_KEY_F12 || key == GLFW_KEY_P) v.screenshot_requested = true;
    if (key == GLFW_KEY_H) v.show_overlay = !v.show_overlay;
    if (key == GLFW_KEY_M) v.measure_mode = !v.measure_mode;
}

void DesktopViewer::Impl::open() {
    glfwSetErrorCallback(glfw_error_callback);
    if (!glfwInit())
        throw NoDisplayError("no display: use `catpaq render` for headless rendering (" + glfw_error_text + ")");
    glfw_initialised = true;
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
    glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
    glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
    glfwWindowHint(GLFW_DEPTH_BITS, 24);
    glfwWindowHint(GLFW_SAMPLES, 0);  // the scene is drawn offscreen (multisampled with --msaa)
    std::string title = "catpaq view - " + settings.location;
    window = glfwCreateWindow(settings.width, settings.height, title.c_str(), nullptr, nullptr);
    if (!window)
        throw NoDisplayError("cannot open an OpenGL 3.3 window (" + glfw_error_text +
                             "): use `catpaq render` for headless rendering");
    glfwMakeContextCurrent(window);
    glfwSwapInterval(settings.vsync ? 1 : 0);
    glfwSetWindowUserPointer(window, this);
    // Our callbacks first: ImGui's (installed next) chain to them.
    glfwSetMouseButtonCallback(window, on_mouse_button);
    glfwSetScrollCallback(window, on_scroll);
    glfwSetKeyCallback(window, on_key);
    glfwSetCursorPosCallback(window, on_cursor);
    glfwSetCharCallback(window, on_char);
    glfwSetWindowRefreshCallback(window, on_refresh);
    glfwSetFramebufferSizeCallback(window, on_size);

    session = std::make_unique<StreamingSession>(settings.location, settings.session);
    tolerance = float(settings.session.tolerance_px);
    const DatasetFormat& format = session->format();
    // The up axis: as asked, else the dataset's (z when it records none).
    if (settings.up_axis == 0) controller = OrbitController(format.up_axis() == 1 ? 1 : 2);
    int fbw, fbh;
    glfwGetFramebufferSize(window, &fbw, &fbh);
    const Aabb bounds = format.world_bounds();
    controller.frame_box({bounds.min[0], bounds.min[1], bounds.min[2]}, {bounds.max[0], bounds.max[1], bounds.max[2]}, 45,
                         double(std::max(fbw, 1)) / double(std::max(fbh, 1)));
    render.background = {0.12f, 0.13f, 0.15f, 1.0f};
    render.splats = settings.splats;

    IMGUI_CHECKVERSION();
    ImGui::CreateContext();
    ImGui::GetIO().IniFilename = nullptr;  // no imgui.ini in the working directory
    ImGui::StyleColorsDark();
    imgui_glfw = ImGui_ImplGlfw_InitForOpenGL(window, true);
    imgui_gl = ImGui_ImplOpenGL3_Init("#version 330 core");
    if (!imgui_glfw || !imgui_gl) fail("cannot initialise the Dear ImGui backends");
}

// The scene as drawn (resolved, without the overlay).
void DesktopViewer::Impl::save_screenshot(const std::string& path, int width, int height) {
    std::vector<uint8_t> pixels = framebuffer->read_pixels();
    for (size_t i = 3; i < pixels.size(); i += 4) pixels[i] = 255;
    try {
        write_png(path, width, height, pixels);
        set_message("saved " + path);
    } catch (const Error& e) {
        set_message(std::string("screenshot not saved: ") + e.what());
    }
}

std::string next_screenshot_path(const std::string& directory) {
    for (int n = 0;; ++n) {
        char name[64];
        std::snprintf(name, sizeof name, "catpaq_view_%04d.png", n);
        std::string path = directory == "." ? name : directory + "/" + name;
        if (access(path.c_str(), F_OK) != 0) return path;
    }
}

bool DesktopViewer::Impl::measure_pick(const Camera& camera, double x, double y, double sx, double sy) {
    const std::optional<glm::dvec3> hit = pick_cut(*session, camera, pixel_ray(camera, x * sx, y * sy));
    if (!hit) {
        char buf[96];
        std::snprintf(buf, sizeof buf, "measure: nothing under the cursor at %.0f,%.0f", x, y);
        set_message(buf);
        return false;
    }
    measurement.add(*hit);
    // One line per pick on stdout, flushed: scripts read the measurement as it happens.
    std::printf("measure: %s\n", measurement.describe().c_str());
    std::fflush(stdout);
    message.clear();  // the overlay shows the measurement itself
    return true;
}

void DesktopViewer::Impl::clear_measurement() {
    measurement.clear();
    std::printf("measure: cleared\n");
    std::fflush(stdout);
}

void DesktopViewer::Impl::draw_measurement(const Camera& camera, double sx, double sy) {
    if (measurement.empty()) return;
    const MeasurementOverlay drawn = measurement_overlay(measurement, camera);
    ImDrawList* list = ImGui::GetForegroundDrawList();
    auto window_point = [&](const glm::dvec2& p) { return ImVec2(float(p.x / sx), float(p.y / sy)); };
    const ImU32 line_colour = IM_COL32(255, 220, 60, 255), outline = IM_COL32(0, 0, 0, 200);
    // Dark under light: the overlay stays readable over bright and dark models alike.
    for (const auto& [a, b] : drawn.segments) {
        list->AddLine(window_point(a), window_point(b), outline, 4.0f);
        list->AddLine(window_point(a), window_point(b), line_colour, 2.0f);
    }
    for (const glm::dvec2& m : drawn.markers) {
        list->AddCircleFilled(window_point(m), 5.0f, line_colour);
        list->AddCircle(window_point(m), 5.0f, outline, 0, 1.5f);
    }
    if (drawn.label_position) {
        // Up and right of its anchor, clear of the marker.
        const ImVec2 anchor = window_point(*drawn.label_position);
        const ImVec2 at(anchor.x + 10, anchor.y - 22);
        const ImVec2 size = ImGui::CalcTextSize(drawn.label.c_str());
        list->AddRectFilled(ImVec2(at.x - 4, at.y - 2), ImVec2(at.x + size.x + 4, at.y + size.y + 2), IM_COL32(0, 0, 0, 190),
                            3.0f);
        list->AddText(at, IM_COL32(255, 255, 255, 255), drawn.label.c_str());
    }
}

void DesktopViewer::Impl::overlay() {
    ImGui::SetNextWindowPos(ImVec2(10, 10), ImGuiCond_FirstUseEver);
    ImGui::SetNextWindowBgAlpha(0.75f);
    if (ImGui::Begin("catpaq", nullptr, ImGuiWindowFlags_AlwaysAutoResize)) {
        const SessionFrameStats& s = stats;
        ImGui::Text("triangles      %llu", (unsigned long long)render_stats.triangles);
        ImGui::Text("fragments      %zu", s.fragments);
        ImGui::Text("nodes          %zu drawn, %zu refined", s.drawn_nodes, s.refined_nodes);
        ImGui::Text("fetched        %s in %llu requests", human_bytes(s.bytes_fetched).c_str(),
                    (unsigned long long)s.requests);
        ImGui::Text("pending        %zu%s", s.pending, s.settled ? " (settled)" : "");
        ImGui::Text("GPU / CPU      %s / %s", human_bytes(s.gpu_bytes).c_str(), human_bytes(s.cpu_bytes).c_str());
        ImGui::Text("cut            %.2f ms", s.cut_ms);
        ImGui::Text("frame          %.1f ms", frame_ms);
        if (s.holes) ImGui::Text("certified err  not bounded yet (%zu nodes loading)", s.holes);
        else ImGui::Text("certified err  %.3f px (%s)", s.certified_error_px, s.tolerance_met ? "within tolerance" : "over");
        if (!s.tolerance_met && s.limits) {
            std::string why;
            for (const char* name : session_limit_names(s.limits)) why += (why.empty() ? "" : ", ") + std::string(name);
            ImGui::Text("limited by     %s", why.c_str());
        }
        for (const NodeFailure& f : session->failures()) {
            ImGui::TextColored(ImVec4(1.0f, 0.35f, 0.3f, 1.0f), "node %llu (level %u) failed: %s",
                               (unsigned long long)f.key, unsigned(f.level), f.error.c_str());
            if (&f - session->failures().data() >= 4) {
                ImGui::TextColored(ImVec4(1.0f, 0.35f, 0.3f, 1.0f), "... %zu failed nodes in all",
                                   session->failures().size());
                break;
            }
        }
        if (!session->failures().empty()) ImGui::TextDisabled("showing the coarser data; retried every few seconds");
        ImGui::Separator();
        if (ImGui::SliderFloat("tolerance px", &tolerance, 0.25f, 16.0f, "%.2f", ImGuiSliderFlags_Logarithmic))
            session->set_tolerance(double(tolerance));
        ImGui::Checkbox("headlight", &headlight);
        if (!headlight) {
            ImGui::SliderFloat("light azimuth", &light_azimuth, -180.0f, 180.0f, "%.0f deg");
            ImGui::SliderFloat("light elevation", &light_elevation, -90.0f, 90.0f, "%.0f deg");
        }
        ImGui::ColorEdit3("background", render.background.data());
        ImGui::Checkbox("wireframe", &render.wireframe);
        bool oriented = render.splats == SplatShape::Oriented;
        if (ImGui::Checkbox("oriented splats (points)", &oriented)) render.splats = oriented ? SplatShape::Oriented : SplatShape::Round;
        ImGui::Separator();
        ImGui::Checkbox("measure (M): click 2 points for a distance, 3 for an angle", &measure_mode);
        if (!measurement.empty()) {
            ImGui::TextWrapped("%s", measurement.describe().c_str());
            if (ImGui::Button("clear measurement (Esc)")) clear_measurement();
        }
        ImGui::Separator();
        ImGui::TextDisabled("drag: orbit  right/shift drag: pan  wheel: zoom");
        ImGui::TextDisabled("double click: fly to  M: measure  P/F12: screenshot  H: hide");
        ImGui::TextDisabled("Esc: clear the measurement, else quit");
        if (message.size() && glfwGetTime() - message_time < 4) ImGui::Text("%s", message.c_str());
    }
    ImGui::End();
}

bool DesktopViewer::Impl::loop_frame(bool last, bool force) {
    double frame_start = glfwGetTime();
    double x, y;
    glfwGetCursorPos(window, &x, &y);
    int win_w, win_h, fbw, fbh;
    glfwGetWindowSize(window, &win_w, &win_h);
    glfwGetFramebufferSize(window, &fbw, &fbh);
    if (fbw <= 0 || fbh <= 0) return false;  // minimised
    double sx = win_w > 0 ? double(fbw) / win_w : 1.0, sy = win_h > 0 ? double(fbh) / win_h : 1.0;
    bool changed = events != events_drawn || controller.flying() || drag != Drag::None || screenshot_requested;
    if (drag != Drag::None) {
        double dx = (x - last_x) * sx, dy = (y - last_y) * sy;
        if (drag == Drag::Orbit) controller.orbit(dx, dy);
        else controller.pan(dx, dy, fbh);
    }
    last_x = x;
    last_y = y;
    if (pick_pending) {
        pick_pending = false;
        Ray ray = pixel_ray(last_camera, pick_x * sx, pick_y * sy);
        if (std::optional<glm::dvec3> hit = pick_cut(*session, last_camera, ray)) {
            controller.fly_to(*hit);
            char buf[160];
            std::snprintf(buf, sizeof buf, "fly to %.6g %.6g %.6g", hit->x, hit->y, hit->z);
            set_message(buf);
        } else {
            set_message("nothing under the cursor");
        }
    }
    for (const glm::dvec2& p : measure_picks_pending) measure_pick(last_camera, p.x, p.y, sx, sy);
    measure_picks_pending.clear();
    controller.update(frame_start);

    Camera camera = controller.camera(fbw, fbh);
    stats = session->step(camera);
    last_camera = camera;
    changed |= stats.arrived > 0 || stats.cut_changes > 0;
    if (!settings.measure_picks.empty() && !scripted_picks_made && (stats.settled || last)) {
        // Scripted picks see the settled cut, as a user who waits for the view would.
        scripted_picks_made = true;
        measure_mode = true;
        for (const glm::dvec2& p : settings.measure_picks)
            if (!measure_pick(camera, p.x, p.y, sx, sy)) exit_status = 1;
        changed = true;
    }
    for (; failures_reported < session->failures().size(); ++failures_reported) {
        const NodeFailure& f = session->failures()[failures_reported];
        std::fprintf(stderr, "view: node %llu (level %u) cannot be loaded: %s (showing the coarser data)\n",
                     (unsigned long long)f.key, unsigned(f.level), f.error.c_str());
        changed = true;
    }
    bool message_visible = message.size() && glfwGetTime() - message_time < 4;
    changed |= message_visible != message_shown;
    if (changed) {
        frames_owed = 3;
        last_change = frame_start;
    }
    if (!force && frames_owed == 0) return false;
    frames_owed = std::max(0, frames_owed - 1);
    events_drawn = events;
    message_shown = message_visible;

    if (headlight) {
        render.light_direction = {0, 0, 0};
    } else {
        glm::dvec3 d = controller.direction(double(light_azimuth) * kPi / 180.0, double(light_elevation) * kPi / 180.0);
        render.light_direction = {float(d.x), float(d.y), float(d.z)};
    }
    if (!framebuffer || framebuffer->width() != fbw || framebuffer->height() != fbh)
        framebuffer = std::make_unique<Framebuffer>(fbw, fbh, settings.msaa);
    framebuffer->bind();
    render_stats = session->draw(camera, render);
    glPolygonMode(GL_FRONT_AND_BACK, GL_FILL);
    if (screenshot_requested) {
        screenshot_requested = false;
        save_screenshot(next_screenshot_path(), fbw, fbh);
    }
    // A scripted measurement ends the run after this frame: it is the last one.
    const bool closing = last || (scripted_picks_made && settings.exit_after_measure);
    if (closing && settings.screenshot.size()) save_screenshot(settings.screenshot, fbw, fbh);
    framebuffer->blit_to_window();
    glViewport(0, 0, fbw, fbh);

    ImGui_ImplOpenGL3_NewFrame();
    ImGui_ImplGlfw_NewFrame();
    ImGui::NewFrame();
    if (show_overlay) overlay();
    draw_measurement(camera, sx, sy);
    ImGui::Render();
    ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
    glfwSwapBuffers(window);
    frame_ms = (glfwGetTime() - frame_start) * 1000.0;
    if (closing) glfwSetWindowShouldClose(window, GLFW_TRUE);
    return true;
}

double DesktopViewer::Impl::idle_wait() const {
    // Settled: nothing will change until an event (or a status message expires).
    if (session->settled()) return 0.5;
    // Streaming: look again soon; when nothing has arrived for a while (a failed node waiting
    // for its retry), less often.
    return glfwGetTime() - last_change > 0.25 ? 0.1 : 0.004;
}

DesktopViewer::DesktopViewer(const ViewerSettings& settings) : impl_(std::make_unique<Impl>(settings)) {
    impl_->open();
}

DesktopViewer::~DesktopViewer() = default;

int DesktopViewer::run() {
    Impl& v = *impl_;
    const int limit = v.settings.frames;
    const double deadline = v.settings.exit_after > 0 ? glfwGetTime() + v.settings.exit_after : 0;
    for (int frame = 0; !glfwWindowShouldClose(v.window);) {
        if (limit > 0) {
            // Scripted (--frames): every iteration draws, as fast as it can.
            glfwPollEvents();
            bool last = frame + 1 >= limit;
            frame += v.loop_frame(last, true);
            if (last) break;
            continue;
        }
        if (deadline > 0 && glfwGetTime() >= deadline) {
            if (v.settings.screenshot.size() && v.framebuffer)
                v.save_screenshot(v.settings.screenshot, v.framebuffer->width(), v.framebuffer->height());
            break;
        }
        if (!v.loop_frame(false, false)) {
            double wait = v.idle_wait();
            if (deadline > 0) wait = std::max(0.0, std::min(wait, deadline - glfwGetTime()));
            glfwWaitEventsTimeout(wait);
        } else {
            glfwPollEvents();
        }
    }
    return v.exit_status;
}

}  // namespace catpaq
