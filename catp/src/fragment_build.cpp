#include "fragment_build.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>

#include "catp/simplify.h"
#include "common_codec/barycentric.h"
#include "common_codec/octahedral.h"
#include "common_codec/packed_vertex.h"

namespace catpaq {

size_t PositionHash::operator()(const Vec3d& p) const {
    uint64_t h = 0xcbf29ce484222325ull;
    for (int i = 0; i < 3; ++i) {
        uint64_t bits;
        std::memcpy(&bits, &p[i], 8);
        h = (h ^ bits) * 0x100000001b3ull;
        h ^= h >> 29;
    }
    return size_t(h);
}

FragmentWelder::FragmentWelder(WorkFragment& fragment) : f_(fragment) {
    size_t capacity = 64;
    while (capacity < fragment.positions.size() * 2 + 16) capacity *= 2;
    table_.assign(capacity, 0);
    mask_ = capacity - 1;
    for (uint32_t i = 0; i < fragment.positions.size(); ++i) {
        size_t h = PositionHash()(fragment.positions[i]) & mask_;
        while (table_[h] != 0) h = (h + 1) & mask_;
        table_[h] = i + 1;
    }
}

void FragmentWelder::grow() {
    size_t capacity = table_.size() * 2;
    table_.assign(capacity, 0);
    mask_ = capacity - 1;
    for (uint32_t i = 0; i < f_.positions.size(); ++i) {
        size_t h = PositionHash()(f_.positions[i]) & mask_;
        while (table_[h] != 0) h = (h + 1) & mask_;
        table_[h] = i + 1;
    }
}

uint32_t FragmentWelder::find_or_insert(const Vec3d& p, bool& inserted) {
    if ((f_.positions.size() + 1) * 2 > table_.size()) grow();
    size_t h = PositionHash()(p) & mask_;
    while (table_[h] != 0) {
        const Vec3d& q = f_.positions[table_[h] - 1];
        if (q[0] == p[0] && q[1] == p[1] && q[2] == p[2]) {
            inserted = false;
            return table_[h] - 1;
        }
        h = (h + 1) & mask_;
    }
    uint32_t index = uint32_t(f_.positions.size());
    table_[h] = index + 1;
    inserted = true;
    return index;
}

uint32_t FragmentWelder::add(const Vec3d& position, const float normal[3], const float color[3]) {
    bool inserted;
    uint32_t index = find_or_insert(position, inserted);
    if (!inserted) return index;
    float len = std::sqrt(normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]);
    Vec3f n = len > 0 ? Vec3f{normal[0] / len, normal[1] / len, normal[2] / len} : Vec3f{0, 0, 1};
    Rgb8 c;
    for (int i = 0; i < 3; ++i) c[i] = uint8_t(std::clamp(std::lround(color[i]), 0l, 255l));
    f_.positions.push_back(position);
    f_.normals.push_back(n);
    f_.colors.push_back(c);
    return index;
}

uint32_t FragmentWelder::add(const Vec3d& position, const Vec3f& normal, const Rgb8& color) {
    bool inserted;
    uint32_t index = find_or_insert(position, inserted);
    if (!inserted) return index;
    f_.positions.push_back(position);
    f_.normals.push_back(normal);
    f_.colors.push_back(color);
    return index;
}

void FragmentWelder::triangle(uint32_t a, uint32_t b, uint32_t c) {
    if (a == b || b == c || a == c) return;
    f_.indices.insert(f_.indices.end(), {a, b, c});
}

void FragmentWelder::append(const WorkFragment& other) {
    std::vector<uint32_t> remap(other.positions.size());
    for (size_t v = 0; v < other.positions.size(); ++v)
        remap[v] = add(other.positions[v], other.normals[v], other.colors[v]);
    for (size_t i = 0; i + 2 < other.indices.size(); i += 3)
        triangle(remap[other.indices[i]], remap[other.indices[i + 1]], remap[other.indices[i + 2]]);
}

