// Cameras: matrices, projection helpers, anchor-relative precision, camera path files.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "base/error.h"
#include "client/camera.h"
#include "gl_support.h"

using namespace catpaq;

namespace {

Camera simple_camera() {
    Camera c;
    c.eye = {0, -10, 0};
    c.target = {0, 0, 0};
    c.up = {0, 0, 1};
    c.fov_y_degrees = 90;
    c.width = 200;
    c.height = 100;
    c.near_plane = 0.1;
    c.far_plane = 100;
    return c;
}

void expect_error_containing(const std::string& json, const std::string& needle) {
    try {
        parse_camera_path(json, "path.json");
        ADD_FAILURE() << "accepted: " << json;
    } catch (const Error& e) {
        std::string what = e.what();
        EXPECT_NE(what.find(needle), std::string::npos) << what;
        EXPECT_NE(what.find("path.json"), std::string::npos) << what;
    }
}

}  // namespace

TEST(Camera, PixelsPerUnitFollowsTheFocalLength) {
    Camera c = simple_camera();
    // height / (2 tan 45deg) = 50 pixels per unit at distance 1.
    EXPECT_NEAR(pixels_per_unit_at(c, 1.0), 50.0, 1e-12);
    EXPECT_NEAR(pixels_per_unit_at(c, 10.0), 5.0, 1e-12);
    // Clamped at the near plane, finite for 0 and negative distances.
    EXPECT_NEAR(pixels_per_unit_at(c, 0.0), 500.0, 1e-9);
    EXPECT_TRUE(std::isfinite(pixels_per_unit_at(c, -1.0)));
    EXPECT_NEAR(distance_to_box(c, {-1, -1, -1}, {1, 1, 1}), 9.0, 1e-12);
    EXPECT_EQ(distance_to_box(c, {-1, -20, -1}, {1, 1, 1}), 0.0);
    EXPECT_NEAR(projected_error(c, 0.5, {-1, -1, -1}, {1, 1, 1}), 0.5 * 50.0 / 9.0, 1e-12);
}

TEST(Camera, ProjectsPointsToPixels) {
    Camera c = simple_camera();
    glm::dvec2 p;
    double depth = 0;
    ASSERT_TRUE(project_to_pixels(c, {0, 0, 0}, p, &depth));
    EXPECT_NEAR(p.x, 100, 1e-9);
    EXPECT_NEAR(p.y, 50, 1e-9);
    EXPECT_NEAR(depth, 10, 1e-12);
    // One unit right at distance 10: 5 pixels right; one unit up: 5 pixels up (y down).
    ASSERT_TRUE(project_to_pixels(c, {1, 0, 1}, p));
    EXPECT_NEAR(p.x, 105, 1e-9);
    EXPECT_NEAR(p.y, 45, 1e-9);
    EXPECT_FALSE(project_to_pixels(c, {0, -20, 0}, p));  // behind the eye

    // The GL matrices agree with project_to_pixels.
    glm::dvec4 clip = c.projection() * c.view() * glm::dvec4(1, 0, 1, 1);
    double x = (clip.x / clip.w * 0.5 + 0.5) * c.width, y = (0.5 - clip.y / clip.w * 0.5) * c.height;
    EXPECT_NEAR(x, 105, 1e-9);
    EXPECT_NEAR(y, 45, 1e-9);

    PixelRect r = project_box(c, {-1, -1, -1}, {1, 1, 1});
    EXPECT_TRUE(r.visible);
    EXPECT_NEAR(r.x0, 100 - 50.0 / 9.0, 1e-9);
    EXPECT_NEAR(r.x1, 100 + 50.0 / 9.0, 1e-9);
    EXPECT_FALSE(project_box(c, {-1, -30, -1}, {1, -20, 1}).visible);   // behind
    EXPECT_FALSE(project_box(c, {50, -1, -1}, {60, 1, 1}).visible);     // off to the side
    PixelRect around = project_box(c, {-1, -11, -1}, {1, -9, 1});       // contains the eye
    EXPECT_TRUE(around.visible);
    EXPECT_EQ(around.x1, 200);
}

TEST(Camera, AnchorRelativeViewKeepsPrecisionFarFromTheOrigin) {
    // A camera 1 unit from a point at 1e6: the relative view maps small offsets exactly, while
    // a float world-space view cannot even represent the millimetre.
    Camera c = simple_camera();
    const glm::dvec3 far(1.0e6 + 0.25, 2.0e6, -1.0e6);
    c.eye = far + glm::dvec3(0, -1, 0);
    c.target = far;
    glm::dmat4 relative = c.view_relative(far);
    glm::mat4 relative_f(relative);
    glm::vec4 e = relative_f * glm::vec4(0.001f, 0.0f, 0.0f, 1.0f);
    EXPECT_NEAR(e.x, 0.001, 1e-9);
    EXPECT_NEAR(e.z, -1.0, 1e-9);
    // The double view agrees.
    glm::dvec4 d = c.view() * glm::dvec4(far + glm::dvec3(0.001, 0, 0), 1.0);
    EXPECT_NEAR(d.x, 0.001, 1e-9);
}

