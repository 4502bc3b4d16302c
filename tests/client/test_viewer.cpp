// The desktop viewer: the orbit controller and ray-triangle test alone, and `catpaq view` run as
// a child process under Xvfb (a real GLFW window on llvmpipe) and without any display.
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>

#include <gtest/gtest.h>

#include "shell_run.h"

#include "base/child_process.h"
#include "catp/builder.h"
#include "client/gl_context.h"
#include "client/image.h"
#include "client/session.h"
#include "client/viewer.h"
#include "mesh/generators.h"
#include "scratch_directory.h"

namespace fs = std::filesystem;
using namespace catpaq;

using namespace catpaq::client_test;

namespace {

const fs::path& scratch_dir() {
    static const test::ScratchDirectory dir("catpaq_viewer_");
    return dir.path();
}

const std::string& sphere_dataset() {
    static std::string path = [] {
        std::string p = (scratch_dir() / "sphere.cpq").string();
        CatpBuildSettings settings;
        settings.leaf_triangles = 500;
        settings.progress = false;
        build_catp(make_sphere(20000), p, settings);
        return p;
    }();
    return path;
}


}  // namespace

TEST(OrbitController, CameraLooksAtTargetWithUpAxis) {
    for (int up_axis : {1, 2}) {
        OrbitController c(up_axis);
        c.frame_box({-1, -1, -1}, {1, 1, 1}, 45, 4.0 / 3.0);
        Camera cam = c.camera(640, 480);
        EXPECT_EQ(cam.problem(), "");
        EXPECT_NEAR(glm::length(cam.target), 0, 1e-12);
        EXPECT_EQ(cam.up[up_axis], 1.0);
        // The bounding sphere (radius sqrt 3) fits: the eye is outside it.
        EXPECT_GT(glm::length(cam.eye - cam.target), std::sqrt(3.0));
        // Orbiting keeps the distance; the elevation is clamped below the pole.
        double d = c.distance();
        c.orbit(1000, -100000);
        cam = c.camera(640, 480);
        EXPECT_NEAR(glm::length(cam.eye - cam.target), d, 1e-9 * d);
        EXPECT_EQ(cam.problem(), "");
        EXPECT_LT(c.elevation(), 0);
        EXPECT_GT(c.elevation(), -std::acos(-1.0) / 2);
    }
}

TEST(OrbitController, PanDollyAndFlyTo) {
    OrbitController c(2);
    c.frame_box({-1, -1, -1}, {1, 1, 1}, 45, 1.0);
    double d = c.distance();
    c.dolly(2);
    EXPECT_NEAR(c.distance(), d * 0.85 * 0.85, 1e-12);
    c.dolly(-2);
    EXPECT_NEAR(c.distance(), d, 1e-12);

    // Panning right moves the target left in the view, perpendicular to the view direction.
    Camera before = c.camera(100, 100);
    c.pan(10, 0, 100);
    Camera after = c.camera(100, 100);
    glm::dvec3 moved = after.target - before.target;
    EXPECT_GT(glm::length(moved), 0);
    EXPECT_NEAR(glm::dot(moved, before.forward()), 0, 1e-12);
    EXPECT_NEAR(glm::dot(after.eye - after.target, before.eye - before.target),
                glm::dot(before.eye - before.target, before.eye - before.target), 1e-9);

    // Fly-to reaches the point after the animation time, not before.
    glm::dvec3 p(0.5, 0.25, -0.5);
    c.fly_to(p, 0.5);
    c.update(10.0);
    EXPECT_TRUE(c.flying());
    c.update(10.25);
    EXPECT_GT(glm::length(c.target() - p), 1e-6);
    c.update(10.5);
    EXPECT_FALSE(c.flying());
    EXPECT_NEAR(glm::length(c.target() - p), 0, 1e-12);
}

TEST(Picking, PixelRayAndTriangle) {
    Camera cam;
    cam.eye = {0, -5, 0};
    cam.target = {0, 0, 0};
    cam.up = {0, 0, 1};
    cam.width = 200;
    cam.height = 100;
    // The centre of the image looks at the target.
    Ray r = pixel_ray(cam, 100, 50);
    EXPECT_NEAR(glm::length(glm::normalize(r.direction) - glm::dvec3(0, 1, 0)), 0, 1e-12);
    // Above the centre is up (+z), right of it is +x.
    EXPECT_GT(pixel_ray(cam, 100, 10).direction.z, 0);
    EXPECT_GT(pixel_ray(cam, 190, 50).direction.x, 0);
    // A triangle in the plane y = 0 around the origin is hit at distance 5.
    glm::dvec3 a(-1, 0, -1), b(1, 0, -1), c(0, 0, 1);
    std::optional<double> t = intersect_triangle(r, a, b, c);
    ASSERT_TRUE(t.has_value());
    EXPECT_NEAR(r.origin.y + *t * r.direction.y, 0, 1e-12);
    EXPECT_TRUE(intersect_triangle(r, a, c, b).has_value());  // double-sided
    // Missing it: a ray through the corner of the image.
    EXPECT_FALSE(intersect_triangle(pixel_ray(cam, 0, 0), a, b, c).has_value());
    // Behind the origin.
    Ray back{{0, 1, 0}, {0, 1, 0}};
    EXPECT_FALSE(intersect_triangle(back, a, b, c).has_value());
}