void FragmentWelder::add_clipped(const std::array<Vec3d, 3>& tri, const std::array<Vec3f, 3>& normals,
                                 const std::array<Rgb8, 3>& colors, const std::vector<ClipPlane>& planes) {
    clip_triangle(tri, planes, polygon_);
    if (polygon_.size() < 3) return;
    pieces_.clear();
    triangulate_polygon(polygon_, pieces_);
    uint32_t ids[16];
    assert(polygon_.size() <= 16);  // a triangle clipped by a tetrahedron has at most 7 corners
    for (size_t k = 0; k < polygon_.size(); ++k) {
        const ClipVertex& cv = polygon_[k];
        int corner = -1;
        for (int j = 0; j < 3; ++j)
            if (cv.weights[j] == 1.0) corner = j;
        if (corner >= 0) {
            ids[k] = add(cv.position, normals[corner], colors[corner]);
            continue;
        }
        float n[3] = {0, 0, 0}, c[3] = {0, 0, 0};
        for (int j = 0; j < 3; ++j)
            for (int a = 0; a < 3; ++a) {
                n[a] += float(cv.weights[j]) * normals[j][a];
                c[a] += float(cv.weights[j]) * colors[j][a];
            }
        ids[k] = add(cv.position, n, c);
    }
    for (auto& piece : pieces_) triangle(ids[piece[0]], ids[piece[1]], ids[piece[2]]);
}

static ClipPlane face_clip_plane(const LatticePoint& a, const LatticePoint& b, const LatticePoint& c,
                                 const LatticePoint& keep) {
    ClipPlane cp;
    cp.plane = make_plane(a, b, c);
    Vec3d k = {double(keep[0]), double(keep[1]), double(keep[2])};
    cp.sign = plane_side(cp.plane, k) > 0 ? 1 : -1;
    cp.corners = {a, b, c};
    cp.lines = {{a, b}, {b, c}, {a, c}};
    return cp;
}

std::vector<ClipPlane> tetrahedron_clip_planes(const Tetrahedron& t, unsigned face_mask) {
    std::vector<ClipPlane> planes;
    for (int f = 0; f < 4; ++f)
        if (face_mask & (1u << f)) planes.push_back(face_clip_plane(t[(f + 1) % 4], t[(f + 2) % 4], t[(f + 3) % 4], t[f]));
    return planes;
}

void quantize_fragment(const WorkFragment& in, const Tetrahedron& corners, FragmentMesh& out) {
    out.vertices.clear();
    out.indices.clear();
    LatticePlane faces[4];
    for (int f = 0; f < 4; ++f) faces[f] = make_plane(corners[(f + 1) % 4], corners[(f + 2) % 4], corners[(f + 3) % 4]);
    std::array<LatticePoint, 4> c = {corners[0], corners[1], corners[2], corners[3]};
    // Vertices closer than a grid step quantize to the same position: merge them (keeping the
    // first one's normal and colour) and drop the triangles that collapse.
    std::vector<uint32_t> remap(in.positions.size());
    std::unordered_map<uint32_t, uint32_t> by_position;
    by_position.reserve(in.positions.size() * 2);
    for (size_t v = 0; v < in.positions.size(); ++v) {
        const Vec3d& p = in.positions[v];
        SupportMask support = 0;
        for (int f = 0; f < 4; ++f)
            if (plane_side(faces[f], p) != 0) support |= SupportMask(1 << f);
        if (support == 0) support = 0xf;  // cannot happen for a point in the tetrahedron
        BaryWeights w = bary_quantize(p.data(), c, support);
        uint32_t index = bary_pack(w);
        auto [it, inserted] = by_position.emplace(index, uint32_t(out.vertices.size()));
        remap[v] = it->second;
        if (!inserted) continue;
        const Vec3f& n = in.normals[v];
        out.vertices.push_back(PackedVertex::make(index, oct_encode_precise(n[0], n[1], n[2]), in.colors[v][0],
                                                  in.colors[v][1], in.colors[v][2]));
    }
    for (size_t i = 0; i + 2 < in.indices.size(); i += 3) {
        uint32_t a = remap[in.indices[i]], b = remap[in.indices[i + 1]], d = remap[in.indices[i + 2]];
        if (a == b || b == d || a == d) continue;
        out.indices.insert(out.indices.end(), {a, b, d});
    }
}

