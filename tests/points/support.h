#pragma once
// Helpers for the point tests: a per-process scratch directory, small deterministic clouds, and
// an assertion that a call fails with a message naming what is wrong.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <string>
#include <unistd.h>

#include "base/atomic_file.h"
#include "base/error.h"
#include "points/point_cloud.h"
#include "scratch_directory.h"

namespace catpaq::test {

inline std::string scratch(const std::string& name) {
    static const ScratchDirectory dir("catpaq_points_");
    return (dir / name).string();
}

inline std::string write_text(const std::string& name, const std::string& content) {
    std::string path = scratch(name);
    std::ofstream out(path, std::ios::binary);
    out.write(content.data(), std::streamsize(content.size()));
    return path;
}

inline uint64_t next_random(uint64_t& state) {
    uint64_t z = (state += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
}
inline double random_unit(uint64_t& state) { return double(next_random(state) >> 11) * 0x1p-53; }

// `count` points on a sphere of radius `radius` around `centre`, with colours, no normals.
inline PointCloud sphere_cloud(size_t count, double radius = 1.0, Vec3d centre = {0, 0, 0}, uint64_t seed = 1) {
    PointCloud cloud;
    uint64_t state = seed;
    for (size_t i = 0; i < count; ++i) {
        double z = 2 * random_unit(state) - 1, phi = 2 * M_PI * random_unit(state), s = std::sqrt(1 - z * z);
        cloud.positions.push_back({centre[0] + radius * s * std::cos(phi), centre[1] + radius * s * std::sin(phi),
                                   centre[2] + radius * z});
        cloud.colors.push_back({uint8_t(128 + 127 * z), uint8_t(i % 256), uint8_t(255 * random_unit(state))});
    }
    return cloud;
}

// Passes if `call` throws catpaq::Error whose message contains every one of `words`.
template <class Call>
::testing::AssertionResult fails_with(Call call, std::initializer_list<const char*> words) {
    try {
        call();
    } catch (const Error& e) {
        std::string message = e.what();
        for (const char* word : words)
            if (message.find(word) == std::string::npos)
                return ::testing::AssertionFailure() << "message '" << message << "' lacks '" << word << "'";
        return ::testing::AssertionSuccess();
    } catch (const std::exception& e) {
        return ::testing::AssertionFailure() << "threw a non-catpaq exception: " << e.what();
    }
    return ::testing::AssertionFailure() << "did not throw";
}

}  // namespace catpaq::test
