// Surface sampling and distance statistics for verify and the benchmarks (see catp/distance.h).
#include <algorithm>
#include <cmath>
#include <random>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "base/progress.h"

#include "catp/distance.h"

namespace catpaq {

std::vector<std::array<double, 3>> sample_surface(const std::vector<std::array<double, 3>>& p,
                                                  const std::vector<uint32_t>& idx, size_t count) {
    std::vector<std::array<double, 3>> out;
    std::mt19937_64 rng(7);
    // Vertices of non-degenerate triangles (isolated vertices and zero-area triangles are not
    // surface), then uniform samples on the triangles.
    size_t triangles = idx.size() / 3;
    std::vector<uint32_t> surface_vertices;
    for (size_t t = 0; t < triangles; ++t) {
        uint32_t a = idx[3 * t], b = idx[3 * t + 1], c = idx[3 * t + 2];
        if (a == b || b == c || a == c) continue;
        surface_vertices.insert(surface_vertices.end(), {a, b, c});
    }
    std::sort(surface_vertices.begin(), surface_vertices.end());
    surface_vertices.erase(std::unique(surface_vertices.begin(), surface_vertices.end()), surface_vertices.end());
    size_t stride = std::max<size_t>(1, surface_vertices.size() / std::max<size_t>(1, count / 2));
    for (size_t i = 0; i < surface_vertices.size(); i += stride) out.push_back(p[surface_vertices[i]]);
    if (triangles == 0) return out;
    // Area-weighted, so zero-area triangles (not surface) are never sampled.
    std::vector<double> cumulative(triangles);
    double total = 0;
    for (size_t t = 0; t < triangles; ++t) {
        const auto &p0 = p[idx[3 * t]], &p1 = p[idx[3 * t + 1]], &p2 = p[idx[3 * t + 2]];
        double u[3], v[3];
        for (int i = 0; i < 3; ++i) {
            u[i] = p1[i] - p0[i];
            v[i] = p2[i] - p0[i];
        }
        double cx = u[1] * v[2] - u[2] * v[1], cy = u[2] * v[0] - u[0] * v[2], cz = u[0] * v[1] - u[1] * v[0];
        total += std::sqrt(cx * cx + cy * cy + cz * cz);
        cumulative[t] = total;
    }
    if (!(total > 0)) return out;
    std::uniform_real_distribution<double> u(0, 1);
    while (out.size() < count) {
        size_t t = size_t(std::lower_bound(cumulative.begin(), cumulative.end(), u(rng) * total) - cumulative.begin());
        if (t >= triangles) t = triangles - 1;
        double a = u(rng), b = u(rng);
        if (a + b > 1) {
            a = 1 - a;
            b = 1 - b;
        }
        const auto &p0 = p[idx[3 * t]], &p1 = p[idx[3 * t + 1]], &p2 = p[idx[3 * t + 2]];
        out.push_back({p0[0] + a * (p1[0] - p0[0]) + b * (p2[0] - p0[0]), p0[1] + a * (p1[1] - p0[1]) + b * (p2[1] - p0[1]),
                       p0[2] + a * (p1[2] - p0[2]) + b * (p2[2] - p0[2])});
    }
    return out;
}

DistanceStats measure_distances(const SurfaceDistance& to, const std::vector<std::array<double, 3>>& points,
                                Progress* progress) {
    std::vector<double> d(points.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, points.size(), 256), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i != r.end(); ++i) d[i] = to.distance(points[i]);
        if (progress) progress->add(r.size());
    });
    double mx = 0, sum = 0;
    for (double v : d) {
        mx = std::max(mx, v);
        sum += v * v;
    }
    return DistanceStats{mx, points.empty() ? 0 : std::sqrt(sum / double(points.size()))};
}


}  // namespace catpaq
