// Node error bounds (patch_errors.h).
#include "patch_errors.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>

#include "base/progress.h"

namespace catpaq::aqp {
namespace {

constexpr double kThird = 1.0 / 3.0;

double distance(const Vec3d& a, const Vec3d& b) {
    return std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
}

Vec3d lerp(const Vec3d& a, const Vec3d& b, double t) {
    return {a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2])};
}

// The affine map from a patch's (u, v) to lattice coordinates of one of its base triangles'
// charts: x = o + u du + v dv (aqp/quad_layout.h: the T1 half is c1 + u (a - c1) + v (b - c1),
// the T2 half (u + v - 1) c2 + (1 - v) a + (1 - u) b; each holds over the whole rhombus).
struct PatchFrame {
    uint32_t chart = kNone;
    double o[2], du[2], dv[2];

    void to_uv(const Vec2& x, double& u, double& v) const {
        const double det = du[0] * dv[1] - du[1] * dv[0];
        const double px = x[0] - o[0], py = x[1] - o[1];
        u = (px * dv[1] - py * dv[0]) / det;
        v = (du[0] * py - du[1] * px) / det;
    }
};

PatchFrame patch_frame(const QuadPatch& q, int half) {
    static const double kCorner[3][2] = {{0, 0}, {1, 0}, {0, 1}};
    PatchFrame f;
    f.chart = q.triangle[half];
    if (half == 0) {
        const double* a = kCorner[q.edge[0]];
        const double* b = kCorner[(q.edge[0] + 1) % 3];
        for (int i = 0; i < 2; ++i) f.o[i] = kThird, f.du[i] = a[i] - kThird, f.dv[i] = b[i] - kThird;
    } else {
        const double* a = kCorner[(q.edge[1] + 1) % 3];
        const double* b = kCorner[q.edge[1]];
        for (int i = 0; i < 2; ++i) f.o[i] = a[i] + b[i] - kThird, f.du[i] = kThird - b[i], f.dv[i] = kThird - a[i];
    }
    return f;
}

// The level's surface at (u, v): grid cells split along their (i,j)-(i+1,j+1) diagonal.
Vec3d level_surface(const std::vector<Vec3d>& grid, int size, double u, double v) {
    const int cells = size - 1;
    const int ci = std::clamp(int(u * cells), 0, cells - 1), cj = std::clamp(int(v * cells), 0, cells - 1);
    const double fu = u * cells - ci, fv = v * cells - cj;
    const Vec3d& p00 = grid[size_t(cj) * size + ci];
    const Vec3d& p10 = grid[size_t(cj) * size + ci + 1];
    const Vec3d& p01 = grid[size_t(cj + 1) * size + ci];
    const Vec3d& p11 = grid[size_t(cj + 1) * size + ci + 1];
    Vec3d out;
    for (int a = 0; a < 3; ++a)
        out[a] = fu >= fv ? p00[a] + fu * (p10[a] - p00[a]) + fv * (p11[a] - p10[a])
                          : p00[a] + fv * (p01[a] - p00[a]) + fu * (p11[a] - p01[a]);
    return out;
}

// A point of the input surface at (u, v) of a patch.
struct PatchPoint {
    double u, v;
    Vec3d position;
};

// The part of an input edge inside an affine patch: (u, v) and input positions at both ends.
struct Segment {
    double u0, v0, u1, v1;
    Vec3d p0, p1;
};

// Clips the segment from (u0, v0) (t = 0) to (u1, v1) (t = 1) to the unit square (Liang-Barsky).
bool clip_to_square(double u0, double v0, double u1, double v1, double& t0, double& t1) {
    t0 = 0, t1 = 1;
    const double p[4] = {-(u1 - u0), u1 - u0, -(v1 - v0), v1 - v0};
    const double q[4] = {u0, 1 - u0, v0, 1 - v0};
    for (int i = 0; i < 4; ++i) {
        if (p[i] == 0) {
            if (q[i] < 0) return false;
            continue;
        }
        const double r = q[i] / p[i];
        if (p[i] < 0) t0 = std::max(t0, r);
        else t1 = std::min(t1, r);
    }
    return t0 <= t1;
}

// Parameters where the segment crosses the lines u = i/n, v = j/n and u - v = m/n.
void grid_crossings(const Segment& s, int n, std::vector<double>& ts) {
    ts.clear();
    auto family = [&](double a0, double a1) {
        if (a0 == a1) return;
        const double lo = std::min(a0, a1) * n, hi = std::max(a0, a1) * n;
        for (double line = std::ceil(lo); line <= hi; line += 1) ts.push_back((line / n - a0) / (a1 - a0));
    };
    family(s.u0, s.u1);
    family(s.v0, s.v1);
    family(s.u0 - s.v0, s.u1 - s.v1);
}

struct PatchInput {
    std::vector<PatchPoint> points;   // input vertices, and samples of edges in border patches
    std::vector<Segment> segments;    // clipped input edges in affine patches
};

// The third of base triangle t that edge k's patch covers, in t's chart: (barycentre, corner k,
// corner k+1).
void third_of(int k, Vec2 out[3]) {
    static const Vec2 kCorner[3] = {{0, 0}, {1, 0}, {0, 1}};
    out[0] = {kThird, kThird};
    out[1] = kCorner[k];
    out[2] = kCorner[(k + 1) % 3];
}

