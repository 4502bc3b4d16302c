// Domain point -> surface point (aqp/surface_map.h).
#include "aqp/surface_map.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>

namespace catpaq::aqp {
namespace {

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
    // Every surface triangle's image lands in the buckets of every base triangle it overlaps, in
    // that triangle's chart (develop_image).
    struct Landing {
        uint32_t base;
        Image image;
    };
    tbb::enumerable_thread_specific<std::vector<Landing>> local_landings;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, surface.triangle_count(), 4096), [&](const tbb::blocked_range<size_t>& r) {
        std::vector<Landing>& landings = local_landings.local();
        for (size_t f = r.begin(); f != r.end(); ++f)
            develop_image(param, &surface.indices[3 * f], [&](uint32_t base, const Vec2 image[3]) {
                Landing landing{base, {}};
                landing.image.triangle = uint32_t(f);
                double x0 = INFINITY, y0 = INFINITY, x1 = -INFINITY, y1 = -INFINITY;
                for (int k = 0; k < 3; ++k) {
                    landing.image.x[k][0] = image[k][0];
                    landing.image.x[k][1] = image[k][1];
                    x0 = std::min(x0, image[k][0]), x1 = std::max(x1, image[k][0]);
                    y0 = std::min(y0, image[k][1]), y1 = std::max(y1, image[k][1]);
                }
                landing.image.box[0] = float(std::nextafter(x0, -INFINITY));
                landing.image.box[1] = float(std::nextafter(y0, -INFINITY));
                landing.image.box[2] = float(std::nextafter(x1, INFINITY));
                landing.image.box[3] = float(std::nextafter(y1, INFINITY));
                landings.push_back(landing);
            });
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
