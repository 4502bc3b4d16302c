#pragma once
// Private to the points module: one format's streaming reader behind PointFileReader
// (points/point_cloud.h). Each format has exactly one parsing path, a PointSource; the
// whole-file readers (read_point_cloud, read_las, ...) gather its batches through
// PointFileReader, so the streaming and the whole-file paths cannot disagree.
#include <cstdint>
#include <memory>
#include <string>

#include "points/point_cloud.h"

namespace catpaq {

class PointSource {
public:
    explicit PointSource(std::string path) : path_(std::move(path)) {}
    virtual ~PointSource() = default;
    PointSource(const PointSource&) = delete;
    PointSource& operator=(const PointSource&) = delete;

    const std::string& path() const { return path_; }

    // Appends up to `max` (> 0) further points to `batch`, with normals, colours and radii
    // exactly when the flags below say so. Returns how many; 0 only once the file is exhausted,
    // after the format's end-of-file checks (counts, "no points") have passed.
    virtual size_t read(PointCloud& batch, size_t max) = 0;

    // Set by the constructor, which opens the file and reads its header.
    PointReadInfo info;
    bool normals = false, colors = false, radii = false;
    uint64_t expected = 0;  // points announced by the header, 0 if unknown

private:
    std::string path_;
};

// The sources of the formats read_point_cloud reads; each opens `path` and reads its header,
// throwing Error on what it refuses.
std::unique_ptr<PointSource> open_ply_source(const std::string& path);   // read_points.cpp
std::unique_ptr<PointSource> open_mesh_source(const std::string& path);  // read_points.cpp
std::unique_ptr<PointSource> open_xyz_source(const std::string& path);   // read_text.cpp
std::unique_ptr<PointSource> open_pts_source(const std::string& path);   // read_text.cpp
std::unique_ptr<PointSource> open_las_source(const std::string& path);   // read_las.cpp

// Gathers every batch of `reader` into one cloud, which passes validate_point_cloud; copies the
// reader's info into `info` if given. The one loop behind every whole-file reader.
PointCloud read_whole_file(PointFileReader& reader, PointReadInfo* info);

}  // namespace catpaq
