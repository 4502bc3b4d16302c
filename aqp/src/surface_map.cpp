// Domain point -> surface point (aqp/surface_map.h).
#include "aqp/surface_map.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>

namespace catpaq::aqp {
namespace {

// Whether the 2D triangles a and b (counter-clockwise) overlap with area: no edge line of either
// has the whole other triangle outside it or on it (separating axis theorem; the two triangles'
// edges are the only candidate separating lines, in any affine frame). Triangles that only touch
// at a point or along an edge do not count: an image with a corner at a base vertex touches
// every triangle around it, and developed around the cone the far ones would be wrong copies.
bool triangles_overlap(const double a[3][2], const double b[3][2], double eps) {
    auto separated = [&](const double p[3][2], const double q[3][2]) {
        for (int i = 0; i < 3; ++i) {
            const double* s = p[i];
            const double* e = p[(i + 1) % 3];
            const double ex = e[0] - s[0], ey = e[1] - s[1];
            bool all_outside = true;
            for (int j = 0; j < 3 && all_outside; ++j)
                all_outside = ex * (q[j][1] - s[1]) - ey * (q[j][0] - s[0]) <= eps;
            if (all_outside) return true;
        }
        return false;
    };
    return !separated(a, b) && !separated(b, a);
}

// Lattice coordinates of point y (chart A) in the chart of a triangle whose corners in chart A
// are c: y = c0 + l1 (c1 - c0) + l2 (c2 - c0).
std::array<double, 2> to_chart(const std::array<Lattice2, 3>& c, const double y[2]) {
    const double ax = c[1][0] - c[0][0], ay = c[1][1] - c[0][1], bx = c[2][0] - c[0][0], by = c[2][1] - c[0][1];
    const double det = ax * by - ay * bx;  // +-1: lattice triangles of the unit's area
    const double qx = y[0] - c[0][0], qy = y[1] - c[0][1];
    return {(qx * by - qy * bx) / det, (ax * qy - ay * qx) / det};
}

// Barycentric coordinates of (px, py) in the 2D triangle x.
std::array<double, 3> bary2(const double x[3][2], double px, double py) {
    const double ax = x[1][0] - x[0][0], ay = x[1][1] - x[0][1], bx = x[2][0] - x[0][0], by = x[2][1] - x[0][1];
    const double det = ax * by - ay * bx;
    if (!(det != 0)) return {-INFINITY, -INFINITY, -INFINITY};
    const double qx = px - x[0][0], qy = py - x[0][1];
    const double l1 = (qx * by - qy * bx) / det, l2 = (ax * qy - ay * qx) / det;
    return {1 - l1 - l2, l1, l2};
}

}  // namespace

SurfaceMap::SurfaceMap(const Mesh& surface, const Parameterization& param) : surface_(surface), param_(param) {
    const size_t nbt = param.domain.triangle_count();
    buckets_.resize(nbt);
    // Every surface triangle's image, developed from its own chart across the base edges it
    // overlaps (breadth first, each base triangle once), lands in the buckets of every base
    // triangle it touches, in that triangle's chart.
    struct Landing {
        uint32_t base;
        Image image;
    };
    tbb::enumerable_thread_specific<std::vector<Landing>> local_landings;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, surface.triangle_count(), 4096), [&](const tbb::blocked_range<size_t>& r) {
        std::vector<Landing>& landings = local_landings.local();
        std::vector<std::pair<uint32_t, std::array<Lattice2, 3>>> queue;
        for (size_t f = r.begin(); f != r.end(); ++f) {
            Vec2 x[3];
            uint32_t chart;
            if (!triangle_image(param, &surface.indices[3 * f], x, &chart)) continue;
            double image[3][2] = {{x[0][0], x[0][1]}, {x[1][0], x[1][1]}, {x[2][0], x[2][1]}};
            const double area = (x[1][0] - x[0][0]) * (x[2][1] - x[0][1]) - (x[1][1] - x[0][1]) * (x[2][0] - x[0][0]);
            if (area < 0) std::swap(image[1], image[2]);  // (a valid map has none)
            queue.assign(1, {chart, {Lattice2{0, 0}, Lattice2{1, 0}, Lattice2{0, 1}}});
            for (size_t q = 0; q < queue.size() && q < 32; ++q) {
                const auto [base, corners] = queue[q];
                double cell[3][2];
                for (int k = 0; k < 3; ++k) cell[k][0] = corners[k][0], cell[k][1] = corners[k][1];
                if (!triangles_overlap(image, cell, 1e-13)) continue;
                Landing landing{base, {}};
                landing.image.triangle = uint32_t(f);
                double x0 = INFINITY, y0 = INFINITY, x1 = -INFINITY, y1 = -INFINITY;
                for (int k = 0; k < 3; ++k) {
                    std::array<double, 2> l = to_chart(corners, &x[k][0]);
                    landing.image.x[k][0] = l[0];
                    landing.image.x[k][1] = l[1];
                    x0 = std::min(x0, l[0]), x1 = std::max(x1, l[0]);
                    y0 = std::min(y0, l[1]), y1 = std::max(y1, l[1]);
                }
                landing.image.box[0] = float(std::nextafter(x0, -INFINITY));
                landing.image.box[1] = float(std::nextafter(y0, -INFINITY));
                landing.image.box[2] = float(std::nextafter(x1, INFINITY));
                landing.image.box[3] = float(std::nextafter(y1, INFINITY));
                landings.push_back(landing);
                for (uint32_t k = 0; k < 3; ++k) {
                    uint32_t next = base;
                    std::array<Lattice2, 3> c = corners;
                    if (!param.domain.across(next, k, c)) continue;
                    bool seen = false;
                    for (const auto& v : queue) seen |= v.first == next;
                    if (!seen) queue.push_back({next, c});
                }
            }
        }
    });
    std::vector<size_t> count(nbt, 0);
    for (auto& local : local_landings)
        for (const Landing& l : local) ++count[l.base];
    for (size_t b = 0; b < nbt; ++b) buckets_[b].images.reserve(count[b]);
    for (auto& local : local_landings) {
        for (const Landing& l : local) buckets_[l.base].images.push_back(l.image);
        std::vector<Landing>().swap(local);
    }

    tbb::parallel_for(size_t(0), nbt, [&](size_t b) {
        Buckets& bk = buckets_[b];
        bk.size = std::clamp(int(std::ceil(std::sqrt(double(bk.images.size()) / 2))), 1, 512);
        const int g = bk.size;
        auto cell_range = [&](const Image& im, int& cx0, int& cy0, int& cx1, int& cy1) {
            cx0 = std::clamp(int(std::floor(im.box[0] * g)) - 1, 0, g - 1);
            cy0 = std::clamp(int(std::floor(im.box[1] * g)) - 1, 0, g - 1);
            cx1 = std::clamp(int(std::floor(im.box[2] * g)) + 1, 0, g - 1);
            cy1 = std::clamp(int(std::floor(im.box[3] * g)) + 1, 0, g - 1);
        };
        std::vector<uint32_t> count(size_t(g) * g + 1, 0);
        for (const Image& im : bk.images) {
            int cx0, cy0, cx1, cy1;
            cell_range(im, cx0, cy0, cx1, cy1);
            for (int y = cy0; y <= cy1; ++y)
                for (int x = cx0; x <= cx1; ++x) ++count[size_t(y) * g + x + 1];
        }
        for (size_t c = 1; c < count.size(); ++c) count[c] += count[c - 1];
        bk.start = count;
        bk.items.resize(count.back());
        for (uint32_t i = 0; i < bk.images.size(); ++i) {
            int cx0, cy0, cx1, cy1;
            cell_range(bk.images[i], cx0, cy0, cx1, cy1);
            for (int y = cy0; y <= cy1; ++y)
                for (int x = cx0; x <= cx1; ++x) bk.items[count[size_t(y) * g + x]++] = i;
        }
    });
}

