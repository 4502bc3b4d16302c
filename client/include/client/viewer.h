#pragma once
// The desktop viewer (`catpaq view`): a GLFW window showing one streaming session.
//
// Controls: left drag orbits around the target, right drag (or shift + left drag) pans, the wheel
// dollies towards the target, a double click flies to the point under the cursor (a ray cast on
// the CPU against the triangles of the drawn cut, as the dataset's format draws them),
// F12 or P saves a screenshot (catpaq_view_NNNN.png in the working directory, the first free
// number: earlier ones are never overwritten), M toggles the measure mode, Escape clears a
// measurement or else quits. A Dear ImGui overlay shows the
// session's statistics (and nodes that failed to load: the coarser data stays on screen) and has
// a tolerance slider, light direction and background colour controls.
//
// Measure mode (M, or the overlay's checkbox): a click (press and release without dragging) picks
// a point with pick_cut; two picks give their distance, three the angle at the middle one, a
// fourth starts over (client/measure.h). The picks, segments and the value are drawn on top of
// the model, and each pick prints the measurement as one line on stdout ("measure: distance ...",
// "measure: angle ..."). `--measure "X,Y X,Y"` (ViewerSettings::measure_picks) makes the same
// picks from a script once the view has settled.
//
// The window is drawn on demand: after input, while the camera moves, when data arrives or the
// cut changes. In between the viewer sleeps in the event queue (a settled, idle view used 0.9 of
// a core redrawing the same image at the display's rate before).
//
// The camera controller and the ray-triangle test are plain code without GL, testable alone.
#include <array>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "base/error.h"
#include "client/camera.h"
#include "client/measure.h"
#include "client/session.h"

namespace catpaq {

// An orbit camera: a target, a distance and two angles around the model's up axis.
class OrbitController {
public:
    // up_axis: 1 (y up) or 2 (z up).
    explicit OrbitController(int up_axis = 2);

    // Frames the box [bmin, bmax]: target at its centre, its bounding sphere filling the view.
    void frame_box(const glm::dvec3& bmin, const glm::dvec3& bmax, double fov_y_degrees, double aspect);

    // Mouse motion in pixels (x right, y down).
    void orbit(double dx_px, double dy_px);
    // Moves the target (and the eye) so the point under the cursor follows it; `height_px` is the
    // viewport height.
    void pan(double dx_px, double dy_px, double height_px);
    // Wheel steps: positive dollies towards the target (the distance shrinks geometrically).
    void dolly(double steps);
    // Starts an animation of the target towards `point` over `seconds`; the distance shrinks to
    // `distance_factor` times the current distance from the eye to the point.
    void fly_to(const glm::dvec3& point, double seconds = 0.5, double distance_factor = 0.5);
    bool flying() const { return fly_.has_value(); }
    // Advances the animation to time `now` (seconds, any clock).
    void update(double now);

    // The camera for a viewport of the given size (clip planes left unset).
    Camera camera(int width, int height) const;

    glm::dvec3 target() const { return target_; }
    double distance() const { return distance_; }
    double azimuth() const { return azimuth_; }
    double elevation() const { return elevation_; }
    void set_distance_limits(double min_distance, double max_distance);
    double fov_y_degrees = 45;

    // Unit vectors of the model frame: world up, and two horizontal axes.
    glm::dvec3 up_vector() const { return basis_[2]; }
    // Direction (unit) from angles around the up axis (radians), in world coordinates.
    glm::dvec3 direction(double azimuth, double elevation) const;

private:
    glm::dvec3 eye_offset() const;  // eye - target

    std::array<glm::dvec3, 3> basis_;  // horizontal a, horizontal b, up
    glm::dvec3 target_{0, 0, 0};
    double distance_ = 3;
    double azimuth_ = -1.5707963267948966;  // looking along +b
    double elevation_ = 0.4363323129985824;  // 25 degrees
    double min_distance_ = 1e-9, max_distance_ = 1e300;
    struct Fly {
        glm::dvec3 from_target, to_target;
        double from_distance, to_distance;
        double start = -1, seconds;
    };
    std::optional<Fly> fly_;
};

// A ray: origin plus t * direction (direction need not be unit).
struct Ray {
    glm::dvec3 origin{0, 0, 0};
    glm::dvec3 direction{0, 0, 1};
};

// The ray from the eye through pixel coordinates (x right, y down; pixel centres at +0.5).
Ray pixel_ray(const Camera& camera, double px, double py);

// Möller-Trumbore: the parameter t > t_min of the hit with triangle (a, b, c), double-sided.
std::optional<double> intersect_triangle(const Ray& ray, const glm::dvec3& a, const glm::dvec3& b,
                                         const glm::dvec3& c, double t_min = 0);

// The nearest hit of the ray with the triangles the session draws (StreamingSession::
// drawn_geometry: for CATP every drawn fragment decoded on the CPU as the shader does), in world
// coordinates. Geometry without triangles (point sets) is picked by its points: the one nearest
// the eye within 3 pixels of the ray.
std::optional<glm::dvec3> pick_cut(const StreamingSession& session, const Camera& camera, const Ray& ray);

// The path of the next screenshot: DIRECTORY/catpaq_view_NNNN.png with the smallest number not
// taken, so a screenshot never replaces an earlier one.
std::string next_screenshot_path(const std::string& directory = ".");

struct ViewerSettings {
    std::string location;           // dataset: local .cpq path or URL
    SessionSettings session;
    int width = 1280, height = 800;
    int up_axis = 0;                // 1: y up, 2: z up, 0: the dataset's (z if it records none)
    int frames = 0;                 // > 0: render this many frames (every one drawn), then exit
    double exit_after = 0;          // > 0: run the interactive loop this many seconds, then exit
    std::string screenshot;         // save the last frame here (PNG)
    bool vsync = true;
    int msaa = 0;                   // anti-aliasing samples per pixel (0: none)
    SplatShape splats = SplatShape::Round;  // how point datasets draw (RenderSettings::splats)
    // Scripted measure picks (window pixels, as clicks), made in measure mode once the view has
    // settled (or on the last frame); a pick that hits nothing makes run() return 1.
    std::vector<glm::dvec2> measure_picks;
    bool exit_after_measure = false;  // close once the scripted picks are made and drawn
};

// Thrown when no window can be opened (no display): the caller tells the user to render headless.
class NoDisplayError : public Error {
public:
    using Error::Error;
};

class DesktopViewer {
public:
    // Opens the window, makes its context current, loads the dataset. Throws NoDisplayError if
    // GLFW cannot initialise or create a window, Error for dataset problems.
    explicit DesktopViewer(const ViewerSettings& settings);
    ~DesktopViewer();
    DesktopViewer(const DesktopViewer&) = delete;
    DesktopViewer& operator=(const DesktopViewer&) = delete;

    // Runs until the window closes, Escape, or the frame limit; returns the exit status (1 when a
    // scripted measure pick hit nothing).
    int run();

    struct Impl;

private:
    std::unique_ptr<Impl> impl_;
};

}  // namespace catpaq