// The edges of a surface triangle's image (in the chart of base triangle `half` of patch p) inside
// the patch: clipped segments in an affine patch, samples every quarter of a finest cell in a
// border patch.
void add_image_edges(const Mesh& surface, const QuadLayout& layout, uint32_t p, int half, const SurfaceMap::Image& im,
                     int n, PatchInput& in) {
    const QuadPatch& q = layout.patches()[p];
    const PatchFrame f = patch_frame(q, half);
    const uint32_t* tri = &surface.indices[3 * im.triangle];
    for (int e = 0; e < 3; ++e) {
        const Vec2 xa{im.x[e][0], im.x[e][1]}, xb{im.x[(e + 1) % 3][0], im.x[(e + 1) % 3][1]};
        const Vec3d& pa = surface.positions[tri[e]];
        const Vec3d& pb = surface.positions[tri[(e + 1) % 3]];
        if (!q.border()) {
            Segment s;
            f.to_uv(xa, s.u0, s.v0);
            f.to_uv(xb, s.u1, s.v1);
            double t0, t1;
            if (!clip_to_square(s.u0, s.v0, s.u1, s.v1, t0, t1)) continue;
            const Segment whole = s;
            s.u0 = whole.u0 + t0 * (whole.u1 - whole.u0), s.v0 = whole.v0 + t0 * (whole.v1 - whole.v0);
            s.u1 = whole.u0 + t1 * (whole.u1 - whole.u0), s.v1 = whole.v0 + t1 * (whole.v1 - whole.v0);
            s.p0 = lerp(pa, pb, t0);
            s.p1 = lerp(pa, pb, t1);
            in.segments.push_back(s);
            continue;
        }
        const double length = std::hypot(xb[0] - xa[0], xb[1] - xa[1]);
        const int steps = std::clamp(int(std::ceil(length * 3 * n * 4)), 1, 1 << 16);
        for (int i = 0; i <= steps; ++i) {
            const double t = double(i) / steps;
            const double x = xa[0] + t * (xb[0] - xa[0]), y = xa[1] + t * (xb[1] - xa[1]);
            if (x < 0 || y < 0 || x + y > 1) continue;
            DomainPoint d;
            d.triangle = f.chart;
            d.bary = {1 - x - y, x, y};
            uint32_t at;
            double u, v;
            layout.locate(d, at, u, v);
            if (at == p) in.points.push_back({u, v, lerp(pa, pb, t)});
        }
    }
}

}  // namespace

std::vector<std::vector<double>> measure_patch_errors(const Mesh& surface, const Parameterization& param,
                                                      const QuadLayout& layout, const SurfaceMap& map,
                                                      const SampleNumbering& numbering,
                                                      const std::vector<Vec3d>& exact,
                                                      const std::function<Vec3d(uint32_t)>& decoded, Progress* progress) {
    const int k = numbering.level(), n = numbering.size() - 1;
    const size_t patches = layout.patch_count();
    // Which patch every input vertex lies in, then each patch's vertices and incident edges.
    std::vector<uint32_t> vertex_patch(surface.vertex_count());
    std::vector<std::array<double, 2>> vertex_uv(surface.vertex_count());
    tbb::parallel_for(size_t(0), surface.vertex_count(), [&](size_t v) {
        layout.locate(param.points[v], vertex_patch[v], vertex_uv[v][0], vertex_uv[v][1]);
    });
    std::vector<std::vector<uint32_t>> vertices(patches);
    for (uint32_t v = 0; v < surface.vertex_count(); ++v) vertices[vertex_patch[v]].push_back(v);

    std::vector<std::vector<double>> error(patches, std::vector<double>(size_t(k) + 1, 0.0));
    tbb::parallel_for(size_t(0), patches, [&](size_t p) {
        PatchInput in;
        for (uint32_t v : vertices[p]) in.points.push_back({vertex_uv[v][0], vertex_uv[v][1], surface.positions[v]});
        // Every surface triangle whose image overlaps the patch contributes its edges.
        const QuadPatch& q = layout.patches()[p];
        for (int half = 0; half < (q.border() ? 1 : 2); ++half) {
            Vec2 third[3];
            third_of(q.edge[half], third);
            for (const SurfaceMap::Image& im : map.images(q.triangle[half])) {
                Vec2 image[3] = {{im.x[0][0], im.x[0][1]}, {im.x[1][0], im.x[1][1]}, {im.x[2][0], im.x[2][1]}};
                if (triangles_overlap(image, third)) add_image_edges(surface, layout, uint32_t(p), half, im, n, in);
            }
        }
        std::vector<Vec3d> grid;
        std::vector<double> ts;
        for (int l = k; l >= 0; --l) {
            const int size = (1 << l) + 1, stride = 1 << (k - l);
            grid.resize(size_t(size) * size);
            for (int j = 0; j < size; ++j)
                for (int i = 0; i < size; ++i) grid[size_t(j) * size + i] = decoded(numbering.id(uint32_t(p), i * stride, j * stride));
            double e = 0;
            auto at = [&](double u, double v, const Vec3d& x) { e = std::max(e, distance(level_surface(grid, size, u, v), x)); };
            for (const PatchPoint& x : in.points) at(x.u, x.v, x.position);
            for (const Segment& s : in.segments) {
                at(s.u0, s.v0, s.p0);
                at(s.u1, s.v1, s.p1);
                grid_crossings(s, size - 1, ts);
                for (double t : ts) at(s.u0 + t * (s.u1 - s.u0), s.v0 + t * (s.v1 - s.v0), lerp(s.p0, s.p1, t));
            }
            for (int j = 0; j <= n; ++j)
                for (int i = 0; i <= n; ++i) at(double(i) / n, double(j) / n, exact[numbering.id(uint32_t(p), i, j)]);
            error[p][l] = l == k ? e : std::max(e, error[p][l + 1]);
        }
        if (progress) progress->add(1);
    });
    return error;
}

}  // namespace catpaq::aqp
