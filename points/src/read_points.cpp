// PLY and mesh-vertex point input, PointFileReader (the format dispatch and the per-batch
// checks), the whole-file readers over it, and validation (points/point_cloud.h).
#include <algorithm>
#include <cassert>
#include <cmath>
#include <filesystem>

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include "base/error.h"
#include "mesh/io.h"
#include "point_source.h"
#include "points/point_cloud.h"

namespace catpaq {

using ull = unsigned long long;

// In parallel: one pass over 2.4 GB of positions at 100M points.
Bounds PointCloud::bounds() const {
    return tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, positions.size(), 1 << 16), Bounds(),
        [&](const tbb::blocked_range<size_t>& r, Bounds b) {
            for (size_t i = r.begin(); i < r.end(); ++i) b.add(positions[i]);
            return b;
        },
        [](Bounds x, const Bounds& y) {
            if (!y.empty()) {
                x.add(y.min);
                x.add(y.max);
            }
            return x;
        });
}

namespace {

// validate_point_cloud's checks but "at least one point", on points numbered from `first` (a
// batch's place in its file, so that messages name file-global points).
void check_points(const PointCloud& cloud, const std::string& what, uint64_t first) {
    const size_t n = cloud.positions.size();
    for (size_t i = 0; i < n; ++i) {
        const Vec3d& p = cloud.positions[i];
        if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
            fail("%s: point %llu has a non-finite coordinate (%g, %g, %g)", what.c_str(), ull(first + i), p[0], p[1], p[2]);
    }
    if (!cloud.normals.empty() && cloud.normals.size() != n)
        fail("%s: %zu normals for %zu points", what.c_str(), cloud.normals.size(), n);
    if (!cloud.colors.empty() && cloud.colors.size() != n)
        fail("%s: %zu colours for %zu points", what.c_str(), cloud.colors.size(), n);
    if (!cloud.radii.empty() && cloud.radii.size() != n)
        fail("%s: %zu radii for %zu points", what.c_str(), cloud.radii.size(), n);
    for (size_t i = 0; i < cloud.normals.size(); ++i) {
        const Vec3f& v = cloud.normals[i];
        if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2]))
            fail("%s: point %llu has a non-finite normal", what.c_str(), ull(first + i));
    }
    for (size_t i = 0; i < cloud.radii.size(); ++i)
        if (!std::isfinite(cloud.radii[i]) || cloud.radii[i] < 0)
            fail("%s: point %llu has an invalid radius (%g)", what.c_str(), ull(first + i), double(cloud.radii[i]));
}

// PLY vertices through PlyStream, which already reads in chunks and numbers vertices from the
// start of the file; the faces (and any other element) are skipped by finish() at the end.
class PlySource final : public PointSource {
public:
    explicit PlySource(const std::string& path) : PointSource(path), stream_(path) {
        if (stream_.vertex_count() == 0) fail("'%s': the PLY file declares no vertices (no points)", path.c_str());
        normals = stream_.has_normals();
        colors = stream_.has_colors();
        radii = stream_.has_radii();
        expected = stream_.vertex_count();
        info.format = "PLY";
        info.dropped = stream_.dropped(/*keeps_radii=*/true);
        if (stream_.face_count() > 0)
            info.dropped.push_back(strprintf("%llu faces (the vertices are read as points)", ull(stream_.face_count())));
    }

    size_t read(PointCloud& batch, size_t max) override {
        if (finished_) return 0;
        size_t n = stream_.read_vertices(max, batch.positions, normals ? &batch.normals : nullptr,
                                         colors ? &batch.colors : nullptr, radii ? &batch.radii : nullptr);
        if (n == 0) {
            stream_.finish();  // the file must end where the header says
            finished_ = true;
        }
        return n;
    }

private:
    PlyStream stream_;
    bool finished_ = false;
};

