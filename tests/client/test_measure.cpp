// Measuring in the desktop viewer (client/measure.h): distances, angles and the picks' state
// machine on known points (also 1e7 from the origin); the overlay's projection; picks on real
// datasets drawn headless (CATP and points 1e7 from the origin, AQP) feeding a measurement; and
// `catpaq view --measure` under Xvfb printing the measurement.
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <string>

#include <gtest/gtest.h>

#include "shell_run.h"

#include "aqp_support.h"
#include "base/error.h"
#include "catp/builder.h"
#include "client/gl_context.h"
#include "client/measure.h"
#include "client/session.h"
#include "client/viewer.h"
#include "mesh/generators.h"
#include "points/builder.h"
#include "points/sampling.h"
#include "scratch_directory.h"

namespace fs = std::filesystem;
using namespace catpaq;

using namespace catpaq::client_test;

namespace {

constexpr double kFar = 1e7;  // an offset from the origin where float keeps only metres

const fs::path& scratch_dir() {
    static const test::ScratchDirectory dir("catpaq_measure_");
    return dir.path();
}

// A CATP sphere (radius 1) moved by `offset` on every axis, built once per process.
const std::string& catp_sphere(double offset) {
    static std::map<double, std::string> paths;
    if (paths.count(offset)) return paths[offset];
    Mesh sphere = make_sphere(20000);
    for (Vec3d& p : sphere.positions)
        for (double& c : p) c += offset;
    const std::string path = (scratch_dir() / ("sphere_" + std::to_string(int64_t(offset)) + ".cpq")).string();
    CatpBuildSettings settings;
    settings.leaf_triangles = 500;
    settings.progress = false;
    build_catp(sphere, path, settings);
    return paths[offset] = path;
}

// A point dataset sampled on the sphere, moved by `offset` on every axis.
std::string points_sphere(double offset) {
    PointCloud cloud = sample_surface(make_sphere(20000), 200000, 7, true, false);
    for (Vec3d& p : cloud.positions)
        for (double& c : p) c += offset;
    const std::string path = (scratch_dir() / ("points_" + std::to_string(int64_t(offset)) + ".cpq")).string();
    PointsBuildSettings settings;
    settings.progress = false;
    build_points(std::move(cloud), path, settings);
    return path;
}

// The camera the viewer starts with for a dataset of these bounds (OrbitController::frame_box).
Camera framing_camera(const Aabb& bounds, int width, int height, int up_axis) {
    OrbitController controller(up_axis);
    controller.frame_box({bounds.min[0], bounds.min[1], bounds.min[2]}, {bounds.max[0], bounds.max[1], bounds.max[2]}, 45,
                         double(width) / double(height));
    return controller.camera(width, height);
}

// Steps the session until its cut is loaded for the camera.
void settle(StreamingSession& session, const Camera& camera) {
    for (int i = 0; i < 20000 && !(i > 0 && session.settled()); ++i) {
        session.step(camera);
        usleep(1000);
    }
    ASSERT_TRUE(session.settled());
}

// The first hit of the ray with the ideal sphere (centre, radius), computed relative to the
// centre so it keeps its precision 1e7 from the origin.
std::optional<glm::dvec3> ray_sphere(const Ray& ray, const glm::dvec3& centre, double radius) {
    const glm::dvec3 o = ray.origin - centre, d = glm::normalize(ray.direction);
    const double b = glm::dot(o, d), c = glm::dot(o, o) - radius * radius;
    const double disc = b * b - c;
    if (disc < 0) return std::nullopt;
    return ray.origin + (-b - std::sqrt(disc)) * d;
}


}  // namespace

// ---------------------------------------------------------------------------------------------
// The measurement alone

TEST(MeasureDistance, IsExactOnKnownPointsAlsoFarFromTheOrigin) {
    for (double offset : {0.0, kFar, -kFar}) {
        const glm::dvec3 base(offset, offset + 0.5, offset - 0.25);
        const MeasuredDistance d = measure_distance(base, base + glm::dvec3(3, 4, 12));
        EXPECT_EQ(d.length, 13.0) << offset;
        EXPECT_EQ(d.delta, glm::dvec3(3, 4, 12)) << offset;
        // Millimetres 1e7 from the origin: what float coordinates (1 m apart there) would lose.
        const MeasuredDistance mm = measure_distance(base, base + glm::dvec3(0.001, 0, 0));
        EXPECT_NEAR(mm.length, 0.001, 2e-9) << offset;  // the rounding of base + 0.001 at 1e7
    }
}

