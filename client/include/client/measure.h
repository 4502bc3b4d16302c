#pragma once
// Measuring in the desktop viewer: the picks of one measurement, its distance or angle, the text
// shown and printed, and where its markers, segments and label fall on the screen.
//
// Plain code without a window or GL: the viewer feeds it the points pick_cut() returns and draws
// what measurement_overlay() returns. Everything is computed in double from world coordinates, and
// projected relative to the eye (project_to_pixels), so datasets 1e7 from the origin measure and
// draw as precisely as ones at the origin.
#include <optional>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "client/camera.h"

namespace catpaq {

// The distance between two points and its components (b - a), in model units.
struct MeasuredDistance {
    double length = 0;
    glm::dvec3 delta{0, 0, 0};
};
MeasuredDistance measure_distance(const glm::dvec3& a, const glm::dvec3& b);

// The angle at `vertex` between the segments to `a` and to `b`, in degrees in [0, 180]; nullopt
// when either segment has zero length (no direction, so no angle). atan2 of the cross and dot
// products, which stays precise for angles near 0 and 180 (acos of the dot product does not).
std::optional<double> angle_at_degrees(const glm::dvec3& a, const glm::dvec3& vertex, const glm::dvec3& b);

// The picks of one measurement. One point: nothing measured yet; two: their distance; three: the
// angle at the second (the middle) point. A pick after three starts a new measurement with it.
class Measurement {
public:
    // Adds a picked point (world coordinates), starting over after a completed angle.
    void add(const glm::dvec3& point);
    void clear() { points_.clear(); }

    const std::vector<glm::dvec3>& points() const { return points_; }
    bool empty() const { return points_.empty(); }
    // The distance between the first two points (with two or three points).
    std::optional<MeasuredDistance> distance() const;
    // The angle at the second point (with three points).
    std::optional<double> angle_degrees() const;

    // The result as one line: "distance L (dx X, dy Y, dz Z) from (..) to (..)", "angle A deg at
    // (..) between (..) and (..)", "1 point (..): pick another" or "" when empty. Lengths with 9
    // significant digits, coordinates with enough digits for a millimetre at 1e7.
    std::string describe() const;
    // The short label drawn next to the picks: "5.000 (3, 4, 0)" or "90.00 deg"; "" when there is
    // nothing to show.
    std::string label() const;

private:
    std::vector<glm::dvec3> points_;
};

// What the overlay draws for a measurement, in pixel coordinates of the camera's image (x right,
// y down): a marker per pick in front of the eye, the segments between consecutive picks (clipped
// at the eye plane, so a pick behind the viewer still draws the visible part of its segment) and
// the label, at the middle of the distance's segment or at the angle's vertex.
struct MeasurementOverlay {
    std::vector<glm::dvec2> markers;
    std::vector<std::pair<glm::dvec2, glm::dvec2>> segments;
    std::string label;
    std::optional<glm::dvec2> label_position;  // nullopt: the anchor is behind the eye
};
MeasurementOverlay measurement_overlay(const Measurement& measurement, const Camera& camera);

// Parses the scripted picks of `catpaq view --measure`: "X,Y" pixel positions (window pixels, as a
// click) separated by spaces or semicolons, e.g. "160,120 200,120". Throws UsageError naming the
// bad position.
std::vector<glm::dvec2> parse_pixel_picks(const std::string& text);

}  // namespace catpaq