// A mesh's vertices. The whole mesh is read first (read_mesh welds STL corners and checks the
// faces, which needs all of it), then handed out in batches from memory: meshes used as point
// input are moderate, so this is the one format whose streaming path holds the file.
class MeshSource final : public PointSource {
public:
    explicit MeshSource(const std::string& path) : PointSource(path) {
        std::vector<std::string> dropped;
        mesh_ = read_mesh(path, &dropped);
        normals = !mesh_.normals.empty();
        colors = !mesh_.colors.empty();
        expected = mesh_.positions.size();
        std::string ext = std::filesystem::path(path).extension().string();
        for (char& c : ext) c = char(std::toupper(static_cast<unsigned char>(c)));
        info.format = (ext.size() > 1 ? ext.substr(1) : std::string("mesh")) + " mesh";
        info.dropped = std::move(dropped);
        info.dropped.push_back(strprintf("%zu triangles (the vertices are read as points)", mesh_.triangle_count()));
        mesh_.indices = {};  // only the vertices are handed out
    }

    size_t read(PointCloud& batch, size_t max) override {
        const size_t first = next_, n = std::min(max, mesh_.positions.size() - next_);
        batch.positions.insert(batch.positions.end(), mesh_.positions.begin() + first, mesh_.positions.begin() + first + n);
        if (normals) batch.normals.insert(batch.normals.end(), mesh_.normals.begin() + first, mesh_.normals.begin() + first + n);
        if (colors) batch.colors.insert(batch.colors.end(), mesh_.colors.begin() + first, mesh_.colors.begin() + first + n);
        next_ += n;
        return n;
    }

private:
    Mesh mesh_;
    size_t next_ = 0;
};

std::string lower_extension(const std::string& path) {
    std::string ext = std::filesystem::path(path).extension().string();
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    return ext;
}

// The source for `path`'s format, chosen by extension as read_point_cloud documents.
std::unique_ptr<PointSource> open_source(const std::string& path) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) fail("cannot open '%s': no such file", path.c_str());
    const std::string ext = lower_extension(path);
    if (ext == ".ply") return open_ply_source(path);
    if (ext == ".xyz" || ext == ".txt" || ext == ".asc") return open_xyz_source(path);
    if (ext == ".pts") return open_pts_source(path);
    if (ext == ".las" || ext == ".laz") return open_las_source(path);
    if (ext == ".obj" || ext == ".off" || ext == ".stl") return open_mesh_source(path);
    fail("'%s': unknown point file type '%s' (known: .ply .xyz .txt .pts .las .obj .off .stl)", path.c_str(), ext.c_str());
}

}  // namespace

void validate_point_cloud(const PointCloud& cloud, const std::string& what) {
    if (cloud.positions.empty()) fail("%s: no points", what.c_str());
    check_points(cloud, what, 0);
}

std::unique_ptr<PointSource> open_ply_source(const std::string& path) { return std::make_unique<PlySource>(path); }
std::unique_ptr<PointSource> open_mesh_source(const std::string& path) { return std::make_unique<MeshSource>(path); }

// ---------------------------------------------------------------------------------------------
// PointFileReader

struct PointFileReader::Impl {
    std::unique_ptr<PointSource> source;
    std::string what;         // "'path'", as messages name the file
    uint64_t delivered = 0;   // points handed out so far: the next batch's first point number
    bool exhausted = false;
};

PointFileReader::PointFileReader(const std::string& path) : PointFileReader(open_source(path)) {}

PointFileReader::PointFileReader(std::unique_ptr<PointSource> source) : impl_(std::make_unique<Impl>()) {
    impl_->what = "'" + source->path() + "'";
    impl_->source = std::move(source);
}

PointFileReader::~PointFileReader() = default;

const std::string& PointFileReader::path() const { return impl_->source->path(); }
const PointReadInfo& PointFileReader::info() const { return impl_->source->info; }
bool PointFileReader::has_normals() const { return impl_->source->normals; }
bool PointFileReader::has_colors() const { return impl_->source->colors; }
bool PointFileReader::has_radii() const { return impl_->source->radii; }
uint64_t PointFileReader::expected_points() const { return impl_->source->expected; }
uint64_t PointFileReader::points_read() const { return impl_->delivered; }

