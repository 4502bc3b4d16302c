// codec_bench: the lossless fragment codec on the Stanford bunny, against Draco and meshoptimizer.
//
// Usage: codec_bench [mesh file] [--grid N] [--profile-decode LOOPS]
//
// The real CATP fragments come from the converter; until it exists, build_fragments() below cuts
// the mesh itself: the mesh is put in a cube on an integer lattice (coordinates up to 2^16), the
// cube is split into N^3 cells of 6 Kuhn tetrahedra each, every triangle goes to the tetrahedron
// containing its centroid and is kept only if its three vertices lie in that tetrahedron (the
// others are dropped and counted). Positions are quantised with bary_quantize, normals
// (area-weighted) with oct_encode_precise, colours come from a synthetic smooth field.
//
// Reported: bits per vertex by component, equivalent global position precision, encode/decode
// speed (best of 20 runs), then Draco (draco_encoder/draco_decoder command-line tools, skipped
// when missing) and meshoptimizer's vertex/index codecs on the same data, each peer's decoding
// against ours with the same attributes (the fragments are also encoded without colour, in the
// layout a colourless input gets, for Draco's colourless files).
#include <meshoptimizer.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "base/error.h"
#include "base/sysinfo.h"
#include "common_codec/barycentric.h"
#include "common_codec/fragment_codec.h"
#include "common_codec/octahedral.h"
#ifdef CATPAQ_HAVE_MESH_IO
#include "mesh/io.h"
#endif

using namespace catpaq;

namespace {

using Vec3 = std::array<double, 3>;

struct InputMesh {
    std::vector<Vec3> positions;
    std::vector<uint32_t> indices;
};

#ifndef CATPAQ_HAVE_MESH_IO
// Tiny OFF reader (triangles and fan-triangulated polygons), used when the mesh module is absent.
InputMesh read_off(const std::string& path) {
    std::ifstream in(path);
    if (!in) fail("cannot open %s", path.c_str());
    std::string magic;
    in >> magic;
    if (magic != "OFF") fail("%s: not an OFF file", path.c_str());
    size_t nv = 0, nf = 0, ne = 0;
    in >> nv >> nf >> ne;
    InputMesh m;
    m.positions.resize(nv);
    for (auto& p : m.positions) in >> p[0] >> p[1] >> p[2];
    for (size_t f = 0; f < nf; ++f) {
        size_t n = 0;
        in >> n;
        std::vector<uint32_t> poly(n);
        for (auto& i : poly) in >> i;
        for (size_t k = 2; k < n; ++k) m.indices.insert(m.indices.end(), {poly[0], poly[k - 1], poly[k]});
    }
    if (!in) fail("%s: truncated OFF file", path.c_str());
    for (uint32_t i : m.indices)
        if (i >= nv) fail("%s: index out of range", path.c_str());
    return m;
}
#endif

InputMesh load_input(const std::string& path) {
#ifdef CATPAQ_HAVE_MESH_IO
    Mesh mesh = read_mesh(path);
    return InputMesh{mesh.positions, mesh.indices};
#else
    return read_off(path);
#endif
}

bool file_exists(const std::string& path) {
    struct stat s;
    return stat(path.c_str(), &s) == 0;
}

std::string run_command(const std::string& cmd) {
    std::string out;
    FILE* p = popen((cmd + " 2>&1").c_str(), "r");
    if (!p) return out;
    char buf[4096];
    size_t n;
    while ((n = fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
    pclose(p);
    return out;
}

// data/bunny.ply when present, otherwise CGAL's copy of the bunny extracted to a temporary file.
std::string default_input(const std::string& temp_dir) {
    std::string ply = std::string(CATPAQ_SOURCE_DIR) + "/data/bunny.ply";
    if (file_exists(ply)) return ply;
    std::string off = temp_dir + "/bunny00.off";
    run_command("tar -xzf /usr/share/doc/libcgal-dev/data.tar.gz data/meshes/bunny00.off -O > " + off);
    if (!file_exists(off)) fail("no input mesh: %s is missing and CGAL's bunny00.off could not be extracted", ply.c_str());
    return off;
}

std::vector<Vec3> area_weighted_normals(const InputMesh& m) {
    std::vector<Vec3> n(m.positions.size(), Vec3{0, 0, 0});
    for (size_t t = 0; t < m.indices.size(); t += 3) {
        const Vec3 &a = m.positions[m.indices[t]], &b = m.positions[m.indices[t + 1]], &c = m.positions[m.indices[t + 2]];
        Vec3 e1 = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2 = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        Vec3 f = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
        for (int k = 0; k < 3; ++k)
            for (int d = 0; d < 3; ++d) n[m.indices[t + size_t(k)]][size_t(d)] += f[size_t(d)];
    }
    for (Vec3& v : n) {
        double l = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
        if (l > 0)
            for (double& x : v) x /= l;
        else
            v = {0, 0, 1};
    }
    return n;
}

// ---- fragment builder (to be replaced by the converter's output) ----------------------------

struct Fragment {
    FragmentMesh mesh;
    std::array<LatticePoint, 4> corners;  // canonical order
};

struct FragmentSet {
    std::vector<Fragment> fragments;
    int grid = 0;              // cells per cube side
    int32_t cell = 0;          // cell side in lattice units
    double lattice_per_unit = 0;  // lattice units per mesh unit
    size_t kept_triangles = 0, dropped_triangles = 0;
};

struct Bounds3 {
    Vec3 lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
    double extent() const { return std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]}); }
    double diagonal() const {
        double s = 0;
        for (int i = 0; i < 3; ++i) s += (hi[size_t(i)] - lo[size_t(i)]) * (hi[size_t(i)] - lo[size_t(i)]);
        return std::sqrt(s);
    }
};

