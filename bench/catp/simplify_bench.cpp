// simplify_bench: catp's simplify_mesh against meshoptimizer's meshopt_simplify (the Debian 0.18
// build, with meshopt_SimplifyLockBorder) on the same scan-like surfaces in the same run.
//
// Surfaces: a closed scan-like blob (mesh/generators.h make_scan_like, or a noisy cube sphere of
// our own when the mesh module is absent) cut open by removing a cap, so it has one border ring;
// the ring's vertices are locked for simplify_mesh and form the topological border that
// meshopt's LockBorder keeps. Both simplify to 50% of the triangles. Times are the best of 5
// (after one warm-up call), by wall clock and by thread CPU time; throughput is input triangles
// per second, single-threaded.
//
// Quality (up to 20k triangles, brute force): the distance from every input vertex to the output
// surface, max and mean, in units of the mean input edge length. The errors each simplifier
// reports are printed too, but they measure different things (ours: sqrt of the area-normalized
// quadric cost; meshopt 0.18: its own normalized metric scaled back to object units).
//
// Usage: simplify_bench [triangles ...]   (default 5000 20000 200000 1000000)
#include <meshoptimizer.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <vector>

#include "catp/simplify.h"
#ifdef CATPAQ_HAVE_MESH_GENERATORS
#include "mesh/generators.h"
#endif

namespace {

using V3 = std::array<double, 3>;

struct Surface {
    std::vector<V3> positions;
    std::vector<uint32_t> indices;
};

V3 sub(const V3& a, const V3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
double dot(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

#ifndef CATPAQ_HAVE_MESH_GENERATORS
// A cube sphere with n x n quads per face, radius displaced by smooth waves plus hashed jitter.
Surface noisy_sphere(size_t target_triangles) {
    const int n = std::max(2, int(std::lround(std::sqrt(double(target_triangles) / 12.0))));
    Surface s;
    // Vertex ids by lattice point on the cube surface, through a dense table.
    std::vector<uint32_t> id(size_t(n + 1) * (n + 1) * (n + 1), UINT32_MAX);
    auto at = [&](int i, int j, int k) {
        uint32_t& v = id[(size_t(i) * (n + 1) + j) * (n + 1) + k];
        if (v == UINT32_MAX) {
            v = uint32_t(s.positions.size());
            double p[3] = {2.0 * i / n - 1, 2.0 * j / n - 1, 2.0 * k / n - 1};
            const double len = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
            uint64_t h = uint64_t(v) * 0x9E3779B97F4A7C15ull;
            h ^= h >> 31;
            h *= 0xBF58476D1CE4E5B9ull;
            h ^= h >> 29;
            const double jitter = (double(h >> 11) / double(1ull << 53) - 0.5) * 0.6 / n;
            double r = 1 + 0.05 * std::sin(7 * p[0] / len) * std::cos(5 * p[1] / len) +
                       0.02 * std::sin(23 * p[2] / len + 3 * p[0] / len) + jitter;
            s.positions.push_back({p[0] / len * r, p[1] / len * r, p[2] / len * r});
        }
        return v;
    };
    for (int axis = 0; axis < 3; ++axis)
        for (int side = 0; side < 2; ++side)
            for (int a = 0; a < n; ++a)
                for (int b = 0; b < n; ++b) {
                    uint32_t q[4];
                    const int da[4] = {0, 1, 1, 0}, db[4] = {0, 0, 1, 1};
                    for (int c = 0; c < 4; ++c) {
                        int g[3];
                        g[axis] = side * n;
                        g[(axis + 1) % 3] = a + da[c];
                        g[(axis + 2) % 3] = b + db[c];
                        q[c] = at(g[0], g[1], g[2]);
                    }
                    if (side == 1) {
                        s.indices.insert(s.indices.end(), {q[0], q[1], q[2], q[0], q[2], q[3]});
                    } else {
                        s.indices.insert(s.indices.end(), {q[0], q[2], q[1], q[0], q[3], q[2]});
                    }
                }
    return s;
}
#endif

Surface closed_surface(size_t triangles) {
#ifdef CATPAQ_HAVE_MESH_GENERATORS
    catpaq::Mesh m = catpaq::make_scan_like(triangles, 7);
    Surface s;
    s.positions.resize(m.positions.size());
    for (size_t i = 0; i < m.positions.size(); ++i)
        s.positions[i] = {m.positions[i][0], m.positions[i][1], m.positions[i][2]};
    s.indices = std::move(m.indices);
    return s;
#else
    return noisy_sphere(triangles);
#endif
}

// Cuts the closed surface open: drops the triangles whose centroid is in the top 8% of its
// height, so the rest has one border ring. Returns the vertices on that ring.
std::vector<uint8_t> cut_open(Surface& s) {
    double lo = 1e300, hi = -1e300;
    for (const V3& p : s.positions) {
        lo = std::min(lo, p[1]);
        hi = std::max(hi, p[1]);
    }
    const double cut = hi - 0.08 * (hi - lo);
    std::vector<uint32_t> kept;
    for (size_t t = 0; t < s.indices.size(); t += 3) {
        double y = 0;
        for (int j = 0; j < 3; ++j) y += s.positions[s.indices[t + j]][1];
        if (y / 3 <= cut) kept.insert(kept.end(), s.indices.begin() + long(t), s.indices.begin() + long(t) + 3);
    }
    s.indices = std::move(kept);
    // Border edges: directed edges without a twin.
    std::vector<uint64_t> edges;
    for (size_t t = 0; t < s.indices.size(); t += 3)
        for (int j = 0; j < 3; ++j) edges.push_back(uint64_t(s.indices[t + j]) << 32 | s.indices[t + (j + 1) % 3]);
    std::sort(edges.begin(), edges.end());
    std::vector<uint8_t> locked(s.positions.size(), 0);
    for (uint64_t e : edges) {
        const uint64_t twin = (e << 32) | (e >> 32);
        if (!std::binary_search(edges.begin(), edges.end(), twin)) locked[e >> 32] = locked[uint32_t(e)] = 1;
    }
    return locked;
}

double point_triangle_distance2(const V3& p, const V3& a, const V3& b, const V3& c) {
    // Closest point on a triangle (Ericson, Real-Time Collision Detection 5.1.5).
    const V3 ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
    const double d1 = dot(ab, ap), d2 = dot(ac, ap);
    auto dist2 = [&](const V3& q) { const V3 d = sub(p, q); return dot(d, d); };
    if (d1 <= 0 && d2 <= 0) return dist2(a);
    const V3 bp = sub(p, b);
    const double d3 = dot(ab, bp), d4 = dot(ac, bp);
    if (d3 >= 0 && d4 <= d3) return dist2(b);
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) {
        const double v = d1 / (d1 - d3);
        return dist2({a[0] + v * ab[0], a[1] + v * ab[1], a[2] + v * ab[2]});
    }
    const V3 cp = sub(p, c);
    const double d5 = dot(ab, cp), d6 = dot(ac, cp);
    if (d6 >= 0 && d5 <= d6) return dist2(c);
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) {
        const double w = d2 / (d2 - d6);
        return dist2({a[0] + w * ac[0], a[1] + w * ac[1], a[2] + w * ac[2]});
    }
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
        const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return dist2({b[0] + w * (c[0] - b[0]), b[1] + w * (c[1] - b[1]), b[2] + w * (c[2] - b[2])});
    }
    const double denom = 1 / (va + vb + vc);
    const double v = vb * denom, w = vc * denom;
    return dist2({a[0] + ab[0] * v + ac[0] * w, a[1] + ab[1] * v + ac[1] * w, a[2] + ab[2] * v + ac[2] * w});
}