TEST(Picking, RayAgainstTheDrawnCut) {
    std::string why;
    if (!HeadlessGlContext::available(&why)) GTEST_SKIP() << why;
    HeadlessGlContext context;
    StreamingSession session(sphere_dataset(), SessionSettings{});
    const Aabb bounds = session.format().world_bounds();
    glm::dvec3 bmin(bounds.min[0], bounds.min[1], bounds.min[2]);
    glm::dvec3 bmax(bounds.max[0], bounds.max[1], bounds.max[2]);
    OrbitController controller(2);
    controller.frame_box(bmin, bmax, 45, 320.0 / 240.0);
    Camera camera = controller.camera(320, 240);
    for (int i = 0; i < 20000 && !(i > 0 && session.settled()); ++i) {
        session.step(camera);
        usleep(1000);
    }
    ASSERT_TRUE(session.settled());
    ASSERT_FALSE(session.items().empty());
    glm::dvec3 centre = (bmin + bmax) * 0.5;
    double radius = (bmax.x - bmin.x) * 0.5;
    // The centre of the image hits the near side of the sphere.
    std::optional<glm::dvec3> hit = pick_cut(session, camera, pixel_ray(camera, 160, 120));
    ASSERT_TRUE(hit.has_value());
    EXPECT_NEAR(glm::length(*hit - centre), radius, radius * 0.02);
    EXPECT_LT(glm::length(*hit - camera.eye), glm::length(centre - camera.eye));
    // An off-centre pixel on the sphere, also on its surface.
    hit = pick_cut(session, camera, pixel_ray(camera, 180, 100));
    ASSERT_TRUE(hit.has_value());
    EXPECT_NEAR(glm::length(*hit - centre), radius, radius * 0.02);
    // The corner of the image misses.
    EXPECT_FALSE(pick_cut(session, camera, pixel_ray(camera, 0.5, 0.5)).has_value());
}

TEST(ViewCommand, RendersUnderXvfb) {
    if (access("/usr/bin/xvfb-run", X_OK) != 0) GTEST_SKIP() << "xvfb-run is not installed";
    ASSERT_TRUE(fs::exists(catpaq_binary())) << catpaq_binary();
    const std::string& dataset = sphere_dataset();
    std::string png = (scratch_dir() / "view.png").string();
    std::string output;
    int status = run("/usr/bin/xvfb-run -a -s \"-screen 0 1280x800x24\" " + catpaq_binary() + " view " + dataset +
                         " --frames 30 --screenshot " + png + " --size 320x240",
                     output);
    ASSERT_EQ(status, 0) << output;
    ASSERT_TRUE(fs::exists(png)) << output;
    RgbaImage image = read_png(png);
    ASSERT_EQ(image.width, 320);
    ASSERT_EQ(image.height, 240);
    // The top-left pixel is background (the sphere is framed in the middle); count both kinds.
    const uint8_t* bg = image.rgba.data();
    size_t background = 0, model = 0;
    for (size_t i = 0; i < image.rgba.size(); i += 4) {
        bool same = std::abs(int(image.rgba[i]) - bg[0]) <= 2 && std::abs(int(image.rgba[i + 1]) - bg[1]) <= 2 &&
                    std::abs(int(image.rgba[i + 2]) - bg[2]) <= 2;
        (same ? background : model)++;
    }
    size_t total = size_t(image.width) * size_t(image.height);
    EXPECT_GT(background, total / 10) << output;
    EXPECT_GT(model, total / 20) << output;
    // The centre pixel is on the sphere.
    size_t centre = (size_t(image.height / 2) * size_t(image.width) + size_t(image.width / 2)) * 4;
    EXPECT_FALSE(image.rgba[centre] == bg[0] && image.rgba[centre + 1] == bg[1] && image.rgba[centre + 2] == bg[2]);
}

TEST(ViewCommand, FailsCleanlyWithoutDisplay) {
    ASSERT_TRUE(fs::exists(catpaq_binary())) << catpaq_binary();
    const std::string& dataset = sphere_dataset();
    std::string output;
    int status = run("env -u DISPLAY -u WAYLAND_DISPLAY " + catpaq_binary() + " view " + dataset + " --frames 2",
                     output);
    EXPECT_NE(status, 0) << output;
    EXPECT_NE(status, -1) << "crashed: " << output;
    EXPECT_NE(output.find("no display"), std::string::npos) << output;
    EXPECT_NE(output.find("catpaq render"), std::string::npos) << output;
}

