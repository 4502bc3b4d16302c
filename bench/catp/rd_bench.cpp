// rd_bench: rate against distortion and decode speed of the peers on one mesh, measured with the
// same distance code as `catpaq verify --mesh` (catp/distance.h: the same surface samples of the
// original, the same CGAL distance), so the rows compare with verify's per-level rows of a CATP
// dataset of the same mesh.
//
//   Draco (draco_encoder / draco_decoder, Debian `draco`): positions, normals and colours at
//   several -qp, normals at -qn 8 (like our 8+8-bit octahedral normals), colours at -qg 8.
//   meshoptimizer 0.18 (meshopt_encodeIndexBuffer / meshopt_encodeVertexBuffer after its vertex
//   cache and fetch optimisations): positions quantised to B bits on the same grid as Draco's
//   (the largest bounding-box extent in 2^B - 1 steps), a 16-bit octahedral normal and RGB; its
//   error is the quantisation error.
//   catpaq (--cpq): decode time of every node of the dataset (the fragment codec on real CATP
//   data), best of 3.
//
// usage: rd_bench MESH [--cpq DATASET] [--qp 8,10,12,14] [--bits 8,10,12,14,16] [--samples N]
// Output: one line per encoding
//   rd|CODEC|SETTING|BYTES|VERTICES|TRIANGLES|BITS_PER_VERTEX|DECODE_MS|DECODED_MTRI_S|
//      ENC->ORIG_MAX|ORIG->ENC_MAX|ENC->ORIG_RMS|ORIG->ENC_RMS
// distances relative to the bounding-box diagonal (-1 where not measured). With --cpq, also one
// line per level of the dataset: where its bytes go, each fragment re-encoded for the codec's
// per-stream sizes (the encoder is deterministic: the same bytes as stored)
//   bytes|LEVEL|NODES|FRAGMENTS|VERTICES|TRIANGLES|NODE_BYTES|OVERHEAD|CONNECTIVITY|POSITION|
//      NORMAL|COLOUR|FACE_VERTICES
// OVERHEAD: fragment headers and the node's framing (slot mask, sizes); FACE_VERTICES: stored
// vertices on a face, edge or corner of their tetrahedron (the ones neighbours share).
// Exit status 1 if a tool fails (Draco missing included: the comparison is the point).
#include <meshoptimizer.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "base/error.h"
#include "base/sysinfo.h"
#include "catp/dataset.h"
#include "catp/distance.h"
#include "common_codec/fragment_codec.h"
#include "common_codec/octahedral.h"
#include "mesh/io.h"

using namespace catpaq;
namespace fs = std::filesystem;

