#pragma once
// Point datasets for the client plug-in's tests, built once per process with points::build_points
// from clouds sampled on generated meshes, in a scratch directory removed at exit.
#include <array>
#include <cstddef>
#include <string>

#include "client/format.h"
#include "points/builder.h"

namespace catpaq::test {

struct PointSet {
    enum Model { Sphere, ScanLike } model = Sphere;
    size_t points = 100000;
    PointSplitRule split = PointSplitRule::Balanced;
    size_t node_points = 4096;
    double offset = 0;  // added to every coordinate (1e7: far from the origin)
    bool colors = true;
    bool normals = true;  // false: the converter estimates them
};

// The dataset's path (built on first use).
const std::string& points_dataset(const PointSet& set);
std::string points_scratch_dir();

// The dataset's prefix (header, meta, index) read from the file.
DatasetPrefix read_prefix(const std::string& path);

}  // namespace catpaq::test
