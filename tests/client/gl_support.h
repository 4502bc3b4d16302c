#pragma once
// Shared by the client GL tests: one headless context for the whole process, datasets built
// once per process in a scratch directory, and image helpers.
#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

#include "catp/builder.h"
#include "catp/cut.h"
#include "catp/dataset.h"
#include "client/camera.h"
#include "client/gl_context.h"

namespace catpaq::test {

// The process-wide context, created on first use and made current; nullptr (with the reason)
// if EGL cannot create one. Tests call GL_TEST_CONTEXT() first.
HeadlessGlContext* gl_context(std::string* why);

#define GL_TEST_CONTEXT()                                                      \
    do {                                                                       \
        std::string why_;                                                      \
        if (!::catpaq::test::gl_context(&why_)) GTEST_SKIP() << "no EGL: " << why_; \
    } while (0)

std::string scratch_dir();  // per process, removed at exit

enum class Model { Sphere, Torus };
// A CATP dataset of the model (built on first use, cached for the process). `leaf_level` is
// forced; the sphere and torus have `triangles` input triangles (with colours).
const std::string& dataset_path(Model model, size_t triangles, int leaf_level, LayoutChoice layout = LayoutChoice::Auto);

// Cameras for a dataset: orbit frames around its bounds plus a close-up.
std::vector<Camera> test_cameras(const CatpIndex& index, int width, int height);

// Coverage: mask[y * width + x] = pixel differs from the background colour.
std::vector<uint8_t> coverage(const std::vector<uint8_t>& rgba, int width, int height, const uint8_t background[3]);
// Chebyshev erosion: a pixel stays set if every pixel within `radius` is set (outside the image
// counts as unset).
std::vector<uint8_t> erode(const std::vector<uint8_t>& mask, int width, int height, int radius);

// Saves an image under the scratch directory when CATPAQ_TEST_IMAGES is set (for debugging).
void maybe_save(const std::string& name, const std::vector<uint8_t>& rgba, int width, int height);

}  // namespace catpaq::test