namespace {

// Closest point on triangle (a, b, c) to p (Ericson, Real-Time Collision Detection 5.1.5);
// returns the squared distance.
double point_triangle_distance2(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    auto sub = [](const Vec3d& x, const Vec3d& y) { return Vec3d{x[0] - y[0], x[1] - y[1], x[2] - y[2]}; };
    auto dot = [](const Vec3d& x, const Vec3d& y) { return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]; };
    auto at = [&](double v, double w) {
        Vec3d q = {a[0] + v * (b[0] - a[0]) + w * (c[0] - a[0]), a[1] + v * (b[1] - a[1]) + w * (c[1] - a[1]),
                   a[2] + v * (b[2] - a[2]) + w * (c[2] - a[2])};
        Vec3d d = sub(p, q);
        return dot(d, d);
    };
    Vec3d ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
    double d1 = dot(ab, ap), d2 = dot(ac, ap);
    if (d1 <= 0 && d2 <= 0) return at(0, 0);
    Vec3d bp = sub(p, b);
    double d3 = dot(ab, bp), d4 = dot(ac, bp);
    if (d3 >= 0 && d4 <= d3) return at(1, 0);
    double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return at(d1 / (d1 - d3), 0);
    Vec3d cp = sub(p, c);
    double d5 = dot(ab, cp), d6 = dot(ac, cp);
    if (d6 >= 0 && d5 <= d6) return at(0, 1);
    double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return at(0, d2 / (d2 - d6));
    double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
        double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return at(1 - w, w);
    }
    double denom = 1.0 / (va + vb + vc);
    return at(vb * denom, vc * denom);
}

// Distance from points to a small triangle mesh through a uniform grid of its triangles' boxes.
// (CGAL's AABB tree took half of the converter's time here: a diamond has a few thousand
// triangles and each query lies close to the surface, which a grid answers in a cell or two.)
class GridDistance {
public:
    GridDistance(const std::vector<Vec3d>& positions, const std::vector<uint32_t>& indices)
        : positions_(positions), indices_(indices) {
        size_t triangles = indices.size() / 3;
        for (int i = 0; i < 3; ++i) {
            lo_[i] = 1e300;
            hi_[i] = -1e300;
        }
        for (uint32_t v : indices)
            for (int i = 0; i < 3; ++i) {
                lo_[i] = std::min(lo_[i], positions[v][i]);
                hi_[i] = std::max(hi_[i], positions[v][i]);
            }
        double extent = std::max({hi_[0] - lo_[0], hi_[1] - lo_[1], hi_[2] - lo_[2], 1e-9});
        // Cells of about two mean edge lengths (a surface fills few of them, each holding a few
        // triangles), at most 128 per axis.
        double edges = 0;
        for (size_t t = 0; t < triangles; ++t)
            for (int k = 0; k < 3; ++k) {
                const Vec3d &a = positions[indices[3 * t + k]], &b = positions[indices[3 * t + (k + 1) % 3]];
                edges += std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
            }
        double mean_edge = triangles ? edges / double(3 * triangles) : extent;
        cell_ = std::max(extent / 128.0, 2.0 * mean_edge) * 1.0000001;
        for (int i = 0; i < 3; ++i) dims_[i] = std::max(1, int((hi_[i] - lo_[i]) / cell_) + 1);
        std::vector<uint32_t> counts(size_t(dims_[0]) * dims_[1] * dims_[2] + 1, 0);
        auto for_cells = [&](size_t t, auto&& f) {
            int a[3], b[3];
            for (int i = 0; i < 3; ++i) {
                double mn = 1e300, mx = -1e300;
                for (int k = 0; k < 3; ++k) {
                    mn = std::min(mn, positions[indices[3 * t + k]][i]);
                    mx = std::max(mx, positions[indices[3 * t + k]][i]);
                }
                a[i] = clamp_cell(i, mn);
                b[i] = clamp_cell(i, mx);
            }
            for (int z = a[2]; z <= b[2]; ++z)
                for (int y = a[1]; y <= b[1]; ++y)
                    for (int x = a[0]; x <= b[0]; ++x) f(cell_index(x, y, z));
        };
        spheres_.resize(triangles);
        for (size_t t = 0; t < triangles; ++t) {
            const Vec3d &a = positions[indices[3 * t]], &b = positions[indices[3 * t + 1]], &c = positions[indices[3 * t + 2]];
            std::array<double, 4>& sphere = spheres_[t];
            for (int i = 0; i < 3; ++i) sphere[i] = (a[i] + b[i] + c[i]) / 3.0;
            sphere[3] = 0;
            for (const Vec3d* q : {&a, &b, &c}) {
                double d = std::sqrt(((*q)[0] - sphere[0]) * ((*q)[0] - sphere[0]) + ((*q)[1] - sphere[1]) * ((*q)[1] - sphere[1]) +
                                     ((*q)[2] - sphere[2]) * ((*q)[2] - sphere[2]));
                sphere[3] = std::max(sphere[3], d * 1.000001);
            }
        }
        for (size_t t = 0; t < triangles; ++t) for_cells(t, [&](size_t c) { counts[c + 1]++; });
        for (size_t c = 1; c < counts.size(); ++c) counts[c] += counts[c - 1];
        start_ = counts;
        items_.resize(counts.back());
        for (size_t t = 0; t < triangles; ++t) for_cells(t, [&](size_t c) { items_[counts[c]++] = uint32_t(t); });
    }