Bounds3 bounds_of(const InputMesh& m) {
    Bounds3 b;
    for (const Vec3& p : m.positions)
        for (int i = 0; i < 3; ++i) {
            b.lo[size_t(i)] = std::min(b.lo[size_t(i)], p[size_t(i)]);
            b.hi[size_t(i)] = std::max(b.hi[size_t(i)], p[size_t(i)]);
        }
    return b;
}

// A smooth synthetic colour field over the bounding box.
std::array<uint8_t, 3> synthetic_color(const Vec3& p, const Bounds3& b) {
    double e = b.extent();
    double x = (p[0] - b.lo[0]) / e, y = (p[1] - b.lo[1]) / e, z = (p[2] - b.lo[2]) / e;
    auto chan = [](double v) { return uint8_t(std::lround(std::clamp(127.5 + 120.0 * v, 0.0, 255.0))); };
    return {chan(std::sin(6.0 * x + 1.0)), chan(std::cos(5.0 * y - 2.0 * z)), chan(std::sin(4.0 * z + 3.0 * x))};
}

FragmentSet build_fragments(const InputMesh& m, const std::vector<Vec3>& normals, int grid) {
    FragmentSet set;
    set.grid = grid;
    set.cell = int32_t((1 << 16) / grid);
    const Bounds3 b = bounds_of(m);
    const double side = double(set.cell) * grid;  // lattice units of the cube
    const double extent = b.extent() * (1.0 + 1e-9);
    set.lattice_per_unit = side / extent;
    const size_t nv = m.positions.size();
    std::vector<Vec3> q(nv);
    for (size_t v = 0; v < nv; ++v)
        for (int i = 0; i < 3; ++i)
            q[v][size_t(i)] = std::clamp((m.positions[v][size_t(i)] - b.lo[size_t(i)]) * set.lattice_per_unit, 0.0, side);

    // Tetrahedron of a point: cell (i, j, k) and the axis permutation sorting local coordinates
    // in decreasing order (Kuhn simplex x_p0 >= x_p1 >= x_p2).
    static const int kPerm[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
    auto cell_of = [&](double x) { return std::min(grid - 1, int(x / set.cell)); };
    auto tet_of = [&](const Vec3& p, int cell[3]) {
        double l[3];
        for (int i = 0; i < 3; ++i) {
            cell[i] = cell_of(p[size_t(i)]);
            l[i] = p[size_t(i)] - double(cell[i]) * set.cell;
        }
        for (int t = 0; t < 6; ++t)
            if (l[kPerm[t][0]] >= l[kPerm[t][1]] && l[kPerm[t][1]] >= l[kPerm[t][2]]) return t;
        return 0;
    };
    // Barycentric coordinates (in path order C0..C3) of p in tetrahedron (cell, t); false if outside.
    auto inside = [&](const Vec3& p, const int cell[3], int t, double lambda[4]) {
        double l[3];
        for (int i = 0; i < 3; ++i) {
            l[i] = p[size_t(i)] - double(cell[i]) * set.cell;
            if (l[i] < 0 || l[i] > set.cell) return false;
        }
        const int* pm = kPerm[t];
        if (!(l[pm[0]] >= l[pm[1]] && l[pm[1]] >= l[pm[2]])) return false;
        lambda[0] = set.cell - l[pm[0]];
        lambda[1] = l[pm[0]] - l[pm[1]];
        lambda[2] = l[pm[1]] - l[pm[2]];
        lambda[3] = l[pm[2]];
        return true;
    };

    std::map<std::array<int, 4>, size_t> frag_of;  // (cell i, j, k, t) -> fragment
    std::vector<std::map<uint32_t, uint32_t>> local;  // per fragment: mesh vertex -> fragment vertex
    const Bounds3 world = b;
    for (size_t t = 0; t < m.indices.size(); t += 3) {
        const uint32_t vi[3] = {m.indices[t], m.indices[t + 1], m.indices[t + 2]};
        Vec3 c = {0, 0, 0};
        for (uint32_t v : vi)
            for (int i = 0; i < 3; ++i) c[size_t(i)] += q[v][size_t(i)] / 3.0;
        int cell[3];
        int tet = tet_of(c, cell);
        double lambda[3][4];
        bool ok = true;
        for (int k = 0; k < 3 && ok; ++k) ok = inside(q[vi[k]], cell, tet, lambda[k]);
        if (!ok) {
            ++set.dropped_triangles;
            continue;
        }
        ++set.kept_triangles;
        std::array<int, 4> key = {cell[0], cell[1], cell[2], tet};
        auto it = frag_of.find(key);
        if (it == frag_of.end()) {
            it = frag_of.emplace(key, set.fragments.size()).first;
            Fragment f;
            const int* pm = kPerm[tet];
            LatticePoint c0 = {cell[0] * set.cell, cell[1] * set.cell, cell[2] * set.cell};
            f.corners[0] = c0;
            for (int s = 0; s < 3; ++s) {
                f.corners[size_t(s) + 1] = f.corners[size_t(s)];
                f.corners[size_t(s) + 1][size_t(pm[s])] += set.cell;
            }
            set.fragments.push_back(f);
            local.emplace_back();
        }
        Fragment& f = set.fragments[it->second];
        for (int k = 0; k < 3; ++k) {
            auto [slot, fresh] = local[it->second].emplace(vi[k], uint32_t(f.mesh.vertices.size()));
            if (fresh) {
                // Support: corners with non-zero barycentric coordinate (exact comparisons).
                std::array<LatticePoint, 4> corners = f.corners;
                std::array<int, 4> perm = canonical_order(corners);
                SupportMask support = 0;
                for (int j = 0; j < 4; ++j)
                    if (lambda[k][perm[size_t(j)]] > 0) support |= SupportMask(1u << j);
                BaryWeights w = bary_quantize(q[vi[k]].data(), corners, support);
                const Vec3& n = normals[vi[k]];
                uint16_t code = oct_encode_precise(float(n[0]), float(n[1]), float(n[2]));
                std::array<uint8_t, 3> rgb = synthetic_color(m.positions[vi[k]], world);
                f.mesh.vertices.push_back(PackedVertex::make(bary_pack(w), code, rgb[0], rgb[1], rgb[2]));
            }
            f.mesh.indices.push_back(slot->second);
        }
    }
    for (Fragment& f : set.fragments) canonical_order(f.corners);
    return set;
}

// Cells per side giving about `target` triangles per non-empty fragment.
int choose_grid(const InputMesh& m, const std::vector<Vec3>& normals, double target) {
    int best = 1;
    double best_err = 1e300;
    for (int g = 1; g <= 8; ++g) {
        FragmentSet s = build_fragments(m, normals, g);
        double avg = double(s.kept_triangles) / double(std::max<size_t>(1, s.fragments.size()));
        double err = std::fabs(std::log(avg / target));
        if (err < best_err) {
            best_err = err;
            best = g;
        }
    }
    return best;
}


// ---- Draco -----------------------------------------------------------------------------------

// Positions and normals, and with `colors` the synthetic colours our fragments carry.
void write_ply_positions_normals(const std::string& path, const InputMesh& m, const std::vector<Vec3>& normals,
                                 bool colors = false) {
    std::ofstream out(path, std::ios::binary);
    out << "ply\nformat binary_little_endian 1.0\nelement vertex " << m.positions.size()
        << "\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\n"
           "property float nz\n"
        << (colors ? "property uchar red\nproperty uchar green\nproperty uchar blue\n" : "") << "element face "
        << m.indices.size() / 3 << "\nproperty list uchar int vertex_indices\nend_header\n";
    const Bounds3 world = bounds_of(m);
    for (size_t v = 0; v < m.positions.size(); ++v) {
        float f[6] = {float(m.positions[v][0]), float(m.positions[v][1]), float(m.positions[v][2]),
                      float(normals[v][0]),      float(normals[v][1]),      float(normals[v][2])};
        out.write(reinterpret_cast<const char*>(f), sizeof f);
        if (colors) {
            const std::array<uint8_t, 3> rgb = synthetic_color(m.positions[v], world);
            out.write(reinterpret_cast<const char*>(rgb.data()), 3);
        }
    }
    for (size_t t = 0; t < m.indices.size(); t += 3) {
        uint8_t n = 3;
        int32_t idx[3] = {int32_t(m.indices[t]), int32_t(m.indices[t + 1]), int32_t(m.indices[t + 2])};
        out.write(reinterpret_cast<const char*>(&n), 1);
        out.write(reinterpret_cast<const char*>(idx), sizeof idx);
    }
    if (!out) fail("cannot write %s", path.c_str());
}

long file_size(const std::string& path) {
    struct stat s;
    return stat(path.c_str(), &s) == 0 ? long(s.st_size) : -1;
}

// Parses "... (N ms to decode)" from draco_decoder's output; negative if absent.
double parse_draco_ms(const std::string& out) {
    size_t at = out.find(" ms to decode");
    if (at == std::string::npos) return -1;
    size_t open = out.rfind('(', at);
    if (open == std::string::npos) return -1;
    return std::atof(out.c_str() + open + 1);
}

}  // namespace

