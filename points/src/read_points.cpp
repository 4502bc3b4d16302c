// PLY and mesh-vertex point input, the reader dispatch and validation (points/point_cloud.h).
#include <algorithm>
#include <cmath>
#include <filesystem>

#include "base/error.h"
#include "mesh/io.h"
#include "points/point_cloud.h"

namespace catpaq {

using ull = unsigned long long;

Bounds PointCloud::bounds() const {
    Bounds b;
    for (const Vec3d& p : positions) b.add(p);
    return b;
}

void validate_point_cloud(const PointCloud& cloud, const std::string& what) {
    const size_t n = cloud.positions.size();
    if (n == 0) fail("%s: no points", what.c_str());
    for (size_t i = 0; i < n; ++i) {
        const Vec3d& p = cloud.positions[i];
        if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
            fail("%s: point %zu has a non-finite coordinate (%g, %g, %g)", what.c_str(), i, p[0], p[1], p[2]);
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
            fail("%s: point %zu has a non-finite normal", what.c_str(), i);
    }
    for (size_t i = 0; i < cloud.radii.size(); ++i)
        if (!std::isfinite(cloud.radii[i]) || cloud.radii[i] < 0)
            fail("%s: point %zu has an invalid radius (%g)", what.c_str(), i, double(cloud.radii[i]));
}

PointCloud read_ply_points(const std::string& path, PointReadInfo* info) {
    PlyStream stream(path);
    PointCloud cloud;
    if (stream.vertex_count() == 0) fail("'%s': the PLY file declares no vertices (no points)", path.c_str());
    cloud.positions.reserve(stream.vertex_count());
    std::vector<Vec3f>* normals = stream.has_normals() ? &cloud.normals : nullptr;
    std::vector<Rgb8>* colors = stream.has_colors() ? &cloud.colors : nullptr;
    std::vector<float>* radii = stream.has_radii() ? &cloud.radii : nullptr;
    while (stream.read_vertices(size_t(1) << 20, cloud.positions, normals, colors, radii) > 0) {
    }
    if (info) {
        info->format = "PLY";
        info->dropped = stream.dropped(/*keeps_radii=*/true);
        if (stream.face_count() > 0)
            info->dropped.push_back(strprintf("%llu faces (the vertices are read as points)", ull(stream.face_count())));
    }
    stream.finish();
    return cloud;
}

static PointCloud read_mesh_vertices(const std::string& path, PointReadInfo* info) {
    std::vector<std::string> dropped;
    Mesh mesh = read_mesh(path, &dropped);
    PointCloud cloud;
    cloud.positions = std::move(mesh.positions);
    cloud.normals = std::move(mesh.normals);
    cloud.colors = std::move(mesh.colors);
    if (info) {
        std::string ext = std::filesystem::path(path).extension().string();
        for (char& c : ext) c = char(std::toupper(static_cast<unsigned char>(c)));
        info->format = (ext.size() > 1 ? ext.substr(1) : std::string("mesh")) + " mesh";
        info->dropped = std::move(dropped);
        info->dropped.push_back(strprintf("%zu triangles (the vertices are read as points)", mesh.triangle_count()));
    }
    return cloud;
}

PointCloud read_point_cloud(const std::string& path, PointReadInfo* info) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) fail("cannot open '%s': no such file", path.c_str());
    std::string ext = std::filesystem::path(path).extension().string();
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    PointCloud cloud;
    if (ext == ".ply") cloud = read_ply_points(path, info);
    else if (ext == ".xyz" || ext == ".txt" || ext == ".asc") cloud = read_xyz(path, info);
    else if (ext == ".pts") cloud = read_pts(path, info);
    else if (ext == ".las" || ext == ".laz") cloud = read_las(path, info);
    else if (ext == ".obj" || ext == ".off" || ext == ".stl") cloud = read_mesh_vertices(path, info);
    else fail("'%s': unknown point file type '%s' (known: .ply .xyz .txt .pts .las .obj .off .stl)", path.c_str(), ext.c_str());
    validate_point_cloud(cloud, "'" + path + "'");
    return cloud;
}

}  // namespace catpaq
