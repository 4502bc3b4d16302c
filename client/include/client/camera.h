#pragma once
// Cameras in world coordinates (double precision), and camera paths.
//
// Scans live at coordinates around 1e6 where float keeps only decimetres, so nothing here hands
// the GPU an absolute world position: view_relative(anchor) maps coordinates *relative to an
// anchor point* (near the camera) to eye space, with the anchor subtracted in double on the CPU.
// The renderer picks the anchor and feeds anchor-relative positions to the GPU.
//
// Pixel coordinates: x to the right, y down, (0, 0) the top-left corner of the top-left pixel.
#include <array>
#include <string>
#include <vector>

#include <glm/glm.hpp>

namespace catpaq {

struct Camera {
    glm::dvec3 eye{0, -3, 0};
    glm::dvec3 target{0, 0, 0};
    glm::dvec3 up{0, 0, 1};
    double fov_y_degrees = 45;  // vertical field of view
    int width = 640, height = 480;
    // Clip planes in world units. Zero (the default) means "not chosen": renderers call
    // fit_clip_planes() with the model's bounds first.
    double near_plane = 0, far_plane = 0;

    bool has_clip_planes() const { return near_plane > 0 && far_plane > near_plane; }
    // Chooses near/far so the box [bmin, bmax] lies between them: far just beyond the farthest
    // corner, near just before the closest point of the box, but no closer than far / 10^4
    // (24-bit depth), which is what it is when the eye is inside the box.
    void fit_clip_planes(const glm::dvec3& bmin, const glm::dvec3& bmax);

    glm::dvec3 forward() const;  // unit view direction
    double aspect() const { return double(width) / double(height); }
    // World to eye space (OpenGL convention: looking down -z), double precision.
    glm::dmat4 view() const;
    // (world - anchor) to eye space: view() * translate(anchor), computed without ever forming
    // large numbers: rotation times (anchor - eye). Convert to float after this.
    glm::dmat4 view_relative(const glm::dvec3& anchor) const;
    glm::dmat4 projection() const;  // asserts has_clip_planes()

    // Checks the camera makes sense (finite, eye != target, up not parallel to the view
    // direction, positive size, fov in (0, 180)); returns an empty string or the problem.
    std::string problem() const;
};

// Pixels covered by one world unit at `distance` from the eye (along the view direction):
// height / (2 tan(fov / 2)) / distance. The projected size of an object-space error e at
// distance d is e * pixels_per_unit_at(camera, d). Distances below the near plane (or below a
// tiny positive value when no near plane is set) are clamped, so the result is finite.
double pixels_per_unit_at(const Camera& camera, double distance);
// Distance from the eye to the closest point of the box (0 if the eye is inside).
double distance_to_box(const Camera& camera, const glm::dvec3& bmin, const glm::dvec3& bmax);
// The cut engine's screen-space error of a node with object-space error `error` and bounds
// [bmin, bmax]: error * pixels_per_unit_at(camera, distance_to_box(...)).
double projected_error(const Camera& camera, double error, const glm::dvec3& bmin, const glm::dvec3& bmax);

// Projects a world point to pixel coordinates (x right, y down) and its eye-space depth (> 0 in
// front of the camera). Returns false if the point is behind the eye (depth <= 0); the pixel
// coordinates are then meaningless.
bool project_to_pixels(const Camera& camera, const glm::dvec3& world, glm::dvec2& pixel, double* depth = nullptr);

// The pixel rectangle covered by a world box, clipped to the image.
struct PixelRect {
    bool visible = false;  // false if the box is entirely outside the view frustum
    double x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};
// Conservative: if any corner is behind the eye but the box is not entirely behind it, the
// whole image is returned.
PixelRect project_box(const Camera& camera, const glm::dvec3& bmin, const glm::dvec3& bmax);

// A sequence of camera frames of one size and field of view.
//   {"width": 640, "height": 480, "fov": 45,
//    "frames": [{"eye": [x, y, z], "target": [x, y, z], "up": [0, 0, 1]}, ...]}
// "fov" (degrees, default 45) and each frame's "up" (default [0, 0, 1]) are optional; a frame may
// override "fov". Clip planes are left unset (chosen from the model's bounds when rendering).
struct CameraPath {
    int width = 640, height = 480;
    double fov_y_degrees = 45;
    std::vector<Camera> frames;
};

// Parses a camera path; throws Error naming `source` and what is wrong (not JSON, missing or
// mistyped field, non-finite number, size out of range, eye == target, up parallel to the view).
CameraPath parse_camera_path(const std::string& json_text, const std::string& source);
CameraPath load_camera_path(const std::string& path);  // reads the file; throws Error
std::string camera_path_to_json(const CameraPath& path);

// `frames` cameras on a circle around the box's centre (z up), `elevation_degrees` above its
// horizontal plane, at the distance where the box's bounding sphere fills the view with a margin
// (`distance_factor` scales that distance).
CameraPath orbit_path(const glm::dvec3& bmin, const glm::dvec3& bmax, int frames, int width, int height,
                      double fov_y_degrees = 45, double elevation_degrees = 25, double distance_factor = 1.0);

}  // namespace catpaq