int main(int argc, char** argv) try {
    std::string input;
    int grid = 0, profile_loops = 0;
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        if (a == "--grid" && i + 1 < argc)
            grid = std::atoi(argv[++i]);
        else if (a == "--profile-decode" && i + 1 < argc)
            profile_loops = std::atoi(argv[++i]);
        else if (a == "-h" || a == "--help") {
            std::printf("usage: codec_bench [mesh file] [--grid N] [--profile-decode LOOPS]\n"
                        "  --profile-decode: only decode our fragments LOOPS times (for a profiler)\n");
            return 0;
        } else
            input = a;
    }
    char temp_template[] = "/tmp/codec_bench.XXXXXX";
    const char* temp_dir = mkdtemp(temp_template);
    if (!temp_dir) fail("cannot create a temporary directory");
    if (input.empty()) input = default_input(temp_dir);

    InputMesh mesh = load_input(input);
    std::vector<Vec3> normals = area_weighted_normals(mesh);
    const size_t input_vertices = mesh.positions.size(), input_triangles = mesh.indices.size() / 3;
    std::printf("input: %s: %zu vertices, %zu triangles\n", input.c_str(), input_vertices, input_triangles);

    if (grid <= 0) grid = choose_grid(mesh, normals, 2000.0);
    FragmentSet set = build_fragments(mesh, normals, grid);
    std::vector<size_t> sizes;
    size_t total_v = 0, total_t = 0;
    for (const Fragment& f : set.fragments) {
        sizes.push_back(f.mesh.triangle_count());
        total_v += f.mesh.vertices.size();
        total_t += f.mesh.triangle_count();
    }
    std::sort(sizes.begin(), sizes.end());
    std::printf("fragments: %d^3 cells x 6 Kuhn tetrahedra, cell = %d lattice units; %zu non-empty fragments, "
                "triangles per fragment min %zu / median %zu / max %zu\n",
                grid, set.cell, set.fragments.size(), sizes.empty() ? 0 : sizes.front(),
                sizes.empty() ? 0 : sizes[sizes.size() / 2], sizes.empty() ? 0 : sizes.back());
    std::printf("dropped %zu of %zu triangles (%.1f%%) that cross a tetrahedron boundary; encoded %zu triangles, "
                "%zu vertices (vertices of kept triangles, per fragment)\n",
                set.dropped_triangles, input_triangles, 100.0 * double(set.dropped_triangles) / double(input_triangles),
                total_t, total_v);
    const Bounds3 bounds = bounds_of(mesh);
    const double step = double(set.cell) / kBaryGrid / set.lattice_per_unit;  // mesh units
    const double precision_bits = std::log2(bounds.diagonal() / step);
    const double axis_bits = std::log2(bounds.extent() / step);
    std::printf("position step %.3g (mesh units): equivalent precision %.2f bits over the bbox diagonal, %.2f bits "
                "over the largest extent\n\n",
                step, precision_bits, axis_bits);

    // ---- ours ----
    std::vector<std::vector<uint8_t>> encoded(set.fragments.size());
    FragmentEncodeStats sum;
    size_t total_bytes = 0;
    for (size_t i = 0; i < set.fragments.size(); ++i) {
        FragmentEncodeStats s;
        fragment_encode(set.fragments[i].mesh, encoded[i], &s);
        sum.header_bytes += s.header_bytes;
        sum.connectivity_bytes += s.connectivity_bytes;
        sum.position_bytes += s.position_bytes;
        sum.normal_bytes += s.normal_bytes;
        sum.color_bytes += s.color_bytes;
        total_bytes += encoded[i].size();
    }
    // Verify before timing.
    FragmentMesh out;
    for (size_t i = 0; i < set.fragments.size(); ++i) {
        FragmentStatus st = fragment_decode(encoded[i].data(), encoded[i].size(), out);
        if (st != FragmentStatus::Ok) fail("fragment %zu: decode failed: %s", i, fragment_status_name(st));
        if (out.vertices.size() != set.fragments[i].mesh.vertices.size() ||
            out.indices.size() != set.fragments[i].mesh.indices.size())
            fail("fragment %zu: decoded counts differ", i);
    }
    if (profile_loops > 0) {
        for (int r = 0; r < profile_loops; ++r)
            for (const auto& e : encoded)
                if (fragment_decode(e.data(), e.size(), out) != FragmentStatus::Ok) std::abort();
        run_command(std::string("rm -rf ") + temp_dir);
        return 0;
    }
    // The same fragments without colour (the layout a colourless input gets, Position48, on the
    // same grid and weights): what Draco's colourless file is compared with. (Until this, the
    // decode time of the coloured fragments stood beside Draco decoding no colour.)
    std::vector<std::vector<uint8_t>> encoded_plain(set.fragments.size());
    size_t plain_bytes = 0;
    {
        const VertexLayout coloured{VertexLayoutKind::Rgb24, kBaryGrid}, plain{VertexLayoutKind::Position48, kBaryGrid};
        const uint8_t no_color[3] = {0, 0, 0};
        for (size_t i = 0; i < set.fragments.size(); ++i) {
            FragmentMesh m = set.fragments[i].mesh;
            m.layout = plain;
            for (PackedVertex& v : m.vertices) {
                BaryWeights w;
                if (!vertex_weights(v, coloured, w)) fail("fragment %zu: a vertex outside the grid", i);
                v = pack_vertex(plain, w, v.normal(), no_color);
            }
            fragment_encode(m, encoded_plain[i]);
            plain_bytes += encoded_plain[i].size();
            FragmentMesh back;
            if (fragment_decode(encoded_plain[i].data(), encoded_plain[i].size(), back) != FragmentStatus::Ok ||
                back.vertices.size() != m.vertices.size() || back.indices.size() != m.indices.size())
                fail("fragment %zu: the colourless copy does not decode", i);
        }
    }
    const int kRuns = 20;
    std::vector<uint8_t> scratch;
    double enc_s = best_of(kRuns, [&] {
        for (const Fragment& f : set.fragments) {
            scratch.clear();
            fragment_encode(f.mesh, scratch);
        }
    });
    double dec_s = best_of(kRuns, [&] {
        for (const auto& e : encoded)
            if (fragment_decode(e.data(), e.size(), out) != FragmentStatus::Ok) std::abort();
    });
    double dec_plain_s = best_of(kRuns, [&] {
        for (const auto& e : encoded_plain)
            if (fragment_decode(e.data(), e.size(), out) != FragmentStatus::Ok) std::abort();
    });
    const double bpv = 8.0 / double(total_v);
    const size_t no_color = total_bytes - sum.color_bytes;
    const double raw_mb = double(8 * total_v + 12 * total_t) / 1e6;
    std::printf("catpaq fragment codec (%zu fragments):\n", set.fragments.size());
    std::printf("  connectivity  %6.2f bits/vertex  (%.2f bits/triangle)\n", double(sum.connectivity_bytes) * bpv,
                double(sum.connectivity_bytes) * 8.0 / double(total_t));
    std::printf("  position      %6.2f bits/vertex\n", double(sum.position_bytes) * bpv);
    std::printf("  normal        %6.2f bits/vertex\n", double(sum.normal_bytes) * bpv);
    std::printf("  header        %6.2f bits/vertex  (%zu bytes per fragment incl. 24-byte header)\n",
                double(sum.header_bytes) * bpv, sum.header_bytes / std::max<size_t>(1, set.fragments.size()));
    std::printf("  TOTAL         %6.2f bits/vertex  connectivity + position + normal + header (target <= 32)\n",
                double(no_color) * bpv);
    std::printf("  colour        %6.2f bits/vertex  on top (synthetic smooth field) -> %.2f bits/vertex with colour\n",
                double(sum.color_bytes) * bpv, double(total_bytes) * bpv);
    std::printf("  encode: %.2f ms = %.1f Mtri/s\n", enc_s * 1e3, double(total_t) / enc_s / 1e6);
    std::printf("  decode: %.2f ms = %.1f Mtri/s, %.0f MB/s of decoded 8-byte vertices + 4-byte indices\n",
                dec_s * 1e3, double(total_t) / dec_s / 1e6, raw_mb / dec_s);
    std::printf("  without colour (Position48 layout, same weights and normals): %.2f bits/vertex, decode %.2f ms = "
                "%.1f Mtri/s\n\n",
                double(plain_bytes) * bpv, dec_plain_s * 1e3, double(total_t) / dec_plain_s / 1e6);

    // ---- comparison table ----
    // Each peer against ours with the same attributes: meshoptimizer's vertices and Draco's
    // coloured files carry colour, Draco's other files do not.
    const double our_tri_s = double(total_t) / dec_s, our_plain_tri_s = double(total_t) / dec_plain_s;
    std::printf("Side by side (decode speed per triangle; ours and meshoptimizer on the %zu fragments, Draco on the "
                "whole mesh; 'ours faster' against ours with the same attributes):\n",
                set.fragments.size());
    std::printf("  %-52s %11s %10s %9s %12s\n", "", "bits/vertex", "decode ms", "Mtri/s", "ours faster");
    std::printf("  %-52s %11.2f %10.2f %9.1f %12s\n", "catpaq: connectivity + position + normal",
                double(plain_bytes) * bpv, dec_plain_s * 1e3, our_plain_tri_s / 1e6, "-");
    std::printf("  %-52s %11.2f %10.2f %9.1f %12s\n", "catpaq: with colour", double(total_bytes) * bpv, dec_s * 1e3,
                our_tri_s / 1e6, "-");

    // meshoptimizer 0.18: vertex cache + fetch optimisation, then its index and vertex codecs on the
    // same 8-byte vertices (so its size includes colour).
    {
        size_t mo_bytes = 0;
        std::vector<std::vector<uint8_t>> ib(set.fragments.size()), vb(set.fragments.size());
        std::vector<size_t> counts_v, counts_i;
        for (size_t i = 0; i < set.fragments.size(); ++i) {
            const FragmentMesh& f = set.fragments[i].mesh;
            std::vector<uint32_t> idx(f.indices.size());
            meshopt_optimizeVertexCache(idx.data(), f.indices.data(), f.indices.size(), f.vertices.size());
            std::vector<PackedVertex> verts(f.vertices.size());
            size_t used = meshopt_optimizeVertexFetch(verts.data(), idx.data(), idx.size(), f.vertices.data(),
                                                      f.vertices.size(), sizeof(PackedVertex));
            verts.resize(used);
            ib[i].resize(meshopt_encodeIndexBufferBound(idx.size(), used));
            ib[i].resize(meshopt_encodeIndexBuffer(ib[i].data(), ib[i].size(), idx.data(), idx.size()));
            vb[i].resize(meshopt_encodeVertexBufferBound(used, sizeof(PackedVertex)));
            vb[i].resize(meshopt_encodeVertexBuffer(vb[i].data(), vb[i].size(), verts.data(), used, sizeof(PackedVertex)));
            mo_bytes += ib[i].size() + vb[i].size();
            counts_v.push_back(used);
            counts_i.push_back(idx.size());
        }
        std::vector<uint32_t> di;
        std::vector<PackedVertex> dv;
        double mo_s = best_of(kRuns, [&] {
            for (size_t i = 0; i < ib.size(); ++i) {
                di.resize(counts_i[i]);
                dv.resize(counts_v[i]);
                if (meshopt_decodeIndexBuffer(di.data(), di.size(), 4, ib[i].data(), ib[i].size()) != 0 ||
                    meshopt_decodeVertexBuffer(dv.data(), dv.size(), sizeof(PackedVertex), vb[i].data(),
                                               vb[i].size()) != 0)
                    std::abort();
            }
        });
        const double mo_tri_s = double(total_t) / mo_s;
        std::printf("  %-52s %11.2f %10.2f %9.1f %11.2fx\n", "meshoptimizer 0.18 codecs (incl. colour)",
                    double(mo_bytes) * bpv, mo_s * 1e3, mo_tri_s / 1e6, our_tri_s / mo_tri_s);
    }

    // Draco 1.5 command-line tools on the whole mesh: positions and area-weighted normals, then
    // with the synthetic colours too (-qg 8), each against ours with the same attributes.
    if (run_command("command -v draco_encoder && command -v draco_decoder").find("draco_decoder") ==
        std::string::npos) {
        std::printf("  Draco: draco_encoder/draco_decoder not found, skipped\n");
    } else {
        std::vector<int> qps = {11, 12, 14};
        const int match = int(std::lround(axis_bits));
        if (std::find(qps.begin(), qps.end(), match) == qps.end()) qps.insert(qps.begin(), match);
        std::sort(qps.begin(), qps.end());
        for (bool colors : {false, true}) {
            std::string ply = std::string(temp_dir) + (colors ? "/in_rgb.ply" : "/in.ply");
            write_ply_positions_normals(ply, mesh, normals, colors);
            for (int qp : qps) {
                std::string drc = std::string(temp_dir) + "/out" + std::to_string(qp) + ".drc";
                std::string log = run_command("draco_encoder -i " + ply + " -o " + drc + " -qp " + std::to_string(qp) +
                                              " -qn 8" + (colors ? " -qg 8" : "") + " -cl 7");
                long size = file_size(drc);
                if (size <= 0) {
                    std::printf("  draco qp %d: draco_encoder failed: %s\n", qp, log.c_str());
                    continue;
                }
                double best_ms = 1e300;
                for (int r = 0; r < 5; ++r) {
                    double ms = parse_draco_ms(
                        run_command("draco_decoder -i " + drc + " -o " + std::string(temp_dir) + "/x.ply"));
                    if (ms > 0) best_ms = std::min(best_ms, ms);
                }
                if (best_ms > 1e299) {
                    std::printf("  draco qp %d: could not parse draco_decoder's timing\n", qp);
                    continue;
                }
                const double tri_s = double(input_triangles) / (best_ms / 1e3);
                char label[96];
                std::snprintf(label, sizeof label, "draco -qp %d -qn 8%s -cl 7%s", qp, colors ? " -qg 8" : "",
                              qp == match ? " (matching precision)" : "");
                std::printf("  %-52s %11.2f %10.2f %9.1f %11.1fx\n", label, double(size) * 8.0 / double(input_vertices),
                            best_ms, tri_s / 1e6, (colors ? our_tri_s : our_plain_tri_s) / tri_s);
            }
        }
        std::printf("  (Draco: %zu vertices / %zu triangles; its 'ms to decode', best of 5 runs, has millisecond "
                    "resolution)\n",
                    input_vertices, input_triangles);
    }
    run_command(std::string("rm -rf ") + temp_dir);
    return 0;
} catch (const std::exception& e) {
    std::fprintf(stderr, "codec_bench: %s\n", e.what());
    return 1;
}
