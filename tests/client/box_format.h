#pragma once
// A second dataset format, for the tests only: it proves the format seam (client/format.h). Its
// nodes are the cells of a quadtree over the square [0, size]^2 in the plane z = 0, each drawing
// its cell as a grid of triangles whose payload is plain floats. It is written with ArchiveWriter
// as an archive of kind Points (the tests' own registries map that kind to it) and streamed by
// the very fetcher, caches, cut engine, session and server that stream CATP, unchanged.
//
//   meta   char[8] "BOXMETA1" | f64 size | u32 levels | u32 grid
//   node   key = level << 56 | y << 28 | x (cell x, y of the level), level, count = triangles,
//          error = the cell's side / grid / 2 (monotone), flags 0;
//          payload: u32 triangles | triangles * 9 f32 (world x, y, z of each corner)
//   parts  one per node (id 0), created by its parent cell (the root's: always)
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "client/format.h"

namespace catpaq::test {

struct BoxDatasetSettings {
    int levels = 5;  // level 0 is the root cell; the leaves are at levels - 1
    int grid = 4;    // quads per cell side: 2 * grid^2 triangles per node
    double size = 100;
};

// Writes the dataset: every cell of every level, 4^level cells per level.
void write_box_dataset(const std::string& path, const BoxDatasetSettings& settings);

// The triangles of a decoded node.
class BoxNode : public DecodedNode {
public:
    std::vector<float> corners;  // 9 floats per triangle
};

class BoxFormat : public DatasetFormat {
public:
    explicit BoxFormat(const DatasetPrefix& prefix);  // throws Error

    const Hierarchy& hierarchy() const override { return hierarchy_; }
    std::string decode(uint32_t node, const uint8_t* data, size_t size,
                       std::shared_ptr<const DecodedNode>& out) const override;
    // The distance to the box of its triangles: a lower bound of the distance to them.
    std::optional<double> data_distance(uint32_t node, const DecodedNode& decoded,
                                        const std::array<double, 3>& eye) const override;
    // Positions relative to the eye.
    DrawnGeometry drawn_geometry(const std::vector<DecodedPart>& parts, const std::array<double, 3>& eye) const override;
    Aabb world_bounds() const override;
    int up_axis() const override { return 2; }
    FormatSummary summary() const override;

    double size() const { return size_; }
    int levels() const { return levels_; }
    int grid() const { return grid_; }

private:
    double size_ = 0;
    int levels_ = 0, grid_ = 0;
    Hierarchy hierarchy_;
};

// The CPU side only (create_renderer left empty): what a test without GL registers.
FormatModule box_format_module();

}  // namespace catpaq::test