TEST(MeasureAngle, IsExactOnKnownPointsAlsoFarFromTheOrigin) {
    for (double offset : {0.0, kFar}) {
        const glm::dvec3 v(offset, offset, offset);
        EXPECT_NEAR(*angle_at_degrees(v + glm::dvec3(1, 0, 0), v, v + glm::dvec3(0, 2, 0)), 90.0, 1e-12);
        EXPECT_NEAR(*angle_at_degrees(v + glm::dvec3(1, 0, 0), v, v + glm::dvec3(1, 1, 0)), 45.0, 1e-12);
        EXPECT_NEAR(*angle_at_degrees(v + glm::dvec3(1, 0, 0), v, v + glm::dvec3(-3, 0, 0)), 180.0, 1e-12);
        EXPECT_NEAR(*angle_at_degrees(v + glm::dvec3(1, 0, 0), v, v + glm::dvec3(5, 0, 0)), 0.0, 1e-12);
        // sqrt(0.75) is stored to 2^-29 (1.9e-9) at 1e7: the angle of the stored point is 120 to
        // about 1e-7 degrees there (1e-9 / 1 rad); the other offsets above are exact in binary.
        EXPECT_NEAR(*angle_at_degrees(v + glm::dvec3(1, 0, 0), v, v + glm::dvec3(-0.5, std::sqrt(0.75), 0)), 120.0,
                    offset == 0 ? 1e-12 : 2e-7);
        // A tiny angle (1e-6 rad: a micron at 1 m) keeps 9 digits: atan2 of cross and dot (acos of
        // the normalised dot product would keep about 2). Its true size is that of the offsets
        // as stored (1e-6 rounds to a multiple of 2^-29 at 1e7).
        const glm::dvec3 tilted = v + glm::dvec3(1, 1e-6, 0);
        const double expected = std::atan((tilted.y - v.y) / (tilted.x - v.x)) * 180 / std::acos(-1.0);
        EXPECT_NEAR(*angle_at_degrees(v + glm::dvec3(1, 0, 0), v, tilted), expected, expected * 1e-9);
    }
    // A pick on the vertex leaves no direction: no angle.
    EXPECT_FALSE(angle_at_degrees({1, 0, 0}, {0, 0, 0}, {0, 0, 0}).has_value());
}

TEST(Measurement, ThirdPickAfterADistanceStartsTheAngleAndAFourthStartsOver) {
    Measurement m;
    EXPECT_TRUE(m.empty());
    EXPECT_EQ(m.describe(), "");
    EXPECT_EQ(m.label(), "");
    const glm::dvec3 a(kFar + 1, kFar, kFar), b(kFar, kFar, kFar), c(kFar, kFar + 1, kFar), d(5, 5, 5);
    m.add(a);
    EXPECT_FALSE(m.distance());
    EXPECT_EQ(m.label(), "");
    EXPECT_NE(m.describe().find("1 point"), std::string::npos) << m.describe();
    m.add(b);
    ASSERT_TRUE(m.distance());
    EXPECT_EQ(m.distance()->length, 1.0);
    EXPECT_FALSE(m.angle_degrees());
    EXPECT_EQ(m.describe().rfind("distance 1 (dx -1, dy 0, dz 0) from (10000001, 10000000, 10000000) to ", 0), 0u)
        << m.describe();
    m.add(c);
    ASSERT_TRUE(m.angle_degrees());
    EXPECT_NEAR(*m.angle_degrees(), 90.0, 1e-12);
    EXPECT_EQ(m.describe().rfind("angle 90 deg at (10000000, 10000000, 10000000) between (10000001, ", 0), 0u)
        << m.describe();
    EXPECT_EQ(m.label(), "90.00 deg");
    m.add(d);  // the fourth pick: a new measurement with it as the first point
    ASSERT_EQ(m.points().size(), 1u);
    EXPECT_EQ(m.points()[0], d);
    EXPECT_FALSE(m.distance());
    m.add(a);
    m.clear();
    EXPECT_TRUE(m.empty());
    EXPECT_FALSE(m.distance());
    EXPECT_EQ(m.describe(), "");
}

TEST(Measurement, DescribesAnAngleAtACoincidentPickAsUndefined) {
    Measurement m;
    m.add({1, 0, 0});
    m.add({0, 0, 0});
    m.add({0, 0, 0});
    EXPECT_FALSE(m.angle_degrees());
    EXPECT_NE(m.describe().find("angle undefined"), std::string::npos) << m.describe();
}

