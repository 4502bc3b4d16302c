#pragma once
// Point clouds in memory and the readers of point files: PLY (ascii and binary; x y z, optional
// nx ny nz, red green blue, radius or scale), XYZ and PTS text (x y z [intensity] [r g b]; PTS
// has a count line before each scan), LAS 1.0-1.4 (point formats 0-10: positions and, in formats
// 2, 3, 5, 7, 8, 10, colours; LAZ is refused: Debian has no decoder), and the vertices of meshes
// (OBJ, OFF, STL through mesh/io.h; PLY faces are skipped).
//
// PointFileReader reads any of them batch by batch in bounded memory (a batch and fixed
// buffers; mesh vertices excepted), for the out-of-core converter; the whole-file readers
// (read_point_cloud, read_las, ...) gather its batches, so each format has one parsing path and
// both ways give the same points and refuse the same files with the same messages.
//
// Every reader throws catpaq::Error naming the file and the problem for input it refuses:
// missing or empty files, non-finite coordinates, counts that disagree with the data, malformed
// lines (with their number), unsupported LAS versions and formats. Positions are read in double
// precision (LAS: integer * scale + offset) so that scans in projected coordinates (1e6-1e7)
// keep their millimetres.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "mesh/mesh.h"

namespace catpaq {

struct PointCloud {
    std::vector<Vec3d> positions;
    std::vector<Vec3f> normals;  // empty, or one unit normal per point
    std::vector<Rgb8> colors;    // empty, or one colour per point
    std::vector<float> radii;    // empty, or one splat radius (>= 0) per point

    size_t size() const { return positions.size(); }
    bool has_normals() const { return !normals.empty(); }
    bool has_colors() const { return !colors.empty(); }
    bool has_radii() const { return !radii.empty(); }
    Bounds bounds() const;
};

// Checks what a reader guarantees: at least one point, finite coordinates, attribute arrays
// empty or sized like positions, finite non-negative radii. Throws Error naming `what`.
void validate_point_cloud(const PointCloud& cloud, const std::string& what);

// What a reader found besides the points, for the tools to report.
struct PointReadInfo {
    std::string format;                 // "PLY", "XYZ", "PTS", "LAS 1.2 format 3", "OBJ mesh", ...
    std::vector<std::string> dropped;   // content the cloud cannot hold, one sentence per kind
    bool z_up = false;                  // the format's convention is z up (LAS)
};

class PointSource;  // one format's streaming reader (private: points/src/point_source.h)

// Reads a point file (any format read_point_cloud reads, chosen by extension) batch by batch, in
// file order, with the same checks and messages as read_point_cloud. Memory: the batch and fixed
// buffers (text: a few MiB of lines; LAS: 1 MiB of records, which it reads twice when the format
// has RGB, since whether colours are scaled depends on all of them), whatever the file's size;
// except mesh vertices (OBJ, OFF, STL), read whole first: meshes used as point input are moderate.
class PointFileReader {
public:
    // Opens the file and reads its header; throws Error as read_point_cloud does (missing file,
    // unknown extension, malformed or refused header). Text formats have no header: they read
    // ahead to their first point line, whose column count says whether there are colours.
    explicit PointFileReader(const std::string& path);
    // Reads `source`'s format whatever the extension (read_las and the other one-format readers).
    explicit PointFileReader(std::unique_ptr<PointSource> source);
    ~PointFileReader();
    PointFileReader(const PointFileReader&) = delete;
    PointFileReader& operator=(const PointFileReader&) = delete;

    const std::string& path() const;
    // Format, dropped content and z_up: complete once the constructor returns.
    const PointReadInfo& info() const;
    // The same for every batch: a batch's attribute array is sized like its positions or empty.
    bool has_normals() const;
    bool has_colors() const;
    bool has_radii() const;
    uint64_t expected_points() const;  // announced by the header (PLY, LAS, mesh), 0 if unknown (text)
    uint64_t points_read() const;      // points handed out so far (the next batch's first point)

    // Replaces `batch`'s contents by up to `max_points` (> 0) further points, which pass
    // validate_point_cloud's per-point checks; returns false, with an empty batch, once the file is
    // exhausted. Throws Error (naming the file and the file-global point or line number) on what
    // read_point_cloud refuses, including at the end: no points at all, counts that disagree with
    // the data. The batch's capacity is kept, so reusing one batch allocates once.
    bool next(PointCloud& batch, size_t max_points);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// Reads any supported file, chosen by extension (.ply .xyz .txt .pts .las .laz .obj .off .stl,
// case-insensitive): PointFileReader's batches gathered. The result passes validate_point_cloud.
PointCloud read_point_cloud(const std::string& path, PointReadInfo* info = nullptr);

// At most `max_points` (> 0) points of the file, a uniform random sample when it holds more (one
// pass, reservoir sampling with a fixed seed: the same sample on every run), in no particular
// order; every point when it holds no more. Memory: the sample and a batch. `total`, if given,
// receives the file's point count. Checks and messages as read_point_cloud.
PointCloud read_point_sample(const std::string& path, size_t max_points, PointReadInfo* info = nullptr,
                             uint64_t* total = nullptr);

// The readers of one format, whatever the extension (also through PointFileReader).
PointCloud read_ply_points(const std::string& path, PointReadInfo* info = nullptr);
// XYZ: one point per line, 3, 4, 6 or 7 numbers: x y z, x y z intensity, x y z r g b,
// x y z intensity r g b; every line has the same count. '#' starts a comment; blank lines are
// skipped. Colours are integers 0..255.
PointCloud read_xyz(const std::string& path, PointReadInfo* info = nullptr);
// PTS (Leica): a line with the point count, then that many XYZ-style lines; a file may hold
// several such scans one after the other. Fewer or more lines than counted are refused.
PointCloud read_pts(const std::string& path, PointReadInfo* info = nullptr);
// LAS 1.0-1.4, uncompressed. Colours are 16-bit in LAS: they are scaled to 8 bits, except in
// files whose colours all fit in 0..255 (writers that store 8-bit values), which are kept as is.
PointCloud read_las(const std::string& path, PointReadInfo* info = nullptr);

// Writes a LAS file (tests and fixtures; the file appears atomically). Version 1.2 for point
// formats 0-3, 1.4 for formats 6-8. Coordinates are stored as integers of `scale` around the
// bounds' minimum (every coordinate must be within 2^31 steps of it); colours (formats 2, 3, 7,
// 8) as 16-bit values v * 257, black where the cloud has none.
void write_las(const std::string& path, const PointCloud& cloud, int point_format, double scale = 0.001);

}  // namespace catpaq