    double distance(const Vec3d& p) const {
        if (indices_.empty()) return 0.0;
        int c[3];
        for (int i = 0; i < 3; ++i) c[i] = clamp_cell(i, p[i]);
        double best = 1e300;
        // Rings of cells around p's cell. Every triangle not yet seen before ring r is at least
        // margin + (r - 1) cells away, margin being p's distance to the faces of its own cell
        // (0 if p lies outside the grid): stop once the best found is closer than that.
        double margin = 1e300;
        for (int i = 0; i < 3; ++i) {
            double in_cell = p[i] - (lo_[i] + c[i] * cell_);
            margin = std::min({margin, in_cell, cell_ - in_cell});
        }
        margin = std::max(0.0, margin);
        for (int r = 0; r <= std::max({dims_[0], dims_[1], dims_[2]}); ++r) {
            if (r > 0 && best < 1e300 && std::sqrt(best) <= margin + double(r - 1) * cell_) break;
            for (int z = c[2] - r; z <= c[2] + r; ++z)
                for (int y = c[1] - r; y <= c[1] + r; ++y)
                    for (int x = c[0] - r; x <= c[0] + r; ++x) {
                        if (std::max({std::abs(x - c[0]), std::abs(y - c[1]), std::abs(z - c[2])}) != r) continue;
                        if (x < 0 || y < 0 || z < 0 || x >= dims_[0] || y >= dims_[1] || z >= dims_[2]) continue;
                        size_t cell = cell_index(x, y, z);
                        for (uint32_t k = start_[cell]; k < start_[cell + 1]; ++k) {
                            uint32_t t = items_[k];
                            // Bounding-sphere lower bound first: most triangles of a cell are
                            // farther than the best already found.
                            const std::array<double, 4>& sphere = spheres_[t];
                            double dx = p[0] - sphere[0], dy = p[1] - sphere[1], dz = p[2] - sphere[2];
                            double gap = std::sqrt(dx * dx + dy * dy + dz * dz) - sphere[3];
                            if (gap > 0 && gap * gap >= best) continue;
                            best = std::min(best, point_triangle_distance2(p, positions_[indices_[3 * t]],
                                                                           positions_[indices_[3 * t + 1]],
                                                                           positions_[indices_[3 * t + 2]]));
                        }
                    }
        }
        return std::sqrt(best);
    }

private:
    int clamp_cell(int axis, double v) const { return std::max(0, std::min(dims_[axis] - 1, int((v - lo_[axis]) / cell_))); }
    size_t cell_index(int x, int y, int z) const { return (size_t(z) * dims_[1] + y) * dims_[0] + x; }

    const std::vector<Vec3d>& positions_;
    const std::vector<uint32_t>& indices_;
    double lo_[3], hi_[3], cell_ = 1;
    int dims_[3] = {1, 1, 1};
    std::vector<uint32_t> start_, items_;
    std::vector<std::array<double, 4>> spheres_;  // per triangle: centroid and radius
};

}  // namespace

