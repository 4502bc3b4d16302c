#include "points/sampling.h"

#include <algorithm>
#include <cassert>
#include <cmath>

#include "base/error.h"

namespace catpaq {
namespace {

uint64_t splitmix64(uint64_t& state) {
    uint64_t z = (state += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
}
double unit(uint64_t& state) { return double(splitmix64(state) >> 11) * 0x1p-53; }

}  // namespace

PointCloud sample_surface(const Mesh& mesh, size_t count, uint64_t seed, bool with_normals, bool with_colors) {
    const size_t triangles = mesh.triangle_count();
    std::vector<double> cumulative(triangles);
    double total = 0;
    for (size_t t = 0; t < triangles; ++t) {
        const Vec3d& a = mesh.positions[mesh.indices[3 * t]];
        const Vec3d& b = mesh.positions[mesh.indices[3 * t + 1]];
        const Vec3d& c = mesh.positions[mesh.indices[3 * t + 2]];
        double u[3], v[3];
        for (int k = 0; k < 3; ++k) u[k] = b[k] - a[k], v[k] = c[k] - a[k];
        double x = u[1] * v[2] - u[2] * v[1], y = u[2] * v[0] - u[0] * v[2], z = u[0] * v[1] - u[1] * v[0];
        total += 0.5 * std::sqrt(x * x + y * y + z * z);
        cumulative[t] = total;
    }
    if (!(total > 0)) fail("sample_surface: the mesh has no area");
    const bool normals = with_normals, colors = with_colors && mesh.has_colors();
    std::vector<Vec3f> face_normals;
    if (normals && !mesh.has_normals()) face_normals = compute_vertex_normals(mesh);
    const std::vector<Vec3f>& vertex_normals = mesh.has_normals() ? mesh.normals : face_normals;
    PointCloud cloud;
    cloud.positions.resize(count);
    if (normals) cloud.normals.resize(count);
    if (colors) cloud.colors.resize(count);
    uint64_t state = seed * 0x2545f4914f6cdd1dULL + 1;
    for (size_t i = 0; i < count; ++i) {
        double pick = unit(state) * total;
        size_t t = size_t(std::lower_bound(cumulative.begin(), cumulative.end(), pick) - cumulative.begin());
        t = std::min(t, triangles - 1);
        double r1 = unit(state), r2 = unit(state);
        if (r1 + r2 > 1) r1 = 1 - r1, r2 = 1 - r2;
        const double w[3] = {1 - r1 - r2, r1, r2};
        const uint32_t* corner = &mesh.indices[3 * t];
        for (int k = 0; k < 3; ++k)
            cloud.positions[i][k] = w[0] * mesh.positions[corner[0]][k] + w[1] * mesh.positions[corner[1]][k] +
                                    w[2] * mesh.positions[corner[2]][k];
        if (normals) {
            double n[3];
            for (int k = 0; k < 3; ++k)
                n[k] = w[0] * vertex_normals[corner[0]][k] + w[1] * vertex_normals[corner[1]][k] +
                       w[2] * vertex_normals[corner[2]][k];
            double length = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            for (int k = 0; k < 3; ++k) cloud.normals[i][k] = length > 0 ? float(n[k] / length) : (k == 2 ? 1.0f : 0.0f);
        }
        if (colors)
            for (int k = 0; k < 3; ++k)
                cloud.colors[i][k] = uint8_t(std::lround(w[0] * mesh.colors[corner[0]][k] + w[1] * mesh.colors[corner[1]][k] +
                                                         w[2] * mesh.colors[corner[2]][k]));
    }
    return cloud;
}

}  // namespace catpaq
