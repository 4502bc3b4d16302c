#include "client/measure.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "base/error.h"

namespace catpaq {

namespace {

constexpr double kPi = 3.14159265358979323846;

// A point with 12 significant digits: a tenth of a millimetre at 1e7 metres from the origin.
std::string point_text(const glm::dvec3& p) {
    char buf[128];
    std::snprintf(buf, sizeof buf, "(%.12g, %.12g, %.12g)", p.x, p.y, p.z);
    return buf;
}

}  // namespace

MeasuredDistance measure_distance(const glm::dvec3& a, const glm::dvec3& b) {
    MeasuredDistance d;
    d.delta = b - a;  // one subtraction in double: exact for nearby points, even far from the origin
    d.length = glm::length(d.delta);
    return d;
}

std::optional<double> angle_at_degrees(const glm::dvec3& a, const glm::dvec3& vertex, const glm::dvec3& b) {
    const glm::dvec3 u = a - vertex, v = b - vertex;
    if (glm::length(u) == 0 || glm::length(v) == 0) return std::nullopt;
    return std::atan2(glm::length(glm::cross(u, v)), glm::dot(u, v)) * (180.0 / kPi);
}

void Measurement::add(const glm::dvec3& point) {
    if (points_.size() >= 3) points_.clear();
    points_.push_back(point);
}

std::optional<MeasuredDistance> Measurement::distance() const {
    if (points_.size() < 2) return std::nullopt;
    return measure_distance(points_[0], points_[1]);
}

std::optional<double> Measurement::angle_degrees() const {
    if (points_.size() < 3) return std::nullopt;
    return angle_at_degrees(points_[0], points_[1], points_[2]);
}

std::string Measurement::describe() const {
    char buf[512];
    if (points_.size() == 3) {
        std::optional<double> angle = angle_degrees();
        if (!angle)
            return "angle undefined at " + point_text(points_[1]) + ": a pick coincides with the vertex";
        std::snprintf(buf, sizeof buf, "angle %.9g deg at ", *angle);
        return buf + point_text(points_[1]) + " between " + point_text(points_[0]) + " and " + point_text(points_[2]);
    }
    if (points_.size() == 2) {
        const MeasuredDistance d = *distance();
        std::snprintf(buf, sizeof buf, "distance %.9g (dx %.9g, dy %.9g, dz %.9g) from ", d.length, d.delta.x, d.delta.y,
                      d.delta.z);
        return buf + point_text(points_[0]) + " to " + point_text(points_[1]);
    }
    if (points_.size() == 1) return "1 point " + point_text(points_[0]) + ": pick another";
    return "";
}

std::string Measurement::label() const {
    char buf[160];
    if (points_.size() == 3) {
        std::optional<double> angle = angle_degrees();
        if (!angle) return "angle undefined";
        std::snprintf(buf, sizeof buf, "%.2f deg", *angle);
        return buf;
    }
    if (points_.size() == 2) {
        const MeasuredDistance d = *distance();
        std::snprintf(buf, sizeof buf, "%.6g (%.4g, %.4g, %.4g)", d.length, d.delta.x, d.delta.y, d.delta.z);
        return buf;
    }
    return "";
}

MeasurementOverlay measurement_overlay(const Measurement& measurement, const Camera& camera) {
    MeasurementOverlay overlay;
    const std::vector<glm::dvec3>& points = measurement.points();
    std::vector<double> depths(points.size());
    for (size_t i = 0; i < points.size(); ++i) {
        glm::dvec2 pixel;
        if (project_to_pixels(camera, points[i], pixel, &depths[i])) overlay.markers.push_back(pixel);
    }
    for (size_t i = 0; i + 1 < points.size(); ++i) {
        glm::dvec3 a = points[i], b = points[i + 1];
        double da = depths[i], db = depths[i + 1];
        // Clip at a depth just in front of the eye: depth is linear along the segment. The
        // margin is relative to the segment's depths so it means the same at every scale.
        const double min_depth = 1e-6 * std::max(std::abs(da), std::abs(db));
        if (!(da > min_depth) && !(db > min_depth)) continue;
        if (!(da > min_depth)) a += (b - a) * ((min_depth - da) / (db - da));
        if (!(db > min_depth)) b += (a - b) * ((min_depth - db) / (da - db));
        glm::dvec2 pa, pb;
        if (project_to_pixels(camera, a, pa) && project_to_pixels(camera, b, pb)) overlay.segments.push_back({pa, pb});
    }
    overlay.label = measurement.label();
    if (!overlay.label.empty()) {
        const glm::dvec3 anchor = points.size() == 3 ? points[1] : (points[0] + points[1]) * 0.5;
        glm::dvec2 pixel;
        if (project_to_pixels(camera, anchor, pixel)) overlay.label_position = pixel;
    }
    return overlay;
}

std::vector<glm::dvec2> parse_pixel_picks(const std::string& text) {
    std::vector<glm::dvec2> picks;
    size_t at = 0;
    while (true) {
        at = text.find_first_not_of(" ;\t", at);
        if (at == std::string::npos) break;
        const size_t end = text.find_first_of(" ;\t", at);
        const std::string item = text.substr(at, end == std::string::npos ? std::string::npos : end - at);
        double x, y;
        char extra;
        if (std::sscanf(item.c_str(), "%lf,%lf%c", &x, &y, &extra) != 2 || !std::isfinite(x) || !std::isfinite(y))
            throw UsageError("--measure: '" + item + "' is not a pixel position X,Y");
        picks.push_back({x, y});
        at = end;
    }
    if (picks.empty()) throw UsageError("--measure: no pixel positions in '" + text + "' (expected X,Y X,Y ...)");
    return picks;
}

}  // namespace catpaq