TEST(ViewCommand, RejectsBadOptions) {
    ASSERT_TRUE(fs::exists(catpaq_binary())) << catpaq_binary();
    std::string output;
    // Usage errors: exit status 2, as for every command.
    EXPECT_EQ(run("env -u DISPLAY " + catpaq_binary() + " view x.cpq --up w", output), 2) << output;
    EXPECT_NE(output.find("--up"), std::string::npos) << output;
    EXPECT_EQ(run("env -u DISPLAY " + catpaq_binary() + " view x.cpq --size 3", output), 2) << output;
    EXPECT_NE(output.find("--size"), std::string::npos) << output;
}

// Screenshots taken with P or F12 are numbered from the first free name: an earlier screenshot
// (of this run or of another) is never replaced (each run used to start again at 0000).
TEST(Screenshots, TakeTheFirstFreeNumber) {
    fs::path dir = scratch_dir() / "shots";
    fs::create_directories(dir);
    EXPECT_EQ(next_screenshot_path(dir.string()), (dir / "catpaq_view_0000.png").string());
    std::fclose(std::fopen((dir / "catpaq_view_0000.png").c_str(), "w"));
    std::fclose(std::fopen((dir / "catpaq_view_0001.png").c_str(), "w"));
    std::fclose(std::fopen((dir / "catpaq_view_0003.png").c_str(), "w"));
    EXPECT_EQ(next_screenshot_path(dir.string()), (dir / "catpaq_view_0002.png").string());
}

// Left alone, the viewer draws only while something changes: once the view has settled it sleeps
// in the event queue. Before, it redrew at the display's rate and used 0.9 of a core while idle
// (more under Xvfb's software GL). The whole run, Xvfb included, must use well under a core.
TEST(ViewCommand, DrawsOnDemandAndIdlesWithoutUsingACore) {
    if (access("/usr/bin/xvfb-run", X_OK) != 0) GTEST_SKIP() << "xvfb-run is not installed";
    const double seconds = 5;
    ChildRun r = run_measured({"/usr/bin/xvfb-run", "-a", "-s", "-screen 0 1280x800x24", catpaq_binary(), "view",
                               sphere_dataset(), "--size", "320x240", "--exit-after", std::to_string(seconds)},
                              (scratch_dir() / "idle.txt").string());
    ASSERT_EQ(r.status, 0) << r.output;
    EXPECT_GE(r.seconds, seconds);
    EXPECT_LT(r.cpu_seconds, 0.4 * seconds) << r.cpu_seconds << " s of CPU in " << r.seconds << " s\n" << r.output;
    std::printf("idle view: %.2f s of CPU in %.2f s\n", r.cpu_seconds, r.seconds);
}

// A node that cannot be loaded is named (on stderr, and in the overlay) and the viewer keeps
// showing the coarser data instead of stopping.
TEST(ViewCommand, ShowsAFailedNodeAndKeepsTheCoarserData) {
    if (access("/usr/bin/xvfb-run", X_OK) != 0) GTEST_SKIP() << "xvfb-run is not installed";
    std::string bytes;
    {
        std::FILE* f = std::fopen(sphere_dataset().c_str(), "rb");
        char buffer[65536];
        size_t n;
        while ((n = std::fread(buffer, 1, sizeof buffer, f)) > 0) bytes.append(buffer, n);
        std::fclose(f);
    }
    bytes[bytes.size() - 100] ^= 0x40;  // inside the last (finest) node
    fs::path corrupt = scratch_dir() / "corrupt.cpq", png = scratch_dir() / "corrupt.png";
    {
        std::FILE* f = std::fopen(corrupt.c_str(), "wb");
        std::fwrite(bytes.data(), 1, bytes.size(), f);
        std::fclose(f);
    }
    std::string output;
    // A tolerance that wants the finest level everywhere, and time past the fetcher's retries.
    int status = run("/usr/bin/xvfb-run -a -s \"-screen 0 1280x800x24\" " + catpaq_binary() + " view " +
                         corrupt.string() + " --size 320x240 --tolerance 0.3 --exit-after 3 --screenshot " + png.string(),
                     output);
    ASSERT_EQ(status, 0) << output;
    EXPECT_NE(output.find("cannot be loaded"), std::string::npos) << output;
    EXPECT_NE(output.find("showing the coarser data"), std::string::npos) << output;
    ASSERT_TRUE(fs::exists(png)) << output;
    RgbaImage image = read_png(png.string());
    size_t centre = (size_t(image.height / 2) * size_t(image.width) + size_t(image.width / 2)) * 4;
    const uint8_t* bg = image.rgba.data();
    EXPECT_FALSE(image.rgba[centre] == bg[0] && image.rgba[centre + 1] == bg[1] && image.rgba[centre + 2] == bg[2])
        << "the sphere is not on screen";
}