// Hausdorff-style distance between the gathered surface and its simplification, both ways:
// removed vertices to the simplified surface, and the simplified triangles' centroids and edge
// midpoints to the gathered surface. (The simplifier's quadric cost is a mean, not a bound:
// measured here so the stored errors can be trusted by the cut engine.)
double measured_simplification_error(const WorkFragment& gathered, const std::vector<uint32_t>& simplified) {
    if (simplified.size() == gathered.indices.size()) return 0.0;
    std::vector<uint8_t> kept(gathered.positions.size(), 0);
    for (uint32_t v : simplified) kept[v] = 1;
    double error = 0;
    {
        GridDistance to_simplified(gathered.positions, simplified);
        for (size_t v = 0; v < gathered.positions.size(); ++v)
            if (!kept[v]) error = std::max(error, to_simplified.distance(gathered.positions[v]));
    }
    GridDistance to_gathered(gathered.positions, gathered.indices);
    for (size_t i = 0; i + 2 < simplified.size(); i += 3) {
        const Vec3d &a = gathered.positions[simplified[i]], &b = gathered.positions[simplified[i + 1]],
                    &c = gathered.positions[simplified[i + 2]];
        Vec3d points[4] = {{(a[0] + b[0] + c[0]) / 3, (a[1] + b[1] + c[1]) / 3, (a[2] + b[2] + c[2]) / 3},
                           {(a[0] + b[0]) / 2, (a[1] + b[1]) / 2, (a[2] + b[2]) / 2},
                           {(b[0] + c[0]) / 2, (b[1] + c[1]) / 2, (b[2] + c[2]) / 2},
                           {(a[0] + c[0]) / 2, (a[1] + c[1]) / 2, (a[2] + c[2]) / 2}};
        for (const Vec3d& p : points) error = std::max(error, to_gathered.distance(p));
    }
    return error;
}

double coarsen_diamond(const DiamondInfo& d, const WorkFragment& gathered, std::array<WorkFragment, 8>& out) {
    for (auto& f : out) f = WorkFragment{};
    uint8_t slots = existing_slots(d);
    int n = d.ring_size;
    // Outer faces: those not containing the spine; plus interior faces on the root boundary of a
    // partial diamond (their neighbour slot does not exist).
    std::vector<LatticePlane> outer;
    for (int s = 0; s < n; ++s) {
        if (!(slots & (1 << s))) continue;
        const LatticePoint &r0 = d.ring[s], &r1 = d.ring[(s + 1) % n];
        outer.push_back(make_plane(d.spine_a, r0, r1));
        outer.push_back(make_plane(d.spine_b, r0, r1));
        if (!(slots & (1 << ((s + n - 1) % n)))) outer.push_back(make_plane(d.spine_a, d.spine_b, r0));
        if (!(slots & (1 << ((s + 1) % n)))) outer.push_back(make_plane(d.spine_a, d.spine_b, r1));
    }
    size_t vertex_count = gathered.positions.size();
    std::vector<uint8_t> locked(vertex_count, 0);
    for (size_t v = 0; v < vertex_count; ++v) {
        const Vec3d& p = gathered.positions[v];
        for (const LatticePlane& plane : outer) {
            double value = plane.n[0] * p[0] + plane.n[1] * p[1] + plane.n[2] * p[2] - double(plane.d);
            if (std::fabs(value) < 1e-3 && plane_side(plane, p) == 0) {
                locked[v] = 1;
                break;
            }
        }
    }
    SimplifySettings settings;
    settings.target_triangles = gathered.indices.size() / 3 / 2;
    SimplifyResult simplified = simplify_mesh(&gathered.positions[0][0], vertex_count, gathered.indices.data(),
                                              gathered.indices.size(), locked.data(), settings);
    double error = measured_simplification_error(gathered, simplified.indices);

    // Clip by the interior faces into the slots.
    std::vector<std::vector<ClipPlane>> slot_planes(n);
    std::vector<FragmentWelder> welders;
    welders.reserve(8);
    for (int s = 0; s < 8; ++s) welders.emplace_back(out[s]);
    for (int s = 0; s < n; ++s) {
        if (!(slots & (1 << s))) continue;
        Tetrahedron t = diamond_tetrahedron(d, s);
        // Faces opposite corners 3 and 2 are (A, B, r0) and (A, B, r1): the interior ones.
        slot_planes[s] = tetrahedron_clip_planes(t, (1u << 2) | (1u << 3));
    }
    for (size_t i = 0; i + 2 < simplified.indices.size(); i += 3) {
        const uint32_t* f = &simplified.indices[i];
        std::array<Vec3d, 3> tri = {gathered.positions[f[0]], gathered.positions[f[1]], gathered.positions[f[2]]};
        std::array<Vec3f, 3> normals = {gathered.normals[f[0]], gathered.normals[f[1]], gathered.normals[f[2]]};
        std::array<Rgb8, 3> colors = {gathered.colors[f[0]], gathered.colors[f[1]], gathered.colors[f[2]]};
        for (int s = 0; s < n; ++s)
            if (!slot_planes[s].empty()) welders[s].add_clipped(tri, normals, colors, slot_planes[s]);
    }
    return error;
}

}  // namespace catpaq
