// Procedural meshes. Determinism rules (see generators.h): splitmix64 for randomness, the
// polynomial sincos_turns below for angles, and only correctly rounded operations for positions.
#include "mesh/generators.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <thread>
#include <utility>

#include "readers.h"  // reserve_huge

namespace catpaq {
namespace {

// ---------------------------------------------------------------------------------------------
// Randomness and smooth noise

uint64_t mix64(uint64_t z) {  // the splitmix64 finaliser
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

struct SplitMix64 {
    uint64_t state;
    uint64_t next() { return mix64(state += 0x9e3779b97f4a7c15ull); }
    uint64_t below(uint64_t n) { return next() % n; }  // the tiny modulo bias is irrelevant here
};

// Pseudo-random values in [-1, 1] at integer lattice points: one finaliser over a linear mix of
// the coordinates, so the 8 corners of a cell differ from the first only by added constants.
constexpr uint64_t kLatticeX = 0x9e3779b97f4a7c15ull, kLatticeY = 0xc2b2ae3d27d4eb4full,
                   kLatticeZ = 0x165667b19e3779f9ull;

double lattice_value(uint64_t key) { return double(mix64(key) >> 11) * 0x1.0p-52 - 1.0; }

double fade(double t) { return t * t * t * (t * (t * 6.0 - 15.0) + 10.0); }  // C2 smoothstep

// Trilinear interpolation of lattice values with a C2 fade: smooth, in [-1, 1].
double value_noise(double x, double y, double z, uint64_t seed) {
    double fx = std::floor(x), fy = std::floor(y), fz = std::floor(z);
    int64_t ix = int64_t(fx), iy = int64_t(fy), iz = int64_t(fz);
    double u = fade(x - fx), v = fade(y - fy), w = fade(z - fz);
    // Neighbouring cells must agree on shared corners: the seed goes in after the coordinates.
    uint64_t key = uint64_t(ix) * kLatticeX + uint64_t(iy) * kLatticeY + uint64_t(iz) * kLatticeZ;
    uint64_t salt = mix64(seed);
    double corner[2][2][2];
    for (int dz = 0; dz < 2; ++dz)
        for (int dy = 0; dy < 2; ++dy)
            for (int dx = 0; dx < 2; ++dx)
                corner[dz][dy][dx] = lattice_value((key + dx * kLatticeX + dy * kLatticeY + dz * kLatticeZ) ^ salt);
    auto lerp = [](double a, double b, double t) { return a + (b - a) * t; };
    double y0 = lerp(lerp(corner[0][0][0], corner[0][0][1], u), lerp(corner[0][1][0], corner[0][1][1], u), v);
    double y1 = lerp(lerp(corner[1][0][0], corner[1][0][1], u), lerp(corner[1][1][0], corner[1][1][1], u), v);
    return lerp(y0, y1, w);
}

// Sum of `octaves` noise layers, each twice the frequency and half the amplitude of the last,
// normalised to [-1, 1].
double fbm(const Vec3d& p, double frequency, int octaves, uint64_t seed) {
    double sum = 0.0, amplitude = 1.0, total = 0.0;
    for (int o = 0; o < octaves; ++o) {
        sum += amplitude * value_noise(p[0] * frequency, p[1] * frequency, p[2] * frequency, seed + uint64_t(o));
        total += amplitude;
        amplitude *= 0.5;
        frequency *= 2.0;
    }
    return sum / total;
}

// sin and cos of 2*pi*turns. std::sin may differ between libm versions; these Taylor
// polynomials (error below 1e-16 on a quarter turn) give the same bits everywhere.
void sincos_turns(double turns, double& s, double& c) {
    turns -= std::floor(turns);
    double q = turns * 4.0;
    int quadrant = std::min(int(q), 3);
    double a = (q - quadrant) * 1.5707963267948966;
    double a2 = a * a;
    double sn = 1.0, cs = 1.0;
    for (int k = 21; k >= 3; k -= 2) sn = 1.0 - a2 / double((k - 1) * k) * sn;  // 1 - a^2/6 (1 - a^2/20 (...))
    for (int k = 20; k >= 2; k -= 2) cs = 1.0 - a2 / double((k - 1) * k) * cs;
    sn *= a;
    switch (quadrant) {
        case 0: s = sn, c = cs; break;
        case 1: s = cs, c = -sn; break;
        case 2: s = -sn, c = -cs; break;
        default: s = -cs, c = sn; break;
    }
}

Vec3d normalized(const Vec3d& p) {
    double length = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    return {p[0] / length, p[1] / length, p[2] / length};
}

// Equal-angle cube map: spreads cube-sphere vertices evenly (tan(q * pi/4) per axis).
double warp1(double q) {
    double s, c;
    sincos_turns(q * 0.125, s, c);
    return s / c;
}

Vec3d warp(const Vec3d& q) { return {warp1(q[0]), warp1(q[1]), warp1(q[2])}; }

// A smooth colour field in the unit-scale coordinates `p`.
Rgb8 smooth_color(const Vec3d& p, uint64_t seed) {
    Rgb8 out;
    for (int k = 0; k < 3; ++k) {
        double n = value_noise(p[0] * 1.7 + 10.0, p[1] * 1.7, p[2] * 1.7, mix64(seed) + uint64_t(k));
        out[k] = uint8_t(std::clamp(std::floor(128.0 + 120.0 * n), 0.0, 255.0));
    }
    return out;
}

// Runs body(begin, end) on slices of [0, n) in parallel. Every element is computed on its own,
// so the result does not depend on the number of threads.
template <class Body>
void parallel_for(size_t n, Body body) {
    size_t threads = n < 65536 ? 1 : std::clamp<size_t>(std::thread::hardware_concurrency(), 1, 16);
    std::vector<std::thread> workers;
    for (size_t t = 1; t < threads; ++t) workers.emplace_back(body, n * t / threads, n * (t + 1) / threads);
    body(0, n / threads);
    for (std::thread& worker : workers) worker.join();
}

// Colours every vertex from its position.
template <class Color>
void color_vertices(Mesh& mesh, Color color) {
    mesh.colors.resize(mesh.positions.size());
    parallel_for(mesh.positions.size(), [&](size_t begin, size_t end) {
        for (size_t v = begin; v < end; ++v) mesh.colors[v] = color(mesh.positions[v]);
    });
}

// Splits `splits` of `quads` quads evenly: quad q is split when the running quota steps.
bool split_here(size_t q, size_t splits, size_t quads) { return (q + 1) * splits / quads > q * splits / quads; }

// Appends quad a-b-c-d (counter-clockwise seen from outside) as two triangles, split along a-c
// (`main_diagonal`) or b-d, or as four around `centre` when centre != UINT32_MAX.
void emit_quad(std::vector<uint32_t>& out, uint32_t a, uint32_t b, uint32_t c, uint32_t d, bool main_diagonal,
               uint32_t centre) {
    if (centre != UINT32_MAX) out.insert(out.end(), {a, b, centre, b, c, centre, c, d, centre, d, a, centre});
    else if (main_diagonal) out.insert(out.end(), {a, b, c, a, c, d});
    else out.insert(out.end(), {a, b, d, b, c, d});
}

// ---------------------------------------------------------------------------------------------
// The surface of an a x b x c lattice box: shared corner and edge vertices are indexed
// arithmetically (no hash map), so memory is the output only.

struct BoxGrid {
    uint32_t n[3];  // subdivisions along x, y, z (each >= 1)

    size_t full_layer() const { return size_t(n[0] + 1) * (n[1] + 1); }
    size_t ring() const { return 2 * size_t(n[0] + n[1]); }
    size_t vertex_count() const { return 2 * full_layer() + size_t(n[2] - 1) * ring(); }
    size_t quad_count() const { return 2 * (size_t(n[0]) * n[1] + size_t(n[1]) * n[2] + size_t(n[2]) * n[0]); }

    // Position along the perimeter of a middle layer, counter-clockwise from (0, 0).
    size_t ring_index(uint32_t i, uint32_t j) const {
        uint32_t a = n[0], b = n[1];
        if (j == 0) return i;
        if (i == a) return a + j;
        if (j == b) return size_t(a) + b + (a - i);
        return 2 * size_t(a) + b + (b - j);
    }
    void ring_point(size_t p, uint32_t& i, uint32_t& j) const {
        uint32_t a = n[0], b = n[1];
        if (p <= a) i = uint32_t(p), j = 0;
        else if (p <= size_t(a) + b) i = a, j = uint32_t(p - a);
        else if (p <= 2 * size_t(a) + b) i = uint32_t(2 * size_t(a) + b - p), j = b;
        else i = 0, j = uint32_t(2 * size_t(a) + 2 * size_t(b) - p);
    }
    // The lattice point of vertex `index` (the inverse of index()).
    void point(size_t index, uint32_t& i, uint32_t& j, uint32_t& k) const {
        size_t middle = full_layer() + size_t(n[2] - 1) * ring();
        if (index < full_layer() || index >= middle) {
            k = index < full_layer() ? 0 : n[2];
            size_t in_layer = index < full_layer() ? index : index - middle;
            i = uint32_t(in_layer % (n[0] + 1));
            j = uint32_t(in_layer / (n[0] + 1));
        } else {
            k = uint32_t(1 + (index - full_layer()) / ring());
            ring_point((index - full_layer()) % ring(), i, j);
        }
    }
    uint32_t index(uint32_t i, uint32_t j, uint32_t k) const {
        if (k == 0) return uint32_t(size_t(j) * (n[0] + 1) + i);
        if (k == n[2]) return uint32_t(full_layer() + size_t(n[2] - 1) * ring() + size_t(j) * (n[0] + 1) + i);
        return uint32_t(full_layer() + size_t(k - 1) * ring() + ring_index(i, j));
    }
    // Cube coordinates in [-1, 1]: exact for power-of-two subdivisions.
    Vec3d cube(double i, double j, double k) const {
        return {(2.0 * i - n[0]) / n[0], (2.0 * j - n[1]) / n[1], (2.0 * k - n[2]) / n[2]};
    }
};

// warp() for the cube coordinates of one BoxGrid, from tables: a component of q is always a
// lattice or half-lattice coordinate (quad centres), so an axis needs only 2n+1 tangents. This
// takes the polynomials out of the per-vertex loop of the 20M-triangle generators.
class GridWarp {
public:
    explicit GridWarp(const BoxGrid& g) {
        for (int k = 0; k < 3; ++k) {
            n_[k] = g.n[k];
            table_[k].resize(2 * size_t(g.n[k]) + 1);
            for (size_t h = 0; h < table_[k].size(); ++h) table_[k][h] = warp1((double(h) - n_[k]) / n_[k]);
        }
    }
    Vec3d operator()(const Vec3d& q) const {
        Vec3d out;
        for (int k = 0; k < 3; ++k) out[k] = table_[k][size_t(std::lround((q[k] + 1.0) * n_[k]))];
        return out;
    }

private:
    double n_[3];
    std::vector<double> table_[3];
};

struct KeepAll {
    bool operator()(int, int, uint32_t, uint32_t) const { return true; }
};

// Builds the box surface. position(q) maps a cube-surface point q in [-1,1]^3 to the mesh;
// keep(axis, side, s, t) may drop quads (then `splits` must be 0). Faces are oriented outward
// and triangulated in a "union jack" pattern: diagonals run along the face's two diagonals.
template <class Position, class Keep = KeepAll>
Mesh box_surface(const BoxGrid& g, size_t splits, Position position, Keep keep = {}) {
    Mesh mesh;
    mesh_io::reserve_huge(mesh.positions, g.vertex_count() + splits);
    mesh.positions.resize(g.vertex_count() + splits);
    parallel_for(g.vertex_count(), [&](size_t begin, size_t end) {
        for (size_t v = begin; v < end; ++v) {
            uint32_t i, j, k;
            g.point(v, i, j, k);
            mesh.positions[v] = position(g.cube(i, j, k));
        }
    });
    mesh_io::reserve_huge(mesh.indices, 6 * g.quad_count() + 6 * splits);
    size_t quad = 0, centre = g.vertex_count();
    for (int axis = 0; axis < 3; ++axis) {
        int u = (axis + 1) % 3, v = (axis + 2) % 3;  // u x v = +axis
        for (int side = 0; side < 2; ++side) {
            for (uint32_t t = 0; t < g.n[v]; ++t) {
                for (uint32_t s = 0; s < g.n[u]; ++s, ++quad) {
                    if (!keep(axis, side, s, t)) continue;
                    uint32_t corner[4];
                    Vec3d sum{0, 0, 0};
                    static const uint32_t kDs[4] = {0, 1, 1, 0}, kDt[4] = {0, 0, 1, 1};
                    for (int c = 0; c < 4; ++c) {
                        uint32_t l[3];
                        l[axis] = side ? g.n[axis] : 0;
                        l[u] = s + kDs[c];
                        l[v] = t + kDt[c];
                        corner[c] = g.index(l[0], l[1], l[2]);
                        Vec3d q = g.cube(l[0], l[1], l[2]);
                        for (int d = 0; d < 3; ++d) sum[d] += q[d];
                    }
                    if (!side) std::swap(corner[1], corner[3]);  // the min side faces the other way
                    uint32_t middle = UINT32_MAX;
                    if (splits && split_here(quad, splits, g.quad_count())) {
                        middle = uint32_t(centre++);
                        mesh.positions[middle] = position({sum[0] * 0.25, sum[1] * 0.25, sum[2] * 0.25});
                    }
                    bool main_diagonal = (2 * s < g.n[u]) == (2 * t < g.n[v]);
                    emit_quad(mesh.indices, corner[0], corner[1], corner[2], corner[3], main_diagonal, middle);
                }
            }
        }
    }
    assert(centre == mesh.positions.size());
    return mesh;
}

// The box (a <= b <= c) whose surface has the most triangles not above `target`, and the
// number of quads to split so the total matches the target (an even target exactly).
void choose_box(size_t target, BoxGrid& grid, size_t& splits) {
    target = std::max<size_t>(target, 12);
    size_t s = size_t(std::sqrt(double(target) / 12.0)), best = 0;
    for (size_t a = std::max<size_t>(1, s > 2 ? s - 2 : 1); a <= s + 1; ++a) {
        for (size_t b = a; b <= a + 3; ++b) {
            if (4 * a * b > target) continue;
            size_t c = (target / 4 - a * b) / (a + b);
            if (c < b) continue;
            size_t triangles = 4 * (a * b + b * c + c * a);
            if (triangles > best) {
                best = triangles;
                grid = BoxGrid{{uint32_t(a), uint32_t(b), uint32_t(c)}};
            }
        }
    }
    splits = (target - best) / 2;
    assert(best > 0 && splits <= grid.quad_count());
}

// The nearest float, as a double. The empty asm makes the float exist in memory: GCC 12.2 at -O2
// miscompiles {double(float(a)), double(float(b)), ...} when its SLP vectoriser pairs the lanes,
// silently dropping the rounding.
double float_rounded(double x) {
    float f = float(x);
    asm volatile("" : "+m"(f));
    return double(f);
}

// Rounds positions to float so a float PLY stores them exactly (and reads give equal bits).
void round_to_float(Mesh& mesh) {
    for (Vec3d& p : mesh.positions)
        for (double& c : p) c = float_rounded(c);
}

std::vector<Vec3f> to_float(const std::vector<Vec3d>& v) {
    std::vector<Vec3f> out(v.size());
    for (size_t i = 0; i < v.size(); ++i) out[i] = {float(v[i][0]), float(v[i][1]), float(v[i][2])};
    return out;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Sphere, torus, scan

Mesh make_sphere(size_t target_triangles, uint64_t seed) {
    BoxGrid grid;
    size_t splits;
    choose_box(target_triangles, grid, splits);
    GridWarp warp(grid);
    Mesh mesh = box_surface(grid, splits, [&](const Vec3d& q) { return normalized(warp(q)); });
    round_to_float(mesh);
    mesh.normals = to_float(mesh.positions);  // on the unit sphere the position is the normal
    for (Vec3f& n : mesh.normals) {
        Vec3d unit = normalized({n[0], n[1], n[2]});
        n = {float(unit[0]), float(unit[1]), float(unit[2])};
    }
    color_vertices(mesh, [seed](const Vec3d& p) { return smooth_color(p, seed); });
    return mesh;
}

Mesh make_torus(size_t target_triangles, uint64_t seed) {
    constexpr double kMajor = 1.0, kMinor = 0.35;
    size_t target = std::max<size_t>(target_triangles, 18);
    // About three quads around the ring per quad around the tube keeps them near square.
    size_t minor = std::max<size_t>(3, size_t(std::sqrt(double(target) / 6.0)));
    size_t major = std::max<size_t>(3, target / (2 * minor));
    size_t quads = major * minor, splits = (target - std::min(target, 2 * quads)) / 2;
    assert(splits <= quads);

    Mesh mesh;
    mesh.positions.resize(quads + splits);
    mesh.normals.resize(quads + splits);
    auto point = [&](size_t index, double u, double v) {  // u, v in turns
        double su, cu, sv, cv;
        sincos_turns(u, su, cu);
        sincos_turns(v, sv, cv);
        double ring = kMajor + kMinor * cv;
        mesh.positions[index] = {float_rounded(ring * cu), float_rounded(ring * su), float_rounded(kMinor * sv)};
        mesh.normals[index] = {float(cv * cu), float(cv * su), float(sv)};
    };
    for (size_t j = 0; j < minor; ++j)
        for (size_t i = 0; i < major; ++i) point(j * major + i, double(i) / major, double(j) / minor);

    mesh.indices.reserve(6 * quads + 6 * splits);
    size_t centre = quads;
    for (size_t j = 0; j < minor; ++j) {
        for (size_t i = 0; i < major; ++i) {
            size_t i1 = (i + 1) % major, j1 = (j + 1) % minor;
            uint32_t middle = UINT32_MAX;
            if (splits && split_here(j * major + i, splits, quads)) {
                middle = uint32_t(centre++);
                point(middle, (i + 0.5) / major, (j + 0.5) / minor);
            }
            // (u, v) counter-clockwise is outward: d/du x d/dv points away from the tube's axis.
            emit_quad(mesh.indices, uint32_t(j * major + i), uint32_t(j * major + i1), uint32_t(j1 * major + i1),
                      uint32_t(j1 * major + i), (i + j) % 2 == 0, middle);
        }
    }
    color_vertices(mesh, [seed](const Vec3d& p) { return smooth_color(p, seed); });
    return mesh;
}

Mesh make_scan_like(size_t target_triangles, uint64_t seed) {
    BoxGrid grid;
    size_t splits;
    choose_box(target_triangles, grid, splits);
    // Octaves down to a wavelength of about eight triangle edges: detail at every scale, as in
    // a scan, without aliasing into noise.
    int octaves = 2;
    for (double wavelength = 1.0 / 1.5; octaves < 14 && wavelength / 2 > 12.0 / grid.n[2]; wavelength /= 2) ++octaves;
    const uint64_t shape_seed = mix64(seed ^ 0x5ca1ab1e);
    const Vec3d scale{0.8, 1.3, 0.7};
    GridWarp warp(grid);
    auto position = [&](const Vec3d& q) {
        Vec3d dir = normalized(warp(q));
        // Radial displacement keeps the surface star-shaped, hence closed and embedded.
        double radius = 1.0 + 0.3 * fbm(dir, 1.5, octaves, shape_seed);
        return Vec3d{dir[0] * radius * scale[0], dir[1] * radius * scale[1], dir[2] * radius * scale[2]};
    };
    Mesh mesh = box_surface(grid, splits, position);
    round_to_float(mesh);
    mesh.normals = compute_vertex_normals(mesh);
    color_vertices(mesh, [shape_seed](const Vec3d& p) {
        // Stone: a warm grey, veined by a second noise field.
        double shade = 150.0 + 60.0 * fbm(p, 3.0, 2, shape_seed + 100);
        return Rgb8{uint8_t(std::clamp(shade + 12.0, 0.0, 255.0)), uint8_t(std::clamp(shade + 4.0, 0.0, 255.0)),
                    uint8_t(std::clamp(shade - 8.0, 0.0, 255.0))};
    });
    return mesh;
}

Mesh make_uneven_density(size_t target_triangles, uint64_t seed) {
    const size_t total = std::max<size_t>(target_triangles, 96);
    Mesh mesh = make_scan_like(total / 8, seed);
    const Mesh sphere = make_sphere(total - mesh.triangle_count(), seed + 1);
    // The blob's surface stays beyond radius 0.5 of the origin: the sphere lies inside it, apart.
    constexpr double kRadius = 0.15;
    const uint32_t first = uint32_t(mesh.positions.size());
    for (size_t v = 0; v < sphere.positions.size(); ++v) {
        const Vec3d& p = sphere.positions[v];
        mesh.positions.push_back({p[0] * kRadius, p[1] * kRadius, p[2] * kRadius});
        mesh.normals.push_back(sphere.normals[v]);
        mesh.colors.push_back(sphere.colors[v]);
    }
    for (uint32_t i : sphere.indices) mesh.indices.push_back(first + i);
    return mesh;
}

}  // namespace catpaq

// ---------------------------------------------------------------------------------------------
// Hard cases

namespace catpaq {
namespace {

// Hand-built meshes: vertices, triangles, and a few solids.
struct Builder {
    Mesh mesh;

    uint32_t vertex(const Vec3d& p) {
        mesh.positions.push_back(p);
        return uint32_t(mesh.positions.size() - 1);
    }
    void triangle(uint32_t a, uint32_t b, uint32_t c) { mesh.indices.insert(mesh.indices.end(), {a, b, c}); }
    void append(const Mesh& other) {
        uint32_t base = uint32_t(mesh.positions.size());
        mesh.positions.insert(mesh.positions.end(), other.positions.begin(), other.positions.end());
        for (uint32_t i : other.indices) mesh.indices.push_back(base + i);
    }
    // A tetrahedron with its faces oriented outward (whatever the order of the corners).
    void tetrahedron(Vec3d p0, Vec3d p1, Vec3d p2, Vec3d p3) {
        Vec3d u{p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]}, v{p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
        Vec3d w{p3[0] - p0[0], p3[1] - p0[1], p3[2] - p0[2]};
        double volume6 = (u[1] * v[2] - u[2] * v[1]) * w[0] + (u[2] * v[0] - u[0] * v[2]) * w[1] +
                         (u[0] * v[1] - u[1] * v[0]) * w[2];
        assert(volume6 != 0.0);
        if (volume6 > 0) std::swap(p1, p2);  // outward needs p3 below face p0 p1 p2
        uint32_t a = vertex(p0), b = vertex(p1), c = vertex(p2), d = vertex(p3);
        triangle(a, b, c);
        triangle(a, d, b);
        triangle(b, d, c);
        triangle(a, c, d);
    }
    // A spindle: two cones sharing a ring of `sides` points of `radius` halfway along from-to.
    void bicone(const Vec3d& from, const Vec3d& to, double radius, int sides) {
        Vec3d axis = normalized({to[0] - from[0], to[1] - from[1], to[2] - from[2]});
        Vec3d helper = std::fabs(axis[0]) < 0.5 ? Vec3d{1, 0, 0} : Vec3d{0, 0, 1};
        Vec3d e1 = normalized(cross(axis, helper)), e2 = cross(axis, e1);  // (e1, e2, axis) right-handed
        uint32_t apex_from = vertex(from), apex_to = vertex(to), first = uint32_t(mesh.positions.size());
        for (int k = 0; k < sides; ++k) {
            double s, c;
            sincos_turns(double(k) / sides, s, c);
            Vec3d p;
            for (int d = 0; d < 3; ++d) p[d] = (from[d] + to[d]) * 0.5 + radius * (c * e1[d] + s * e2[d]);
            vertex(p);
        }
        for (int k = 0; k < sides; ++k) {
            uint32_t r0 = first + uint32_t(k), r1 = first + uint32_t((k + 1) % sides);
            triangle(r0, r1, apex_to);    // the ring runs counter-clockwise about the axis
            triangle(r1, r0, apex_from);
        }
    }
    static Vec3d cross(const Vec3d& a, const Vec3d& b) {
        return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
    }
};

// Merges vertices with identical positions (hand-built pieces meet at shared points).
void weld_exact(Mesh& mesh) {
    std::vector<uint32_t> order(mesh.positions.size()), remap(mesh.positions.size());
    for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(),
                     [&](uint32_t a, uint32_t b) { return mesh.positions[a] < mesh.positions[b]; });
    std::vector<Vec3d> positions;
    for (size_t k = 0; k < order.size(); ++k) {
        if (k == 0 || mesh.positions[order[k]] != mesh.positions[order[k - 1]])
            positions.push_back(mesh.positions[order[k]]);
        remap[order[k]] = uint32_t(positions.size() - 1);
    }
    for (uint32_t& i : mesh.indices) i = remap[i];
    mesh.positions = std::move(positions);
}

// Drops vertices no triangle uses (left behind when holes are cut).
void drop_unused_vertices(Mesh& mesh) {
    std::vector<uint32_t> remap(mesh.positions.size(), UINT32_MAX);
    std::vector<Vec3d> positions;
    for (uint32_t& i : mesh.indices) {
        if (remap[i] == UINT32_MAX) {
            remap[i] = uint32_t(positions.size());
            positions.push_back(mesh.positions[i]);
        }
        i = remap[i];
    }
    mesh.positions = std::move(positions);
}

// The cube [0,1]^3 on a 1/16 lattice with each face pushed inward as a step pyramid of depth
// (distance to the face border) / 4: coordinates stay multiples of 1/64, lattice lines stay in
// the planes x, y, z = k/16, and the surface stays embedded (the pyramids are shallower than
// the 45-degree wedges that separate the faces).
Mesh pushed_box() {
    auto position = [](const Vec3d& q) {
        Vec3d p{0.5 * q[0] + 0.5, 0.5 * q[1] + 0.5, 0.5 * q[2] + 0.5};
        Vec3d out = p;
        for (int axis = 0; axis < 3; ++axis) {
            if (q[axis] != -1.0 && q[axis] != 1.0) continue;
            int u = (axis + 1) % 3, v = (axis + 2) % 3;
            double depth = std::min({p[u], 1.0 - p[u], p[v], 1.0 - p[v]}) * 0.25;
            out[axis] = q[axis] < 0 ? depth : 1.0 - depth;
        }
        return out;
    };
    return box_surface(BoxGrid{{16, 16, 16}}, 0, position);
}

// A sphere with bounding box exactly [0,1]^3 (even subdivisions put vertices at the six poles,
// and |normalised component| <= 1 holds after rounding), scaled by `size`.
template <class Keep = KeepAll>
Mesh unit_box_sphere(uint32_t subdivisions, double size, Keep keep = {}) {
    auto position = [size](const Vec3d& q) {
        Vec3d d = normalized(warp(q));
        return Vec3d{size * (0.5 + 0.5 * d[0]), size * (0.5 + 0.5 * d[1]), size * (0.5 + 0.5 * d[2])};
    };
    return box_surface(BoxGrid{{subdivisions, subdivisions, subdivisions}}, 0, position, keep);
}

Mesh on_lattice_edges_and_corners() {
    Builder b;
    // An octahedron through the six face centres, each face split in four at edge midpoints.
    const Vec3d poles[6] = {{0, 0.5, 0.5}, {1, 0.5, 0.5}, {0.5, 0, 0.5}, {0.5, 1, 0.5}, {0.5, 0.5, 0}, {0.5, 0.5, 1}};
    Builder octahedron;
    for (int sx = 0; sx < 2; ++sx)
        for (int sy = 0; sy < 2; ++sy)
            for (int sz = 0; sz < 2; ++sz) {
                Vec3d a = poles[sx], c = poles[2 + sy], e = poles[4 + sz];
                if ((sx + sy + sz) % 2 == 0) std::swap(c, e);  // outward for every octant
                auto mid = [](const Vec3d& p, const Vec3d& q) {
                    return Vec3d{(p[0] + q[0]) * 0.5, (p[1] + q[1]) * 0.5, (p[2] + q[2]) * 0.5};
                };
                Vec3d ac = mid(a, c), ce = mid(c, e), ea = mid(e, a);
                for (const auto& t : {std::array<Vec3d, 3>{a, ac, ea}, std::array<Vec3d, 3>{ac, c, ce},
                                      std::array<Vec3d, 3>{ea, ce, e}, std::array<Vec3d, 3>{ac, ce, ea}})
                    octahedron.triangle(octahedron.vertex(t[0]), octahedron.vertex(t[1]), octahedron.vertex(t[2]));
            }
    weld_exact(octahedron.mesh);
    b.append(octahedron.mesh);
    // A vertex at the centre, one at the level-2 lattice corner (0.5,0.5,0.25), one on x=y=z.
    b.tetrahedron({0.5, 0.5, 0.5}, {0.5, 0.5, 0.25}, {0.25, 0.25, 0.25}, {0.75, 0.25, 0.375});
    // A face in the plane z=0.5 with the centre strictly inside it.
    b.tetrahedron({0.25, 0.25, 0.5}, {0.875, 0.375, 0.5}, {0.375, 0.875, 0.5}, {0.5, 0.5, 0.625});
    // An edge through the lattice corner (0.5,0.5,0.75) (its midpoint).
    b.tetrahedron({0.25, 0.75, 0.75}, {0.75, 0.25, 0.75}, {0.625, 0.625, 0.875}, {0.375, 0.375, 0.5625});
    // An edge along x=y=z with the centre as its midpoint.
    b.tetrahedron({0.375, 0.375, 0.375}, {0.625, 0.625, 0.625}, {0.75, 0.25, 0.5}, {0.5, 0.75, 0.25});
    return std::move(b.mesh);
}

Mesh slivers() {
    Builder b;
    const double radius = 0x1.0p-13;  // about 1.2e-4 against lengths near 1: aspect about 1e4
    b.bicone({0, 0, 0}, {1, 1, 1}, radius, 12);
    b.bicone({1, 0, 0}, {0, 1, 0.5}, radius, 12);  // these two miss the first and each other
    b.bicone({0, 0, 1}, {1, 0.5, 0}, radius, 12);
    return std::move(b.mesh);
}

Mesh degenerate_and_duplicate_triangles() {
    BoxGrid grid{{8, 8, 8}};
    Mesh mesh = box_surface(grid, 0, [](const Vec3d& q) {
        return Vec3d{0.5 * q[0] + 0.5, 0.5 * q[1] + 0.5, 0.5 * q[2] + 0.5};
    });
    std::vector<uint32_t>& t = mesh.indices;
    uint32_t a = t[0], b = t[1], c = t[2];
    // Three consecutive lattice points on the cube edge y = z = 0: distinct and exactly collinear.
    uint32_t p = grid.index(0, 0, 0), q = grid.index(1, 0, 0), r = grid.index(2, 0, 0);
    std::vector<uint32_t> extra = {a, a, b,          // repeated index
                                   c, c, c,          // a single point
                                   p, q, r, p, r, q,  // collinear, both orientations
                                   t[15], t[16], t[17],  // exact duplicate of triangle 5
                                   t[27], t[29], t[28]};  // triangle 9 reversed
    t.insert(t.end(), extra.begin(), extra.end());
    return mesh;
}

Mesh non_manifold_edges() {
    Builder b;
    // Three sheets hinged on the edge (0.5,0.5,0)-(0.5,0.5,1), reaching x=1, y=1 and (0,0).
    const Vec3d e0{0.5, 0.5, 0}, e1{0.5, 0.5, 1};
    const std::array<double, 2> far_edges[3] = {{1, 0.5}, {0.5, 1}, {0, 0}};
    for (const auto& far : far_edges) {
        uint32_t h0 = b.vertex(e0), h1 = b.vertex(e1);
        uint32_t f0 = b.vertex({far[0], far[1], 0}), f1 = b.vertex({far[0], far[1], 1});
        b.triangle(h0, f0, f1);
        b.triangle(h0, f1, h1);  // the hinge h0-h1 is an edge of this triangle in every sheet
    }
    // Two boxes meeting along the edge x=0.25, y=0.75, z in [0, 0.25].
    auto box = [&](const Vec3d& lo, const Vec3d& hi) {
        b.append(box_surface(BoxGrid{{1, 1, 1}}, 0, [&](const Vec3d& q) {
            Vec3d p;
            for (int d = 0; d < 3; ++d) p[d] = q[d] < 0 ? lo[d] : hi[d];
            return p;
        }));
    };
    box({0, 0.75, 0}, {0.25, 1, 0.25});
    box({0.25, 0.625, 0}, {0.375, 0.75, 0.25});
    weld_exact(b.mesh);
    return std::move(b.mesh);
}

// Four rectangular holes (2x2, 3x3, 1x1 and 4x2 quads) away from the poles and face borders:
// 8 + 12 + 4 + 12 = 36 border edges.
Mesh holes() {
    struct Hole {
        int axis, side;
        uint32_t s0, s1, t0, t1;
    };
    static const Hole kHoles[] = {{0, 1, 2, 4, 2, 4}, {1, 1, 10, 13, 3, 6}, {2, 0, 5, 6, 11, 12}, {0, 0, 9, 13, 9, 11}};
    auto keep = [](int axis, int side, uint32_t s, uint32_t t) {
        for (const Hole& h : kHoles)
            if (axis == h.axis && side == h.side && s >= h.s0 && s < h.s1 && t >= h.t0 && t < h.t1) return false;
        return true;
    };
    Mesh mesh = unit_box_sphere(16, 1.0, keep);
    drop_unused_vertices(mesh);
    return mesh;
}

Mesh flat(bool tilted) {
    constexpr uint32_t n = 32;
    Builder b;
    for (uint32_t j = 0; j <= n; ++j)
        for (uint32_t i = 0; i <= n; ++i)
            b.vertex({double(i) / n, double(j) / n, tilted ? double(i + j) / (2 * n) : 0.5});
    for (uint32_t j = 0; j < n; ++j)
        for (uint32_t i = 0; i < n; ++i) {
            uint32_t v = j * (n + 1) + i;
            emit_quad(b.mesh.indices, v, v + 1, v + n + 2, v + n + 1, (2 * i < n) == (2 * j < n), UINT32_MAX);
        }
    return std::move(b.mesh);
}

Mesh far_from_origin(double offset) {
    Mesh mesh = pushed_box();
    for (Vec3d& p : mesh.positions) p = {p[0] + offset, p[1] + 2 * offset, p[2] - offset};
    return mesh;
}

// A closed box surface in which some triangles (a, b, c) become three: (a, m, c), (m, b, c) and
// the sliver (a, b, m), with m at a height h above the midpoint of a-b (towards c in the
// triangle's plane, or along its inward normal). The sliver covers exactly what the other two leave
// out, so the surface stays closed and consistently oriented; its area relative to the triangle
// is about h / height of c, from 1e-12 to 1e-6: near-degenerate, but never exactly degenerate.
Mesh near_degenerate_triangles() {
    BoxGrid grid{{8, 8, 8}};
    Mesh mesh = box_surface(grid, 0, [](const Vec3d& q) {
        return Vec3d{0.5 * q[0] + 0.5, 0.5 * q[1] + 0.5, 0.5 * q[2] + 0.5};
    });
    const size_t triangles = mesh.triangle_count();
    const double heights[] = {1e-12, 1e-11, 1e-10, 1e-9, 1e-8, 1e-7, 1e-6};
    size_t k = 0;
    for (size_t t = 0; t < triangles; t += 13, ++k) {  // a spread-out subset, every face of the box
        uint32_t a = mesh.indices[3 * t], b = mesh.indices[3 * t + 1], c = mesh.indices[3 * t + 2];
        const Vec3d &pa = mesh.positions[a], &pb = mesh.positions[b], &pc = mesh.positions[c];
        Vec3d mid, ab, ac, dir;
        for (int i = 0; i < 3; ++i) {
            mid[i] = 0.5 * (pa[i] + pb[i]);
            ab[i] = pb[i] - pa[i];
            ac[i] = pc[i] - pa[i];
        }
        if (k % 2 == 0) {  // in the plane, towards c: the part of ac orthogonal to ab
            double s = (ab[0] * ac[0] + ab[1] * ac[1] + ab[2] * ac[2]) / (ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2]);
            dir = normalized({ac[0] - s * ab[0], ac[1] - s * ab[1], ac[2] - s * ab[2]});
        } else {  // along the triangle's inward normal (outward could leave the documented bounds)
            dir = normalized({ab[2] * ac[1] - ab[1] * ac[2], ab[0] * ac[2] - ab[2] * ac[0], ab[1] * ac[0] - ab[0] * ac[1]});
        }
        double h = heights[k % std::size(heights)];
        Vec3d m{mid[0] + h * dir[0], mid[1] + h * dir[1], mid[2] + h * dir[2]};
        if (m == mid) continue;  // h below the spacing of doubles here: would be exactly degenerate
        mesh.positions.push_back(m);
        uint32_t mi = uint32_t(mesh.positions.size() - 1);
        mesh.indices[3 * t + 1] = mi;                               // (a, m, c)
        mesh.indices.insert(mesh.indices.end(), {mi, b, c, a, b, mi});  // (m, b, c), sliver (a, b, m)
    }
    return mesh;
}

// Applies the seed (vertex and triangle order, corner rotation, colours) and adds normals.
void finish_hard_case(Mesh& mesh, uint64_t seed) {
    SplitMix64 rng{mix64(seed) ^ 0x4a5d};
    size_t n = mesh.positions.size();
    std::vector<uint32_t> permutation(n);
    for (uint32_t i = 0; i < n; ++i) permutation[i] = i;
    for (size_t i = n; i > 1; --i) std::swap(permutation[i - 1], permutation[rng.below(i)]);
    std::vector<Vec3d> positions(n);
    for (size_t i = 0; i < n; ++i) positions[permutation[i]] = mesh.positions[i];
    mesh.positions = std::move(positions);
    for (uint32_t& i : mesh.indices) i = permutation[i];

    size_t triangles = mesh.triangle_count();
    std::vector<uint32_t>& t = mesh.indices;
    for (size_t i = triangles; i > 1; --i) {
        size_t j = rng.below(i);
        for (int k = 0; k < 3; ++k) std::swap(t[3 * (i - 1) + k], t[3 * j + k]);
    }
    for (size_t i = 0; i < triangles; ++i) std::rotate(&t[3 * i], &t[3 * i] + rng.below(3), &t[3 * i] + 3);

    mesh.normals = compute_vertex_normals(mesh);
    Bounds bounds = mesh.bounds();
    double extent = 0;
    for (int k = 0; k < 3; ++k) extent = std::max(extent, bounds.max[k] - bounds.min[k]);
    mesh.colors.resize(n);
    for (size_t v = 0; v < n; ++v) {
        const Vec3d& p = mesh.positions[v];
        Vec3d unit{(p[0] - bounds.min[0]) / extent, (p[1] - bounds.min[1]) / extent, (p[2] - bounds.min[2]) / extent};
        mesh.colors[v] = smooth_color(unit, seed);
    }
}

}  // namespace

const char* hard_case_name(HardCase c) {
    switch (c) {
        case HardCase::OnBisectionPlanes: return "OnBisectionPlanes";
        case HardCase::OnLatticeEdgesAndCorners: return "OnLatticeEdgesAndCorners";
        case HardCase::Slivers: return "Slivers";
        case HardCase::DegenerateAndDuplicateTriangles: return "DegenerateAndDuplicateTriangles";
        case HardCase::NonManifoldEdges: return "NonManifoldEdges";
        case HardCase::Holes: return "Holes";
        case HardCase::Flat: return "Flat";
        case HardCase::FlatTilted: return "FlatTilted";
        case HardCase::FarFromOrigin: return "FarFromOrigin";
        case HardCase::FarFromOrigin1e7: return "FarFromOrigin1e7";
        case HardCase::Tiny: return "Tiny";
        case HardCase::NearDegenerateTriangles: return "NearDegenerateTriangles";
    }
    return "?";
}

Mesh make_hard_case(HardCase c, uint64_t seed) {
    Mesh mesh;
    switch (c) {
        case HardCase::OnBisectionPlanes: mesh = pushed_box(); break;
        case HardCase::OnLatticeEdgesAndCorners: mesh = on_lattice_edges_and_corners(); break;
        case HardCase::Slivers: mesh = slivers(); break;
        case HardCase::DegenerateAndDuplicateTriangles: mesh = degenerate_and_duplicate_triangles(); break;
        case HardCase::NonManifoldEdges: mesh = non_manifold_edges(); break;
        case HardCase::Holes: mesh = holes(); break;
        case HardCase::Flat: mesh = flat(false); break;
        case HardCase::FlatTilted: mesh = flat(true); break;
        case HardCase::FarFromOrigin: mesh = far_from_origin(1e6); break;
        case HardCase::FarFromOrigin1e7: mesh = far_from_origin(1e7); break;
        case HardCase::Tiny: mesh = unit_box_sphere(8, 1e-4); break;
        case HardCase::NearDegenerateTriangles: mesh = near_degenerate_triangles(); break;
    }
    finish_hard_case(mesh, seed);
    return mesh;
}

size_t hard_case_border_edges(HardCase c) {
    switch (c) {
        case HardCase::NonManifoldEdges: return 9;
        case HardCase::Holes: return 36;
        case HardCase::Flat:
        case HardCase::FlatTilted: return 128;
        default: return 0;
    }
}

Bounds hard_case_bounds(HardCase c) {
    Bounds bounds;
    bounds.min = {0, 0, 0};
    bounds.max = {1, 1, 1};
    if (c == HardCase::Flat) bounds.min[2] = bounds.max[2] = 0.5;
    if (c == HardCase::FarFromOrigin || c == HardCase::FarFromOrigin1e7) {
        double o = c == HardCase::FarFromOrigin ? 1e6 : 1e7;
        bounds.min = {o, 2 * o, -o};
        bounds.max = {o + 1, 2 * o + 1, -o + 1};
    }
    if (c == HardCase::Tiny) bounds.max = {1e-4, 1e-4, 1e-4};
    return bounds;
}

}  // namespace catpaq