SurfacePoint SurfaceMap::locate(const DomainPoint& p) const {
    const Buckets& bk = buckets_[p.triangle];
    const double px = p.bary[1], py = p.bary[2];
    const int g = bk.size;
    const int cx = std::clamp(int(px * g), 0, g - 1), cy = std::clamp(int(py * g), 0, g - 1);
    SurfacePoint best;
    double best_inside = -INFINITY;
    auto test = [&](const Image& im) {
        std::array<double, 3> b = bary2(im.x, px, py);
        double inside = std::min({b[0], b[1], b[2]});
        if (inside > best_inside) {
            best_inside = inside;
            best.triangle = im.triangle;
            best.bary = b;
        }
    };
    for (uint32_t i = bk.start[size_t(cy) * g + cx]; i < bk.start[size_t(cy) * g + cx + 1]; ++i) test(bk.images[bk.items[i]]);
    if (best_inside < -1e-12)
        for (const Image& im : bk.images) test(im);  // rare: rounding on an edge between images
    if (best_inside == -INFINITY) {
        misses_.fetch_add(1);
        // No image at all: the surface vertex nearest in the chart (cannot happen for a valid map).
        best.triangle = bk.images.empty() ? 0 : bk.images[0].triangle;
        best.bary = {1, 0, 0};
        return best;
    }
    if (best_inside < -1e-9) misses_.fetch_add(1);
    double sum = 0;
    for (double& b : best.bary) sum += (b = std::max(b, 0.0));
    for (double& b : best.bary) b /= sum;
    return best;
}

SurfaceSample SurfaceMap::interpolate(const SurfacePoint& s) const {
    SurfaceSample out;
    const uint32_t* tri = &surface_.indices[3 * s.triangle];
    double n[3] = {0, 0, 0}, c[3] = {0, 0, 0};
    out.position = {0, 0, 0};
    for (int k = 0; k < 3; ++k) {
        const double w = s.bary[k];
        for (int i = 0; i < 3; ++i) {
            out.position[i] += w * surface_.positions[tri[k]][i];
            n[i] += w * surface_.normals[tri[k]][i];
            if (surface_.has_colors()) c[i] += w * surface_.colors[tri[k]][i];
        }
    }
    const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (len > 0) out.normal = {float(n[0] / len), float(n[1] / len), float(n[2] / len)};
    for (int i = 0; i < 3; ++i) out.color[i] = uint8_t(std::clamp(std::lround(c[i]), 0l, 255l));
    return out;
}

SurfaceSample SurfaceMap::sample(const DomainPoint& x) const { return interpolate(locate(x)); }

}  // namespace catpaq::aqp