bool PointFileReader::next(PointCloud& batch, size_t max_points) {
    assert(max_points > 0);
    // clear() keeps the capacity: a caller that reuses its batch allocates once.
    batch.positions.clear();
    batch.normals.clear();
    batch.colors.clear();
    batch.radii.clear();
    Impl& s = *impl_;
    if (s.exhausted) return false;
    const size_t n = s.source->read(batch, max_points);
    if (n == 0) {
        s.exhausted = true;
        // Formats check this with their own words; this is the net under all of them.
        if (s.delivered == 0) fail("%s: no points", s.what.c_str());
        return false;
    }
    assert(n <= max_points && batch.positions.size() == n);
    assert(batch.normals.size() == (has_normals() ? n : 0) && batch.colors.size() == (has_colors() ? n : 0) &&
           batch.radii.size() == (has_radii() ? n : 0));
    check_points(batch, s.what, s.delivered);
    s.delivered += n;
    return true;
}

// ---------------------------------------------------------------------------------------------
// Whole-file readers

PointCloud read_whole_file(PointFileReader& reader, PointReadInfo* info) {
    // Batches big enough that the per-call overhead vanishes, small enough to stay in cache.
    constexpr size_t kBatch = size_t(1) << 16;
    PointCloud cloud, batch;
    if (const uint64_t n = reader.expected_points()) {
        cloud.positions.reserve(size_t(n));
        if (reader.has_normals()) cloud.normals.reserve(size_t(n));
        if (reader.has_colors()) cloud.colors.reserve(size_t(n));
        if (reader.has_radii()) cloud.radii.reserve(size_t(n));
    }
    while (reader.next(batch, kBatch)) {
        cloud.positions.insert(cloud.positions.end(), batch.positions.begin(), batch.positions.end());
        cloud.normals.insert(cloud.normals.end(), batch.normals.begin(), batch.normals.end());
        cloud.colors.insert(cloud.colors.end(), batch.colors.begin(), batch.colors.end());
        cloud.radii.insert(cloud.radii.end(), batch.radii.begin(), batch.radii.end());
    }
    if (info) *info = reader.info();
    validate_point_cloud(cloud, "'" + reader.path() + "'");
    return cloud;
}

PointCloud read_point_cloud(const std::string& path, PointReadInfo* info) {
    PointFileReader reader(path);
    return read_whole_file(reader, info);
}

PointCloud read_point_sample(const std::string& path, size_t max_points, PointReadInfo* info, uint64_t* total) {
    if (max_points == 0) fail("a sample of '%s' needs at least one point", path.c_str());
    PointFileReader reader(path);
    if (reader.expected_points() && reader.expected_points() <= max_points) {
        if (total) *total = reader.expected_points();
        return read_whole_file(reader, info);
    }
    constexpr size_t kBatch = size_t(1) << 16;
    PointCloud sample, batch;
    uint64_t seen = 0, state = 0x9e3779b97f4a7c15ULL;  // splitmix64, fixed seed
    auto random = [&state] {
        uint64_t z = (state += 0x9e3779b97f4a7c15ULL);
        z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
        z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
        return z ^ (z >> 31);
    };
    while (reader.next(batch, kBatch)) {
        for (size_t i = 0; i < batch.size(); ++i, ++seen) {
            // Algorithm R: point `seen` takes a random slot of the first seen + 1 ones.
            size_t slot = sample.size();
            if (seen >= max_points) {
                const uint64_t j = random() % (seen + 1);
                if (j >= max_points) continue;
                slot = size_t(j);
            } else {
                sample.positions.emplace_back();
                if (batch.has_normals()) sample.normals.emplace_back();
                if (batch.has_colors()) sample.colors.emplace_back();
                if (batch.has_radii()) sample.radii.emplace_back();
            }
            sample.positions[slot] = batch.positions[i];
            if (batch.has_normals()) sample.normals[slot] = batch.normals[i];
            if (batch.has_colors()) sample.colors[slot] = batch.colors[i];
            if (batch.has_radii()) sample.radii[slot] = batch.radii[i];
        }
    }
    if (info) *info = reader.info();
    if (total) *total = seen;
    validate_point_cloud(sample, "'" + reader.path() + "'");
    return sample;
}

PointCloud read_ply_points(const std::string& path, PointReadInfo* info) {
    PointFileReader reader(open_ply_source(path));
    return read_whole_file(reader, info);
}

}  // namespace catpaq