// Max and mean distance from the input's referenced vertices to the output surface.
void surface_distance(const Surface& s, const std::vector<uint32_t>& out, double& max_d, double& mean_d) {
    std::vector<uint8_t> used(s.positions.size(), 0);
    for (uint32_t v : s.indices) used[v] = 1;
    max_d = 0;
    double sum = 0;
    size_t count = 0;
    for (size_t v = 0; v < s.positions.size(); ++v) {
        if (!used[v]) continue;
        double best = 1e300;
        for (size_t t = 0; t < out.size(); t += 3)
            best = std::min(best, point_triangle_distance2(s.positions[v], s.positions[out[t]], s.positions[out[t + 1]],
                                                          s.positions[out[t + 2]]));
        const double d = std::sqrt(best);
        max_d = std::max(max_d, d);
        sum += d;
        ++count;
    }
    mean_d = count ? sum / double(count) : 0;
}

double mean_edge(const Surface& s) {
    double sum = 0;
    for (size_t t = 0; t < s.indices.size(); t += 3)
        for (int j = 0; j < 3; ++j) {
            const V3 d = sub(s.positions[s.indices[t + j]], s.positions[s.indices[t + (j + 1) % 3]]);
            sum += std::sqrt(dot(d, d));
        }
    return sum / double(s.indices.size());
}

// Best of `runs` by wall clock and, separately, by this thread's CPU time (user + system, so
// page faults count): on a machine shared with other work the CPU time is the steadier figure.
struct Timing {
    double wall = 1e300, cpu = 1e300;
};

double thread_cpu_seconds() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