// The markers are drawn where the picked points are on screen: a point on a pixel's ray projects
// back to that pixel, 1e7 from the origin too (relative to the eye, in double).
TEST(MeasurementOverlay, MarkersProjectBackToTheClickedPixelsFarFromTheOrigin) {
    for (double offset : {0.0, kFar}) {
        Camera camera;
        camera.eye = glm::dvec3(offset, offset - 5, offset + 1);
        camera.target = glm::dvec3(offset, offset, offset);
        camera.width = 320;
        camera.height = 240;
        const glm::dvec2 clicks[3] = {{100.5, 80.25}, {160, 120}, {300, 20}};
        Measurement m;
        for (const glm::dvec2& click : clicks) {
            const Ray ray = pixel_ray(camera, click.x, click.y);
            m.add(ray.origin + 0.7 * ray.direction);  // a point 0.7 along the ray, ~3.5 units away
        }
        const MeasurementOverlay overlay = measurement_overlay(m, camera);
        ASSERT_EQ(overlay.markers.size(), 3u);
        for (int i = 0; i < 3; ++i) {
            EXPECT_NEAR(overlay.markers[i].x, clicks[i].x, 1e-5) << offset;
            EXPECT_NEAR(overlay.markers[i].y, clicks[i].y, 1e-5) << offset;
        }
        ASSERT_EQ(overlay.segments.size(), 2u);
        EXPECT_NEAR(glm::length(overlay.segments[0].first - clicks[0]), 0, 1e-5);
        EXPECT_NEAR(glm::length(overlay.segments[1].second - clicks[2]), 0, 1e-5);
        ASSERT_TRUE(overlay.label_position);  // an angle's label sits at its vertex
        EXPECT_NEAR(glm::length(*overlay.label_position - clicks[1]), 0, 1e-5);
        EXPECT_EQ(overlay.label, m.label());
    }
}

// A pick behind the eye (after orbiting past it) has no marker; its segment is still drawn up to
// the eye plane, towards the visible pick.
TEST(MeasurementOverlay, ClipsASegmentToAPickBehindTheEye) {
    Camera camera;
    camera.eye = {0, -5, 0};
    camera.target = {0, 0, 0};
    camera.width = 200;
    camera.height = 200;
    Measurement m;
    m.add({0.5, 0, 0});   // in front, right of the centre
    m.add({0.5, -10, 0});  // 5 units behind the eye
    const MeasurementOverlay overlay = measurement_overlay(m, camera);
    ASSERT_EQ(overlay.markers.size(), 1u);
    ASSERT_EQ(overlay.segments.size(), 1u);
    EXPECT_TRUE(std::isfinite(overlay.segments[0].second.x) && std::isfinite(overlay.segments[0].second.y));
    // Towards the eye plane at x = 0.5 the segment runs off the right edge of the image.
    EXPECT_GT(overlay.segments[0].second.x, 200);
    EXPECT_FALSE(overlay.label_position) << "the midpoint (y = -5) is on the eye plane, not in front";
    // Both behind: nothing drawn.
    Measurement behind;
    behind.add({0, -6, 0});
    behind.add({1, -7, 0});
    const MeasurementOverlay none = measurement_overlay(behind, camera);
    EXPECT_TRUE(none.markers.empty());
    EXPECT_TRUE(none.segments.empty());
}