TEST(Camera, FitsClipPlanesToTheBounds) {
    Camera c = simple_camera();
    c.near_plane = c.far_plane = 0;
    EXPECT_FALSE(c.has_clip_planes());
    c.fit_clip_planes({-1, -1, -1}, {1, 1, 1});
    ASSERT_TRUE(c.has_clip_planes());
    EXPECT_LE(c.near_plane, 9.0);
    EXPECT_GT(c.near_plane, 8.0);
    EXPECT_GE(c.far_plane, std::sqrt(1 + 11.0 * 11 + 1));
    // Eye inside the box: near is a small fraction of far, still positive.
    c.eye = {0, 0, 0.5};
    c.fit_clip_planes({-1, -1, -1}, {1, 1, 1});
    EXPECT_GT(c.near_plane, 0);
    EXPECT_LT(c.near_plane, c.far_plane / 1000);
}

TEST(CameraPath, ParsesFramesWithDefaults) {
    CameraPath p = parse_camera_path(R"({"width": 320, "height": 200, "fov": 60,
        "frames": [{"eye": [1, 2, 3], "target": [0, 0, 0]},
                   {"eye": [0, 0, 5], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 30}]})",
                                     "path.json");
    EXPECT_EQ(p.width, 320);
    EXPECT_EQ(p.height, 200);
    ASSERT_EQ(p.frames.size(), 2u);
    EXPECT_EQ(p.frames[0].eye, glm::dvec3(1, 2, 3));
    EXPECT_EQ(p.frames[0].up, glm::dvec3(0, 0, 1));
    EXPECT_EQ(p.frames[0].fov_y_degrees, 60);
    EXPECT_EQ(p.frames[0].width, 320);
    EXPECT_EQ(p.frames[1].up, glm::dvec3(0, 1, 0));
    EXPECT_EQ(p.frames[1].fov_y_degrees, 30);
    EXPECT_FALSE(p.frames[0].has_clip_planes());

    // Round trip through the writer.
    CameraPath q = parse_camera_path(camera_path_to_json(p), "again.json");
    ASSERT_EQ(q.frames.size(), 2u);
    EXPECT_EQ(q.frames[1].eye, p.frames[1].eye);
    EXPECT_EQ(q.frames[1].fov_y_degrees, 30);
}

TEST(CameraPath, RejectsMalformedFilesClearly) {
    expect_error_containing("{", "not valid JSON");
    expect_error_containing("[1, 2]", "must be a JSON object");
    expect_error_containing(R"({"width": 10})", "missing \"frames\"");
    expect_error_containing(R"({"frames": []})", "non-empty array");
    expect_error_containing(R"({"width": 0, "frames": [{"eye": [1,0,0], "target": [0,0,0]}]})", "out of range");
    expect_error_containing(R"({"width": 2.5, "frames": [{"eye": [1,0,0], "target": [0,0,0]}]})", "integer");
    expect_error_containing(R"({"fov": 180, "frames": [{"eye": [1,0,0], "target": [0,0,0]}]})", "fov");
    expect_error_containing(R"({"frames": [{"target": [0,0,0]}]})", "frame 0: missing \"eye\"");
    expect_error_containing(R"({"frames": [{"eye": [1,0], "target": [0,0,0]}]})", "array of 3 numbers");
    expect_error_containing(R"({"frames": [{"eye": [1,0,"x"], "target": [0,0,0]}]})", "must be a number");
    expect_error_containing(R"({"frames": [{"eye": [1,0,0], "target": [1,0,0]}]})", "coincide");
    // Finite, but their distance overflows: not "coincide".
    expect_error_containing(R"({"frames": [{"eye": [1e308,0,0], "target": [-1e308,0,0]}]})", "too far apart");
    expect_error_containing(R"({"frames": [{"eye": [0,0,1], "target": [0,0,0]}]})", "parallel");
    expect_error_containing(R"({"frames": [{"eye": [1,0,0], "target": [0,0,0]}, 3]})", "frame 1: must be an object");
}

TEST(CameraPath, LoadsFilesAndNamesMissingOnes) {
    std::string path = test::scratch_dir() + "/cameras.json";
    {
        std::ofstream out(path);
        out << R"({"frames": [{"eye": [3, 0, 0], "target": [0, 0, 0]}]})";
    }
    CameraPath p = load_camera_path(path);
    ASSERT_EQ(p.frames.size(), 1u);
    EXPECT_EQ(p.width, 640);
    EXPECT_THROW(load_camera_path(test::scratch_dir() + "/missing.json"), Error);
}

TEST(CameraPath, OrbitKeepsTheBoundsInView) {
    CameraPath p = orbit_path({-1, -2, -1}, {1, 2, 1}, 8, 320, 240, 45);
    ASSERT_EQ(p.frames.size(), 8u);
    for (Camera c : p.frames) {
        EXPECT_EQ(c.problem(), "");
        EXPECT_EQ(c.target, glm::dvec3(0, 0, 0));
        c.fit_clip_planes({-1, -2, -1}, {1, 2, 1});
        for (int i = 0; i < 8; ++i) {
            glm::dvec3 corner((i & 1) ? 1 : -1, (i & 2) ? 2 : -2, (i & 4) ? 1 : -1);
            glm::dvec2 px;
            ASSERT_TRUE(project_to_pixels(c, corner, px));
            EXPECT_GE(px.x, 0);
            EXPECT_LE(px.x, 320);
            EXPECT_GE(px.y, 0);
            EXPECT_LE(px.y, 240);
        }
    }
    // Distinct viewpoints at the same distance.
    EXPECT_NEAR(glm::length(p.frames[0].eye), glm::length(p.frames[3].eye), 1e-9);
    EXPECT_GT(glm::length(p.frames[0].eye - p.frames[1].eye), 0.1);
}