template <class F>
Timing best_of(int runs, F&& f) {
    Timing best;
    f();  // warm-up: the allocator's pages and the caches, for both libraries alike
    for (int r = 0; r < runs; ++r) {
        const double c0 = thread_cpu_seconds();
        const auto t0 = std::chrono::steady_clock::now();
        f();
        const auto t1 = std::chrono::steady_clock::now();
        const double c1 = thread_cpu_seconds();
        best.wall = std::min(best.wall, std::chrono::duration<double>(t1 - t0).count());
        best.cpu = std::min(best.cpu, c1 - c0);
    }
    return best;
}

}  // namespace

int main(int argc, char** argv) {
    std::vector<size_t> sizes = {5000, 20000, 200000, 1000000};
    if (argc > 1) {
        sizes.clear();
        for (int i = 1; i < argc; ++i) sizes.push_back(size_t(std::strtoull(argv[i], nullptr, 10)));
    }
    std::printf("simplify_mesh (catp) vs meshopt_simplify 0.18 (LockBorder), to 50%% of the triangles, single thread,\n"
                "best of 5; throughput in million input triangles/s by wall clock and by thread CPU time\n\n");
    std::printf("%9s | %-25s | %-25s | %-11s | %-19s | %-19s\n", "", "catp Mt/s", "meshopt Mt/s", "catp/mopt",
                "reported error", "max dist in->out");
    std::printf("%9s | %8s %8s %7s | %8s %8s %7s | %5s %5s | %9s %9s | %9s %9s\n", "triangles", "wall", "cpu", "out",
                "wall", "cpu", "out", "wall", "cpu", "catp", "meshopt", "catp", "meshopt");
    bool all_fast = true;
    std::vector<double> means;
    for (size_t size : sizes) {
        Surface s = closed_surface(size);
        const std::vector<uint8_t> locked = cut_open(s);
        const size_t tris = s.indices.size() / 3;
        const size_t target = tris / 2;

        catpaq::SimplifySettings settings;
        settings.target_triangles = target;
        catpaq::SimplifyResult ours;
        const Timing t_ours = best_of(5, [&] {
            ours = catpaq::simplify_mesh(s.positions[0].data(), s.positions.size(), s.indices.data(), s.indices.size(),
                                         locked.data(), settings);
        });

        std::vector<float> fpos(s.positions.size() * 3);
        for (size_t i = 0; i < s.positions.size(); ++i)
            for (int k = 0; k < 3; ++k) fpos[i * 3 + k] = float(s.positions[i][k]);
        std::vector<uint32_t> mopt(s.indices.size());
        size_t mopt_count = 0;
        float mopt_rel_error = 0;
        const Timing t_mopt = best_of(5, [&] {
            mopt_count = meshopt_simplify(mopt.data(), s.indices.data(), s.indices.size(), fpos.data(),
                                          s.positions.size(), sizeof(float) * 3, target * 3, 1e30f,
                                          meshopt_SimplifyLockBorder, &mopt_rel_error);
        });
        mopt.resize(mopt_count);
        const double mopt_error =
            mopt_rel_error * meshopt_simplifyScale(fpos.data(), s.positions.size(), sizeof(float) * 3);

        const double edge = mean_edge(s);
        double our_max = NAN, our_mean = NAN, mopt_max = NAN, mopt_mean = NAN;
        if (tris <= 20000) {
            surface_distance(s, ours.indices, our_max, our_mean);
            surface_distance(s, mopt, mopt_max, mopt_mean);
            means.insert(means.end(), {double(tris), our_mean / edge, mopt_mean / edge});
        }
        const double t = double(tris) / 1e6;
        all_fast = all_fast && t / t_ours.cpu >= 2;
        std::printf("%9zu | %8.2f %8.2f %7zu | %8.2f %8.2f %7zu | %5.2f %5.2f | %9.4f %9.4f | %9.4f %9.4f\n", tris,
                    t / t_ours.wall, t / t_ours.cpu, ours.indices.size() / 3, t / t_mopt.wall, t / t_mopt.cpu,
                    mopt_count / 3, t_mopt.wall / t_ours.wall, t_mopt.cpu / t_ours.cpu, ours.error / edge,
                    mopt_error / edge, our_max / edge, mopt_max / edge);
    }
    std::printf("\nerrors and distances in mean input edge lengths; reported errors are each library's own metric;\n"
                "max dist = largest distance from an input vertex to the output surface (brute force, up to 20k\n"
                "triangles)\n");
    for (size_t i = 0; i < means.size(); i += 3)
        std::printf("mean distance input vertex -> output surface at %.0f triangles: catp %.4f, meshopt %.4f\n",
                    means[i], means[i + 1], means[i + 2]);
    std::printf("catp >= 2M input triangles/s (thread CPU time) on every size: %s\n", all_fast ? "yes" : "NO");
    return 0;
}
