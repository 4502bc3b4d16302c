#include "point_datasets.h"

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <tuple>
#include <vector>

#include "base/error.h"
#include "mesh/generators.h"
#include "points/sampling.h"
#include "scratch_directory.h"

namespace fs = std::filesystem;

namespace catpaq::test {

std::string points_scratch_dir() {
    static const ScratchDirectory dir("catpaq_points_client_");
    return dir.string();
}

const std::string& points_dataset(const PointSet& set) {
    static std::map<std::tuple<int, size_t, int, size_t, double, bool, bool>, std::string> built;
    const auto key = std::make_tuple(int(set.model), set.points, int(set.split), set.node_points, set.offset, set.colors,
                                     set.normals);
    auto it = built.find(key);
    if (it != built.end()) return it->second;
    // A finely triangulated mesh, so the samples lie on the smooth surface within a hair.
    Mesh mesh = set.model == PointSet::Sphere ? make_sphere(40000, 3) : make_scan_like(40000, 7);
    PointCloud cloud = sample_surface(mesh, set.points, 11, set.normals, set.colors);
    for (Vec3d& p : cloud.positions)
        for (double& c : p) c += set.offset;
    const std::string path = points_scratch_dir() + "/points_" + std::to_string(built.size()) + ".cpq";
    PointsBuildSettings settings;
    settings.split = set.split;
    settings.node_points = set.node_points;
    settings.progress = false;
    settings.threads = 2;
    build_points(std::move(cloud), path, settings);
    return built.emplace(key, path).first->second;
}

DatasetPrefix read_prefix(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) fail("cannot open '%s'", path.c_str());
    std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    return DatasetPrefix::parse(bytes.data(), bytes.size(), path);
}

}  // namespace catpaq::test