namespace {

using Point = std::array<double, 3>;


std::vector<int> parse_list(const std::string& text, int lo, int hi, const char* what) {
    std::vector<int> out;
    std::stringstream in(text);
    std::string item;
    while (std::getline(in, item, ',')) {
        char* end = nullptr;
        long v = std::strtol(item.c_str(), &end, 10);
        if (item.empty() || *end || v < lo || v > hi) fail("%s: '%s' is not a list of integers in %d..%d", what, text.c_str(), lo, hi);
        out.push_back(int(v));
    }
    return out;
}

// Runs a shell command, returns its output (stdout and stderr) and sets `status`.
std::string run(const std::string& cmd, int& status) {
    std::string out;
    FILE* p = popen((cmd + " 2>&1").c_str(), "r");
    if (!p) fail("cannot run %s", cmd.c_str());
    char buf[4096];
    size_t n;
    while ((n = fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
    status = pclose(p);
    return out;
}

// "... (N ms to decode)" in draco_decoder's output; negative if absent.
double parse_draco_ms(const std::string& out) {
    size_t at = out.find(" ms to decode");
    if (at == std::string::npos) return -1;
    size_t open = out.rfind('(', at);
    return open == std::string::npos ? -1 : std::atof(out.c_str() + open + 1);
}

// The original, its distance structure and its surface samples, shared by every measurement.
struct Reference {
    Mesh mesh;
    std::vector<Point> positions;
    std::unique_ptr<SurfaceDistance> surface;
    std::vector<Point> samples;
    double diagonal = 0;
    size_t sample_count = 0;
};

struct Distances {
    double to_max = -1, from_max = -1, to_rms = -1, from_rms = -1;  // relative to the diagonal
};

// Both directions, as verify measures a level: samples of the encoded surface to the original,
// and the original's samples to the encoded surface.
Distances measure(const Reference& ref, const std::vector<Point>& positions, const std::vector<uint32_t>& indices) {
    Distances d;
    DistanceStats to = measure_distances(*ref.surface, sample_surface(positions, indices, ref.sample_count));
    SurfaceDistance encoded(positions, indices);
    DistanceStats from = measure_distances(encoded, ref.samples);
    d.to_max = to.max / ref.diagonal;
    d.to_rms = to.rms / ref.diagonal;
    d.from_max = from.max / ref.diagonal;
    d.from_rms = from.rms / ref.diagonal;
    return d;
}

void print_row(const char* codec, const std::string& setting, uint64_t bytes, size_t vertices, size_t triangles,
               double decode_s, const Distances& d) {
    std::printf("rd|%s|%s|%llu|%zu|%zu|%.3f|%.3f|%.2f|%.4g|%.4g|%.4g|%.4g\n", codec, setting.c_str(),
                (unsigned long long)bytes, vertices, triangles, 8.0 * double(bytes) / double(vertices), decode_s * 1e3,
                double(triangles) / decode_s / 1e6, d.to_max, d.from_max, d.to_rms, d.from_rms);
    std::fflush(stdout);
}

// Largest bounding-box extent and its minimum corner: the quantisation grid of Draco's -qp.
void quantization_grid(const Mesh& m, Point& lo, double& extent) {
    Bounds b = m.bounds();
    extent = 0;
    for (int i = 0; i < 3; ++i) {
        lo[i] = b.min[i];
        extent = std::max(extent, b.max[i] - b.min[i]);
    }
}

void run_draco(const Reference& ref, const std::vector<int>& qps, const std::string& dir) {
    int status = 0;
    run("command -v draco_encoder && command -v draco_decoder", status);
    if (status != 0) fail("draco_encoder/draco_decoder not found (scripts/setup.sh installs Debian's draco)");
    std::string ply = dir + "/draco_in.ply";
    write_ply(ply, ref.mesh, true);
    for (int qp : qps) {
        std::string drc = dir + "/out.drc", out = dir + "/draco_out.ply";
        std::string cmd = strprintf("draco_encoder -i %s -o %s -qp %d -qn 8 -qg 8 -cl 7", ply.c_str(), drc.c_str(), qp);
        std::string log = run(cmd, status);
        if (status != 0) fail("%s failed: %s", cmd.c_str(), log.c_str());
        uint64_t bytes = fs::file_size(drc);
        double best_ms = 1e300;
        for (int r = 0; r < 3; ++r) {
            log = run("draco_decoder -i " + drc + " -o " + out, status);
            if (status != 0) fail("draco_decoder failed: %s", log.c_str());
            double ms = parse_draco_ms(log);
            if (ms < 0) fail("could not read draco_decoder's timing from: %s", log.c_str());
            best_ms = std::min(best_ms, ms);
        }
        // Draco reports whole milliseconds; below 1 ms say 0.5 rather than divide by zero.
        best_ms = std::max(best_ms, 0.5);
        Mesh decoded = read_mesh(out);
        std::vector<Point> p(decoded.positions.begin(), decoded.positions.end());
        print_row("draco", strprintf("-qp %d", qp), bytes, ref.mesh.vertex_count(), ref.mesh.triangle_count(),
                  best_ms / 1e3, measure(ref, p, decoded.indices));
    }
}

// 12-byte vertex: quantised position (16 bits per axis), octahedral normal, RGB, padding.
struct QuantVertex {
    uint16_t x, y, z, normal;
    uint8_t r, g, b, pad;
};
static_assert(sizeof(QuantVertex) == 12);

void run_meshopt(const Reference& ref, const std::vector<int>& bits_list) {
    const Mesh& m = ref.mesh;
    Point lo;
    double extent;
    quantization_grid(m, lo, extent);
    std::vector<uint32_t> indices(m.indices.size());
    meshopt_optimizeVertexCache(indices.data(), m.indices.data(), m.indices.size(), m.vertex_count());
    for (int bits : bits_list) {
        const double steps = double((1u << bits) - 1);
        std::vector<QuantVertex> verts(m.vertex_count());
        for (size_t v = 0; v < verts.size(); ++v) {
            uint16_t q[3];
            for (int i = 0; i < 3; ++i) q[i] = uint16_t(std::lround((m.positions[v][i] - lo[i]) / extent * steps));
            uint16_t n = m.has_normals() ? oct_encode_precise(m.normals[v][0], m.normals[v][1], m.normals[v][2]) : 0;
            Rgb8 c = m.has_colors() ? m.colors[v] : Rgb8{0, 0, 0};
            verts[v] = QuantVertex{q[0], q[1], q[2], n, c[0], c[1], c[2], 0};
        }
        std::vector<uint32_t> idx = indices;
        std::vector<QuantVertex> fetched(verts.size());
        size_t used = meshopt_optimizeVertexFetch(fetched.data(), idx.data(), idx.size(), verts.data(), verts.size(),
                                                  sizeof(QuantVertex));
        fetched.resize(used);
        std::vector<uint8_t> ib(meshopt_encodeIndexBufferBound(idx.size(), used));
        ib.resize(meshopt_encodeIndexBuffer(ib.data(), ib.size(), idx.data(), idx.size()));
        std::vector<uint8_t> vb(meshopt_encodeVertexBufferBound(used, sizeof(QuantVertex)));
        vb.resize(meshopt_encodeVertexBuffer(vb.data(), vb.size(), fetched.data(), used, sizeof(QuantVertex)));
        std::vector<uint32_t> di(idx.size());
        std::vector<QuantVertex> dv(used);
        double s = best_of(5, [&] {
            if (meshopt_decodeIndexBuffer(di.data(), di.size(), 4, ib.data(), ib.size()) != 0 ||
                meshopt_decodeVertexBuffer(dv.data(), dv.size(), sizeof(QuantVertex), vb.data(), vb.size()) != 0)
                fail("meshoptimizer could not decode its own output");
        });
        // The index codec keeps triangle order but may rotate a triangle's corners.
        for (size_t t = 0; t < idx.size(); t += 3) {
            bool same = false;
            for (int r = 0; r < 3 && !same; ++r)
                same = di[t] == idx[t + r] && di[t + 1] == idx[t + (r + 1) % 3] && di[t + 2] == idx[t + (r + 2) % 3];
            if (!same) fail("meshoptimizer index round trip differs at triangle %zu", t / 3);
        }
        std::vector<Point> p(used);
        for (size_t v = 0; v < used; ++v)
            p[v] = {lo[0] + dv[v].x / steps * extent, lo[1] + dv[v].y / steps * extent, lo[2] + dv[v].z / steps * extent};
        print_row("meshopt", strprintf("%d-bit positions", bits), ib.size() + vb.size(), m.vertex_count(),
                  m.triangle_count(), s, measure(ref, p, di));
    }
}

// Per level: where a dataset's bytes go (the bytes| lines described at the top).
void print_level_bytes(const CatpFile& file) {
    struct Level {
        size_t nodes = 0, fragments = 0, vertices = 0, triangles = 0, face_vertices = 0;
        uint64_t bytes = 0, overhead = 0, connectivity = 0, position = 0, normal = 0, colour = 0;
    };
    std::map<int, Level> levels;
    std::vector<uint8_t> scratch;
    for (const ArchiveEntry& e : file.index().entries()) {
        Level& l = levels[e.level];
        const DiamondFragments d = file.decode(e);
        l.nodes++;
        l.bytes += e.size;
        uint64_t fragment_bytes = 0;
        for (int s = 0; s < 8; ++s) {
            if (!(d.slot_mask & (1 << s))) continue;
            const FragmentMesh& m = d.slots[size_t(s)];
            FragmentEncodeStats st;
            scratch.clear();
            fragment_bytes += fragment_encode(m, scratch, &st);
            l.fragments++;
            l.vertices += m.vertices.size();
            l.triangles += m.triangle_count();
            l.overhead += st.header_bytes;
            l.connectivity += st.connectivity_bytes;
            l.position += st.position_bytes;
            l.normal += st.normal_bytes;
            l.colour += st.color_bytes;
            for (const PackedVertex& v : m.vertices) {
                BaryWeights w;
                if (vertex_weights(v, m.layout, w)) l.face_vertices += w[0] == 0 || w[1] == 0 || w[2] == 0 || w[3] == 0;
            }
        }
        l.overhead += e.size - std::min<uint64_t>(e.size, fragment_bytes);  // slot mask and sizes
    }
    std::printf("# bytes|level|nodes|fragments|vertices|triangles|node bytes|overhead|connectivity|position|normal|"
                "colour|face vertices\n");
    for (const auto& [level, l] : levels)
        std::printf("bytes|%d|%zu|%zu|%zu|%zu|%llu|%llu|%llu|%llu|%llu|%llu|%zu\n", level, l.nodes, l.fragments, l.vertices,
                    l.triangles, (unsigned long long)l.bytes, (unsigned long long)l.overhead,
                    (unsigned long long)l.connectivity, (unsigned long long)l.position, (unsigned long long)l.normal,
                    (unsigned long long)l.colour, l.face_vertices);
}

void run_catpaq(const std::string& path, size_t vertices) {
    CatpFile file(path);
    size_t triangles = 0;
    for (const ArchiveEntry& e : file.index().entries()) triangles += e.count;
    double s = best_of(3, [&] {
        for (const ArchiveEntry& e : file.index().entries()) file.decode(e);
    });
    // Whole-dataset decode: every level, so the triangles are those of all levels together.
    print_row("catpaq", "all nodes", fs::file_size(path), vertices, triangles, s, Distances{});
    print_level_bytes(file);
}

}  // namespace

int main(int argc, char** argv) try {
    std::string mesh_path, cpq, qp_text = "8,10,12,14", bits_text = "8,10,12,14,16";
    size_t samples = 50000;
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        auto value = [&]() -> std::string {
            if (i + 1 >= argc) fail("%s needs a value", a.c_str());
            return argv[++i];
        };
        if (a == "--cpq")
            cpq = value();
        else if (a == "--qp")
            qp_text = value();
        else if (a == "--bits")
            bits_text = value();
        else if (a == "--samples")
            samples = size_t(parse_list(value(), 100, 100000000, "--samples")[0]);
        else if (a == "-h" || a == "--help") {
            std::printf("usage: rd_bench MESH [--cpq DATASET] [--qp 8,10,12,14] [--bits 8,10,12,14,16] [--samples N]\n");
            return 0;
        } else if (a.size() && a[0] == '-')
            fail("unknown option %s (see --help)", a.c_str());
        else if (mesh_path.empty())
            mesh_path = a;
        else
            fail("more than one mesh given");
    }
    if (mesh_path.empty()) fail("no mesh given (see --help)");
    std::vector<int> qps = parse_list(qp_text, 1, 30, "--qp"), bits = parse_list(bits_text, 1, 16, "--bits");

    Reference ref;
    ref.mesh = read_mesh(mesh_path);
    // Like the converter: without normals in the file every codec carries computed ones.
    if (!ref.mesh.has_normals()) ref.mesh.normals = compute_vertex_normals(ref.mesh);
    ref.positions.assign(ref.mesh.positions.begin(), ref.mesh.positions.end());
    Bounds b = ref.mesh.bounds();
    for (int i = 0; i < 3; ++i) ref.diagonal += (b.max[i] - b.min[i]) * (b.max[i] - b.min[i]);
    ref.diagonal = std::sqrt(ref.diagonal);
    if (!(ref.diagonal > 0)) fail("%s: empty bounding box", mesh_path.c_str());
    ref.sample_count = samples;
    ref.surface = std::make_unique<SurfaceDistance>(ref.positions, ref.mesh.indices);
    ref.samples = sample_surface(ref.positions, ref.mesh.indices, samples);
    std::printf("# input: %s: %zu vertices, %zu triangles, bbox diagonal %.6g, %zu samples per direction\n",
                mesh_path.c_str(), ref.mesh.vertex_count(), ref.mesh.triangle_count(), ref.diagonal, samples);
    std::printf("# rd|codec|setting|bytes|vertices|triangles|bits/vertex|decode ms|decoded Mtri/s|"
                "enc->orig max|orig->enc max|enc->orig rms|orig->enc rms\n");
    fs::path dir = fs::temp_directory_path() / ("catpaq_rd_bench_" + std::to_string(getpid()));
    fs::create_directories(dir);
    struct Cleanup {
        fs::path dir;
        ~Cleanup() { fs::remove_all(dir); }
    } cleanup{dir};
    if (!cpq.empty()) run_catpaq(cpq, ref.mesh.vertex_count());
    run_meshopt(ref, bits);
    run_draco(ref, qps, dir.string());
    return 0;
} catch (const std::exception& e) {
    std::fprintf(stderr, "rd_bench: %s\n", e.what());
    return 1;
}
