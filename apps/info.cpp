// catpaq info MESH|DATASET: what a user wants to know before converting a mesh, or about a
// dataset (a local .cpq or a URL, read from its prefix only: header, metadata, index).
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>

#include "apps/commands.h"
#include "base/error.h"
#include "base/options.h"
#include "catp/dataset.h"
#include "client/fetcher.h"
#include "common_codec/archive.h"
#include "mesh/io.h"
#include "mesh/mesh.h"

namespace catpaq {

static const char* kInfoUsage =
    "usage: catpaq info MESH|DATASET\n"
    "  For a mesh (PLY, OBJ, OFF, STL): counts, bounds, attributes and border edges.\n"
    "  For a dataset (a .cpq file, a server URL http://HOST:PORT/api/datasets/NAME, or the URL of a\n"
    "  .cpq on a static server): its size, levels, input, bounds and stored error per level, read\n"
    "  from the prefix alone (one request).\n";

// A URL, or a local file that starts with the dataset container's magic.
static bool is_dataset(const std::string& location) {
    if (location.rfind("http://", 0) == 0 || location.rfind("https://", 0) == 0) return true;
    std::ifstream in(location, std::ios::binary);
    char magic[sizeof kArchiveMagic] = {};
    in.read(magic, sizeof magic);
    return in.gcount() == sizeof magic && std::memcmp(magic, kArchiveMagic, sizeof magic) == 0;
}

static void dataset_info(const std::string& location) {
    std::unique_ptr<NodeSource> source = open_node_source(location);
    CatpIndex index = load_catp_index(*source);
    const ArchiveHeader& h = index.header();
    const CatpMeta& m = index.meta();
    struct Level {
        size_t diamonds = 0;
        uint64_t triangles = 0, bytes = 0;
        double error = 0;
    };
    std::vector<Level> levels;
    for (const ArchiveEntry& e : index.entries()) {
        if (e.level >= levels.size()) levels.resize(size_t(e.level) + 1);
        Level& l = levels[e.level];
        l.diamonds++;
        l.triangles += e.count;
        l.bytes += e.size;
        l.error = std::max(l.error, double(e.error));
    }
    double d2 = 0;
    for (int i = 0; i < 3; ++i) d2 += (m.bounds_max[i] - m.bounds_min[i]) * (m.bounds_max[i] - m.bounds_min[i]);
    std::printf("dataset:   %s\n", location.c_str());
    std::printf("format:    %s (container version %u)\n", archive_kind_name(h.kind), unsigned(h.version));
    std::printf("size:      %llu bytes, of which %llu of header, metadata and index\n", (unsigned long long)h.file_size,
                (unsigned long long)(h.index_offset + h.index_size));
    std::printf("nodes:     %u diamonds in %zu levels (leaf level %u)\n", unsigned(h.node_count), levels.size(),
                unsigned(m.leaf_level));
    std::printf("input:     %llu vertices, %llu triangles; colours %s, normals %s\n",
                (unsigned long long)m.input_vertices, (unsigned long long)m.input_triangles,
                (m.flags & 1) ? "from the input" : "none (one default colour)",
                (m.flags & 2) ? "from the input" : "computed");
    std::printf("bounds:    [%.9g %.9g %.9g] - [%.9g %.9g %.9g]\n", m.bounds_min[0], m.bounds_min[1], m.bounds_min[2],
                m.bounds_max[0], m.bounds_max[1], m.bounds_max[2]);
    std::printf("diagonal:  %.9g\n", std::sqrt(d2));
    std::printf("vertices:  %s layout, grid %d\n", m.layout.name(), m.layout.grid);
    if (m.precision > 0) {
        std::printf("precision: %.6g", m.precision);
        if (m.mean_edge > 0) std::printf(" (%.3g mean input edges of %.6g)", m.precision / m.mean_edge, m.mean_edge);
        std::printf("\n");
    }
    std::printf("up axis:   %s\n", m.up == UpAxis::Unknown ? "not recorded (z assumed)" : up_axis_name(m.up));
    std::printf("%6s %9s %11s %12s %12s\n", "level", "diamonds", "triangles", "bytes", "max error");
    for (size_t l = 0; l < levels.size(); ++l)
        if (levels[l].diamonds)
            std::printf("%6zu %9zu %11llu %12llu %12.4g\n", l, levels[l].diamonds,
                        (unsigned long long)levels[l].triangles, (unsigned long long)levels[l].bytes, levels[l].error);
    std::printf("errors are stored bounds in model units (catpaq verify --mesh measures them)\n");
}

static void mesh_info(const std::string& path) {
    std::vector<std::string> dropped;
    Mesh mesh = read_mesh(path, &dropped);
    Bounds b = mesh.bounds();
    std::printf("file:      %s\n", path.c_str());
    std::printf("vertices:  %zu\n", mesh.vertex_count());
    std::printf("triangles: %zu\n", mesh.triangle_count());
    std::printf("normals:   %s\n", mesh.has_normals() ? "yes" : "no");
    std::printf("colors:    %s\n", mesh.has_colors() ? "yes" : "no");
    std::printf("bounds:    [%.9g %.9g %.9g] - [%.9g %.9g %.9g]\n", b.min[0], b.min[1], b.min[2], b.max[0], b.max[1],
                b.max[2]);
    std::printf("diagonal:  %.9g\n", b.diagonal());
    std::printf("border edges: %zu\n", count_border_edges(mesh.indices));
    for (const std::string& d : dropped) std::printf("left out:  %s\n", d.c_str());
}

int cmd_info(int argc, char** argv) {
    Options options(argc, argv, kInfoUsage);
    if (options.help()) {
        std::printf("%s", kInfoUsage);
        return 0;
    }
    options.finish();
    if (options.positional().size() != 1) usage_error("expected one mesh or dataset");
    const std::string& location = options.positional()[0];
    if (is_dataset(location)) dataset_info(location);
    else mesh_info(location);
    return 0;
}

}  // namespace catpaq
