#include "mesh/mesh.h"

#include <algorithm>
#include <cmath>

#include "base/error.h"

namespace catpaq {

double Bounds::diagonal() const {
    if (empty()) return 0.0;
    double sum = 0.0;
    for (int i = 0; i < 3; ++i) {
        double extent = max[i] - min[i];
        sum += extent * extent;
    }
    return std::sqrt(sum);
}

Bounds Mesh::bounds() const {
    Bounds bounds;
    for (const Vec3d& p : positions) bounds.add(p);
    return bounds;
}

void validate_mesh(const Mesh& mesh, const std::string& what) {
    const char* name = what.c_str();
    size_t n = mesh.positions.size();
    for (size_t v = 0; v < n; ++v) {
        const Vec3d& p = mesh.positions[v];
        if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
            fail("'%s': vertex %zu has a non-finite coordinate (%g, %g, %g)", name, v, p[0], p[1], p[2]);
    }
    if (!mesh.normals.empty() && mesh.normals.size() != n)
        fail("'%s': %zu normals for %zu vertices", name, mesh.normals.size(), n);
    if (!mesh.colors.empty() && mesh.colors.size() != n)
        fail("'%s': %zu colours for %zu vertices", name, mesh.colors.size(), n);
    for (size_t v = 0; v < mesh.normals.size(); ++v) {
        const Vec3f& q = mesh.normals[v];
        if (!std::isfinite(q[0]) || !std::isfinite(q[1]) || !std::isfinite(q[2]))
            fail("'%s': vertex %zu has a non-finite normal", name, v);
    }
    if (mesh.indices.size() % 3 != 0)
        fail("'%s': %zu triangle indices is not a multiple of 3", name, mesh.indices.size());
    for (size_t i = 0; i < mesh.indices.size(); ++i) {
        if (mesh.indices[i] >= n)
            fail("'%s': triangle %zu uses vertex index %u, out of range (%zu vertices)", name, i / 3,
                 mesh.indices[i], n);
    }
}

std::vector<Vec3f> compute_vertex_normals(const Mesh& mesh) {
    // Accumulate in double: a vertex shared by thousands of tiny triangles (a fan in a scan)
    // would otherwise lose the small contributions.
    std::vector<Vec3d> sum(mesh.positions.size(), Vec3d{0, 0, 0});
    for (size_t t = 0; t + 2 < mesh.indices.size(); t += 3) {
        uint32_t ia = mesh.indices[t], ib = mesh.indices[t + 1], ic = mesh.indices[t + 2];
        const Vec3d& a = mesh.positions[ia];
        const Vec3d& b = mesh.positions[ib];
        const Vec3d& c = mesh.positions[ic];
        double ux = b[0] - a[0], uy = b[1] - a[1], uz = b[2] - a[2];
        double vx = c[0] - a[0], vy = c[1] - a[1], vz = c[2] - a[2];
        // The unnormalised cross product has length 2*area: that is the area weighting.
        Vec3d n{uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx};
        for (uint32_t v : {ia, ib, ic})
            for (int k = 0; k < 3; ++k) sum[v][k] += n[k];
    }
    std::vector<Vec3f> normals(sum.size());
    for (size_t v = 0; v < sum.size(); ++v) {
        const Vec3d& s = sum[v];
        double length = std::sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
        if (length > 0 && std::isfinite(length))
            normals[v] = {float(s[0] / length), float(s[1] / length), float(s[2] / length)};
        else
            normals[v] = {0.0f, 0.0f, 1.0f};
    }
    return normals;
}

EdgeCounts count_edges(const std::vector<uint32_t>& indices) {
    // Sort directed edges (from << 32 | to); the use count of an undirected edge is the size of
    // its run plus the size of the reversed run. Sorting 8-byte keys keeps memory at 24 bytes per
    // triangle, which matters for the 20M-triangle generator tests.
    std::vector<uint64_t> directed;
    directed.reserve(indices.size());
    for (size_t t = 0; t + 2 < indices.size(); t += 3) {
        for (int k = 0; k < 3; ++k) {
            uint32_t from = indices[t + k], to = indices[t + (k + 1) % 3];
            if (from != to) directed.push_back(uint64_t(from) << 32 | to);
        }
    }
    std::sort(directed.begin(), directed.end());

    EdgeCounts counts;
    for (size_t i = 0; i < directed.size();) {
        size_t j = i;
        while (j < directed.size() && directed[j] == directed[i]) ++j;
        uint64_t key = directed[i];
        uint32_t from = uint32_t(key >> 32), to = uint32_t(key);
        uint64_t reversed = uint64_t(to) << 32 | from;
        auto range = std::equal_range(directed.begin(), directed.end(), reversed);
        size_t forward_uses = j - i, backward_uses = size_t(range.second - range.first);
        // Visit each undirected edge once: from its smaller-first direction when that exists.
        if (from < to || backward_uses == 0) {
            size_t uses = forward_uses + backward_uses;
            ++counts.edges;
            if (uses == 1) ++counts.border;
            else if (uses == 2) ++counts.manifold;
            else ++counts.nonmanifold;
            if (uses == 2 && (forward_uses == 2 || backward_uses == 2)) ++counts.misoriented;
        }
        i = j;
    }
    return counts;
}

size_t count_border_edges(const std::vector<uint32_t>& indices) { return count_edges(indices).border; }

}  // namespace catpaq
