// Cameras: double-precision view/projection, anchor-relative views, projection helpers, and
// JSON camera paths.
#include "client/camera.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>

#include <glm/gtc/matrix_transform.hpp>
#include <nlohmann/json.hpp>

#include "base/atomic_file.h"
#include "base/error.h"

namespace catpaq {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDepthRange = 1e4;  // far / near at most (24-bit depth)

bool finite3(const glm::dvec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

// Rows of the camera's rotation: right, true up, backward (OpenGL eye space looks down -z).
void basis(const Camera& c, glm::dvec3& right, glm::dvec3& up, glm::dvec3& back) {
    back = glm::normalize(c.eye - c.target);
    right = glm::normalize(glm::cross(c.up, back));
    up = glm::cross(back, right);
}

}  // namespace

std::string Camera::problem() const {
    if (!finite3(eye) || !finite3(target) || !finite3(up)) return "eye, target and up must be finite";
    if (width <= 0 || height <= 0 || width > 16384 || height > 16384)
        return strprintf("image size %dx%d is out of range (1..16384)", width, height);
    if (!(fov_y_degrees > 0 && fov_y_degrees < 180)) return strprintf("fov %g is not in (0, 180) degrees", fov_y_degrees);
    glm::dvec3 d = target - eye;
    double len = glm::length(d);
    if (!std::isfinite(len))  // finite coordinates whose difference or its square overflows
        return "eye and target are too far apart: their distance overflows a double";
    if (!(len > 0)) return "eye and target coincide";
    double up_len = glm::length(up);
    if (!(up_len > 0)) return "up is the zero vector";
    double sine = glm::length(glm::cross(d / len, up / up_len));
    if (!(sine > 1e-9)) return "up is parallel to the view direction";
    if (near_plane != 0 || far_plane != 0) {
        if (!(near_plane > 0 && far_plane > near_plane && std::isfinite(far_plane)))
            return strprintf("clip planes near %g far %g are invalid", near_plane, far_plane);
    }
    return "";
}

glm::dvec3 Camera::forward() const { return glm::normalize(target - eye); }

glm::dmat4 Camera::view() const { return view_relative(glm::dvec3(0.0)); }

glm::dmat4 Camera::view_relative(const glm::dvec3& anchor) const {
    glm::dvec3 right, true_up, back;
    basis(*this, right, true_up, back);
    // Eye-space position of a point p given relative to the anchor: R * (p + anchor - eye).
    // (anchor - eye) is one double subtraction of nearby values when the anchor is near the eye.
    glm::dvec3 offset = anchor - eye;
    glm::dmat4 m(1.0);
    for (int i = 0; i < 3; ++i) {
        m[i][0] = right[i];
        m[i][1] = true_up[i];
        m[i][2] = back[i];
    }
    m[3][0] = glm::dot(right, offset);
    m[3][1] = glm::dot(true_up, offset);
    m[3][2] = glm::dot(back, offset);
    return m;
}

glm::dmat4 Camera::projection() const {
    assert(has_clip_planes());
    return glm::perspective(fov_y_degrees * kPi / 180.0, aspect(), near_plane, far_plane);
}

void Camera::fit_clip_planes(const glm::dvec3& bmin, const glm::dvec3& bmax) {
    double farthest = 0;
    for (int i = 0; i < 8; ++i) {
        glm::dvec3 corner((i & 1) ? bmax.x : bmin.x, (i & 2) ? bmax.y : bmin.y, (i & 4) ? bmax.z : bmin.z);
        farthest = std::max(farthest, glm::length(corner - eye));
    }
    double closest = distance_to_box(*this, bmin, bmax);
    double extent = glm::length(bmax - bmin);
    far_plane = farthest * 1.01 + extent * 1e-6;
    if (!(far_plane > 0)) far_plane = 1.0;
    near_plane = std::max(closest * 0.99, far_plane / kDepthRange);
}

double pixels_per_unit_at(const Camera& camera, double distance) {
    double floor_distance = camera.near_plane > 0 ? camera.near_plane : 1e-12;
    if (!(distance > floor_distance)) distance = floor_distance;  // also catches NaN
    double focal = double(camera.height) / (2.0 * std::tan(camera.fov_y_degrees * kPi / 360.0));
    return focal / distance;
}

double distance_to_box(const Camera& camera, const glm::dvec3& bmin, const glm::dvec3& bmax) {
    glm::dvec3 closest = glm::clamp(camera.eye, bmin, bmax);
    return glm::length(camera.eye - closest);
}

double projected_error(const Camera& camera, double error, const glm::dvec3& bmin, const glm::dvec3& bmax) {
    return error * pixels_per_unit_at(camera, distance_to_box(camera, bmin, bmax));
}

bool project_to_pixels(const Camera& camera, const glm::dvec3& world, glm::dvec2& pixel, double* depth) {
    glm::dvec3 right, up, back;
    basis(camera, right, up, back);
    glm::dvec3 d = world - camera.eye;
    double x = glm::dot(right, d), y = glm::dot(up, d), z = -glm::dot(back, d);
    if (depth) *depth = z;
    if (!(z > 0)) return false;
    double focal = double(camera.height) / (2.0 * std::tan(camera.fov_y_degrees * kPi / 360.0));
    pixel.x = double(camera.width) * 0.5 + focal * x / z;
    pixel.y = double(camera.height) * 0.5 - focal * y / z;
    return true;
}

PixelRect project_box(const Camera& camera, const glm::dvec3& bmin, const glm::dvec3& bmax) {
    PixelRect r;
    double x0 = std::numeric_limits<double>::infinity(), y0 = x0, x1 = -x0, y1 = -x0;
    int behind = 0;
    for (int i = 0; i < 8; ++i) {
        glm::dvec3 corner((i & 1) ? bmax.x : bmin.x, (i & 2) ? bmax.y : bmin.y, (i & 4) ? bmax.z : bmin.z);
        glm::dvec2 p;
        if (!project_to_pixels(camera, corner, p)) {
            ++behind;
            continue;
        }
        x0 = std::min(x0, p.x);
        y0 = std::min(y0, p.y);
        x1 = std::max(x1, p.x);
        y1 = std::max(y1, p.y);
    }
    if (behind == 8) return r;
    if (behind > 0) {
        // Straddles the eye plane: conservatively the whole image.
        r.visible = true;
        r.x1 = camera.width;
        r.y1 = camera.height;
        return r;
    }
    if (x1 < 0 || y1 < 0 || x0 > camera.width || y0 > camera.height) return r;
    r.visible = true;
    r.x0 = std::max(x0, 0.0);
    r.y0 = std::max(y0, 0.0);
    r.x1 = std::min(x1, double(camera.width));
    r.y1 = std::min(y1, double(camera.height));
    return r;
}

// ---- camera paths -------------------------------------------------------------------------

namespace {

using nlohmann::json;

double number_field(const json& object, const char* name, const std::string& where, bool required, double fallback) {
    auto it = object.find(name);
    if (it == object.end()) {
        if (required) fail("%s: missing \"%s\"", where.c_str(), name);
        return fallback;
    }
    if (!it->is_number()) fail("%s: \"%s\" must be a number", where.c_str(), name);
    double v = it->get<double>();
    if (!std::isfinite(v)) fail("%s: \"%s\" is not finite", where.c_str(), name);
    return v;
}

int size_field(const json& object, const char* name, const std::string& where, int fallback) {
    auto it = object.find(name);
    if (it == object.end()) return fallback;
    if (!it->is_number_integer()) fail("%s: \"%s\" must be an integer", where.c_str(), name);
    int64_t v = it->get<int64_t>();
    if (v < 1 || v > 16384) fail("%s: \"%s\" = %lld is out of range (1..16384)", where.c_str(), name, (long long)v);
    return int(v);
}

glm::dvec3 vector_field(const json& object, const char* name, const std::string& where, const glm::dvec3* fallback) {
    auto it = object.find(name);
    if (it == object.end()) {
        if (!fallback) fail("%s: missing \"%s\"", where.c_str(), name);
        return *fallback;
    }
    if (!it->is_array() || it->size() != 3) fail("%s: \"%s\" must be an array of 3 numbers", where.c_str(), name);
    glm::dvec3 v;
    for (int i = 0; i < 3; ++i) {
        const json& e = (*it)[size_t(i)];
        if (!e.is_number()) fail("%s: \"%s\"[%d] must be a number", where.c_str(), name, i);
        v[i] = e.get<double>();
        if (!std::isfinite(v[i])) fail("%s: \"%s\"[%d] is not finite", where.c_str(), name, i);
    }
    return v;
}

}  // namespace

CameraPath parse_camera_path(const std::string& json_text, const std::string& source) {
    json doc;
    try {
        doc = json::parse(json_text);
    } catch (const json::parse_error& e) {
        fail("%s: not valid JSON: %s", source.c_str(), e.what());
    }
    if (!doc.is_object()) fail("%s: a camera path must be a JSON object", source.c_str());
    CameraPath path;
    path.width = size_field(doc, "width", source, path.width);
    path.height = size_field(doc, "height", source, path.height);
    path.fov_y_degrees = number_field(doc, "fov", source, false, path.fov_y_degrees);
    if (!(path.fov_y_degrees > 0 && path.fov_y_degrees < 180))
        fail("%s: \"fov\" = %g is not in (0, 180) degrees", source.c_str(), path.fov_y_degrees);
    auto frames = doc.find("frames");
    if (frames == doc.end()) fail("%s: missing \"frames\"", source.c_str());
    if (!frames->is_array() || frames->empty()) fail("%s: \"frames\" must be a non-empty array", source.c_str());
    const glm::dvec3 default_up(0, 0, 1);
    for (size_t i = 0; i < frames->size(); ++i) {
        const json& f = (*frames)[i];
        std::string where = strprintf("%s: frame %zu", source.c_str(), i);
        if (!f.is_object()) fail("%s: must be an object", where.c_str());
        Camera c;
        c.width = path.width;
        c.height = path.height;
        c.fov_y_degrees = number_field(f, "fov", where, false, path.fov_y_degrees);
        c.eye = vector_field(f, "eye", where, nullptr);
        c.target = vector_field(f, "target", where, nullptr);
        c.up = vector_field(f, "up", where, &default_up);
        std::string problem = c.problem();
        if (!problem.empty()) fail("%s: %s", where.c_str(), problem.c_str());
        path.frames.push_back(c);
    }
    return path;
}

CameraPath load_camera_path(const std::string& path) { return parse_camera_path(read_file(path), path); }

std::string camera_path_to_json(const CameraPath& path) {
    json doc;
    doc["width"] = path.width;
    doc["height"] = path.height;
    doc["fov"] = path.fov_y_degrees;
    json frames = json::array();
    for (const Camera& c : path.frames) {
        json f;
        f["eye"] = {c.eye.x, c.eye.y, c.eye.z};
        f["target"] = {c.target.x, c.target.y, c.target.z};
        f["up"] = {c.up.x, c.up.y, c.up.z};
        if (c.fov_y_degrees != path.fov_y_degrees) f["fov"] = c.fov_y_degrees;
        frames.push_back(f);
    }
    doc["frames"] = frames;
    return doc.dump(2) + "\n";
}

CameraPath orbit_path(const glm::dvec3& bmin, const glm::dvec3& bmax, int frames, int width, int height,
                      double fov_y_degrees, double elevation_degrees, double distance_factor) {
    assert(frames > 0 && width > 0 && height > 0);
    CameraPath path;
    path.width = width;
    path.height = height;
    path.fov_y_degrees = fov_y_degrees;
    glm::dvec3 centre = (bmin + bmax) * 0.5;
    double radius = std::max(glm::length(bmax - bmin) * 0.5, 1e-300);
    // The bounding sphere fits the narrower of the two fields of view, with 10% margin.
    double half_fov = fov_y_degrees * kPi / 360.0;
    double half_fov_x = std::atan(std::tan(half_fov) * double(width) / double(height));
    double distance = radius / std::sin(std::min(half_fov, half_fov_x)) * 1.1 * distance_factor;
    double elevation = std::clamp(elevation_degrees, -89.0, 89.0) * kPi / 180.0;  // up stays valid
    for (int i = 0; i < frames; ++i) {
        double azimuth = 2.0 * kPi * double(i) / double(frames) - kPi / 2;  // frame 0 looks along +y
        Camera c;
        c.width = width;
        c.height = height;
        c.fov_y_degrees = fov_y_degrees;
        c.target = centre;
        c.eye = centre + distance * glm::dvec3(std::cos(elevation) * std::cos(azimuth),
                                               std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
        c.up = glm::dvec3(0, 0, 1);
        path.frames.push_back(c);
    }
    return path;
}

}  // namespace catpaq