TEST(MeasurePicks, ParseWindowPixelsAndRefuseOthersByName) {
    const std::vector<glm::dvec2> picks = parse_pixel_picks("160,120 200.5,100;  3,4");
    ASSERT_EQ(picks.size(), 3u);
    EXPECT_EQ(picks[0], glm::dvec2(160, 120));
    EXPECT_EQ(picks[1], glm::dvec2(200.5, 100));
    EXPECT_EQ(picks[2], glm::dvec2(3, 4));
    for (const char* bad : {"", "160", "160,x", "1,2,3", "1,2 nan,4"}) {
        try {
            parse_pixel_picks(bad);
            ADD_FAILURE() << "accepted '" << bad << "'";
        } catch (const UsageError& e) {
            EXPECT_NE(std::string(e.what()).find("--measure"), std::string::npos) << e.what();
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Picks on real datasets, drawn headless

namespace {

// Picks three pixels on the sphere dataset at `path` (its bounds: a sphere) and checks each pick
// lies on the model where the pixel's ray meets the ideal sphere, and that the measurement built
// from the picks has the distance and angle of those ideal points. `tolerance`: in radii.
void check_sphere_measurement(const std::string& path, double tolerance) {
    std::string why;
    if (!HeadlessGlContext::available(&why)) GTEST_SKIP() << why;
    HeadlessGlContext context;
    StreamingSession session(path, SessionSettings{});
    const Aabb bounds = session.format().world_bounds();
    const glm::dvec3 bmin(bounds.min[0], bounds.min[1], bounds.min[2]), bmax(bounds.max[0], bounds.max[1], bounds.max[2]);
    const glm::dvec3 centre = (bmin + bmax) * 0.5;
    const double radius = (bmax.x - bmin.x) * 0.5;
    const Camera camera = framing_camera(bounds, 320, 240, 2);
    settle(session, camera);
    if (::testing::Test::HasFatalFailure()) return;

    // frame_box fits the box's bounding sphere (radius sqrt(3)) in the view: the sphere covers
    // ~59 px around the centre of the image. Three pixels inside it.
    const glm::dvec2 clicks[3] = {{200, 120}, {160, 120}, {160, 80}};
    Measurement measured, ideal;
    for (const glm::dvec2& click : clicks) {
        const Ray ray = pixel_ray(camera, click.x, click.y);
        const std::optional<glm::dvec3> hit = pick_cut(session, camera, ray);
        ASSERT_TRUE(hit) << path << " at " << click.x << "," << click.y;
        const std::optional<glm::dvec3> expected = ray_sphere(ray, centre, radius);
        ASSERT_TRUE(expected);
        EXPECT_NEAR(glm::length(*hit - *expected), 0, tolerance * radius) << path << " at " << click.x << "," << click.y;
        measured.add(*hit);
        ideal.add(*expected);
        if (measured.points().size() == 2) {
            EXPECT_NEAR(measured.distance()->length, ideal.distance()->length, 2 * tolerance * radius) << path;
            // The picks are drawn where they were clicked (points: within the 3 px pick radius).
            const MeasurementOverlay overlay = measurement_overlay(measured, camera);
            ASSERT_EQ(overlay.markers.size(), 2u);
            for (int i = 0; i < 2; ++i) EXPECT_NEAR(glm::length(overlay.markers[i] - clicks[i]), 0, 3.01) << path;
        }
    }
    // The angle at the image centre's pick: the picks are ~0.7 radii apart, so a tolerance of
    // t radii moves the directions by about t / 0.7 rad.
    ASSERT_TRUE(measured.angle_degrees()) << path;
    EXPECT_NEAR(*measured.angle_degrees(), *ideal.angle_degrees(), 3 * tolerance / 0.7 * 180 / std::acos(-1.0)) << path;
    std::printf("%s: %s\n", fs::path(path).filename().c_str(), measured.describe().c_str());
}

}  // namespace

TEST(MeasurePicking, PicksLieOnACatpMeshFarFromTheOrigin) { check_sphere_measurement(catp_sphere(kFar), 0.01); }

// A point pick is the depth of the drawn point nearest the eye within 3 px of the ray: up to 3 px
// (0.05 radii at this distance) beside the ray, on a surface sloping up to ~45 degrees there.
TEST(MeasurePicking, PicksLieOnAPointDatasetFarFromTheOrigin) { check_sphere_measurement(points_sphere(kFar), 0.06); }

TEST(MeasurePicking, PicksLieOnAnAqpMesh) { check_sphere_measurement(test::aqp_dataset_path(test::AqpModel::Sphere), 0.02); }

// ---------------------------------------------------------------------------------------------
// `catpaq view --measure` under Xvfb

namespace {

// The three coordinates after `prefix` in `line` ("... from (x, y, z) ...").
glm::dvec3 point_after(const std::string& line, const std::string& prefix) {
    const size_t at = line.find(prefix);
    if (at == std::string::npos) return glm::dvec3(NAN);
    glm::dvec3 p;
    if (std::sscanf(line.c_str() + at + prefix.size(), "(%lf, %lf, %lf)", &p.x, &p.y, &p.z) != 3) return glm::dvec3(NAN);
    return p;
}

// The line of `output` starting with `start` ("" if none).
std::string line_starting(const std::string& output, const std::string& start) {
    for (size_t at = 0; at < output.size();) {
        const size_t end = output.find('\n', at);
        const std::string line = output.substr(at, end == std::string::npos ? std::string::npos : end - at);
        if (line.rfind(start, 0) == 0) return line;
        if (end == std::string::npos) break;
        at = end + 1;
    }
    return "";
}

}  // namespace

// Scripted clicks in a real window print the distance and then the angle, each computed from
// picks that lie on the model and match a headless pick with the viewer's starting camera.
TEST(ViewMeasure, ScriptedClicksPrintTheDistanceAndAngleUnderXvfb) {
    if (access("/usr/bin/xvfb-run", X_OK) != 0) GTEST_SKIP() << "xvfb-run is not installed";
    ASSERT_TRUE(fs::exists(catpaq_binary())) << catpaq_binary();
    const std::string& dataset = catp_sphere(kFar);
    std::string output;
    const int status = run("/usr/bin/xvfb-run -a -s \"-screen 0 1280x800x24\" " + catpaq_binary() + " view " + dataset +
                               " --size 320x240 --measure \"200,120 160,120 160,80\"",
                           output);
    ASSERT_EQ(status, 0) << output;
    const std::string distance = line_starting(output, "measure: distance ");
    const std::string angle = line_starting(output, "measure: angle ");
    ASSERT_NE(distance, "") << output;
    ASSERT_NE(angle, "") << output;

    // The printed distance is that of the printed points, both on the sphere. The points are
    // printed with 12 digits: to 1e-4 at 1e7, so their differences agree to 2e-4.
    constexpr double kPrinted = 2e-4;
    double length = 0, dx = 0, dy = 0, dz = 0;
    ASSERT_EQ(std::sscanf(distance.c_str(), "measure: distance %lf (dx %lf, dy %lf, dz %lf)", &length, &dx, &dy, &dz), 4)
        << distance;
    const glm::dvec3 first = point_after(distance, " from "), second = point_after(distance, " to ");
    const glm::dvec3 centre(kFar, kFar, kFar);
    EXPECT_NEAR(glm::length(first - centre), 1.0, 0.02) << distance;
    EXPECT_NEAR(glm::length(second - centre), 1.0, 0.02) << distance;
    EXPECT_NEAR(length, glm::length(second - first), kPrinted) << distance;
    EXPECT_NEAR(dx, (second - first).x, kPrinted) << distance;
    EXPECT_NEAR(dy, (second - first).y, kPrinted) << distance;
    EXPECT_NEAR(dz, (second - first).z, kPrinted) << distance;
    EXPECT_NEAR(length, std::sqrt(dx * dx + dy * dy + dz * dz), 1e-8) << distance;

    // The same pick headless, with the camera the viewer starts with.
    {
        std::string why;
        if (HeadlessGlContext::available(&why)) {
            HeadlessGlContext context;
            StreamingSession session(dataset, SessionSettings{});
            const Camera camera = framing_camera(session.format().world_bounds(), 320, 240, session.format().up_axis() == 1 ? 1 : 2);
            settle(session, camera);
            const std::optional<glm::dvec3> hit = pick_cut(session, camera, pixel_ray(camera, 200, 120));
            ASSERT_TRUE(hit);
            EXPECT_NEAR(glm::length(*hit - first), 0, 0.01) << distance;
        }
    }

    // The angle line: at the second pick, between the first and the third, as computed here.
    double degrees = 0;
    ASSERT_EQ(std::sscanf(angle.c_str(), "measure: angle %lf deg", &degrees), 1) << angle;
    const glm::dvec3 vertex = point_after(angle, " at "), third = point_after(angle, " and ");
    EXPECT_NEAR(glm::length(vertex - second), 0, 1e-3) << angle;
    EXPECT_NEAR(glm::length(third - centre), 1.0, 0.02) << angle;
    // Printed points 2e-4 off over segments of ~0.6: 3e-4 rad, 0.02 degrees.
    EXPECT_NEAR(degrees, *angle_at_degrees(first, second, third), 0.02) << angle;
    EXPECT_GT(degrees, 45);
    EXPECT_LT(degrees, 135);
}

// A scripted click on the background is an error the script sees (status 1, named on stderr);
// a malformed --measure is a usage error (status 2).
TEST(ViewMeasure, AClickOnNothingFailsAndABadPositionIsAUsageError) {
    ASSERT_TRUE(fs::exists(catpaq_binary())) << catpaq_binary();
    std::string output;
    EXPECT_EQ(run("env -u DISPLAY " + catpaq_binary() + " view x.cpq --measure 12", output), 2) << output;
    EXPECT_NE(output.find("--measure: '12' is not a pixel position X,Y"), std::string::npos) << output;
    if (access("/usr/bin/xvfb-run", X_OK) != 0) GTEST_SKIP() << "xvfb-run is not installed";
    const int status = run("/usr/bin/xvfb-run -a -s \"-screen 0 1280x800x24\" " + catpaq_binary() + " view " +
                               catp_sphere(0) + " --size 320x240 --measure \"160,120 2,2\"",
                           output);
    EXPECT_EQ(status, 1) << output;
    EXPECT_NE(output.find("measure: 1 point"), std::string::npos) << output;
    EXPECT_NE(output.find("nothing under the cursor at 2,2"), std::string::npos) << output;
}
