// catpaq info MESH|DATASET: what a user wants to know before converting a mesh, or about a
// dataset (a local .cpq or a URL, read from its prefix only: header, metadata, index).
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>

#include "apps/commands.h"
#include "base/error.h"
#include "base/options.h"
#include "client/builtin_formats.h"
#include "client/fetcher.h"
#include "common_codec/archive.h"
#include "mesh/io.h"
#include "mesh/mesh.h"

namespace catpaq {

static const char* kInfoUsage =
    "usage: catpaq info MESH|DATASET\n"
    "  For a mesh (PLY, OBJ, OFF, STL): counts, bounds, attributes and border edges.\n"
    "  For a dataset (a .cpq file, a server URL http://HOST:PORT/api/datasets/NAME, or the URL of a\n"
    "  .cpq on a static server): its size, levels, stored error per level and what its format\n"
    "  records (CATP: input, bounds, vertex layout, precision, up axis), read from the prefix alone\n"
    "  (one request).\n";

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
    DatasetPrefix prefix = load_prefix(*source);
    const ArchiveHeader& h = prefix.header;
    // What the dataset's format says; a format this build cannot stream still gets the
    // container's facts.
    FormatSummary summary;
    const FormatModule* module = builtin_formats().find(h.kind);
    if (module) summary = module->open(prefix)->summary();
    struct Level {
        size_t nodes = 0;
        uint64_t primitives = 0, bytes = 0;
        double error = 0;
    };
    std::vector<Level> levels;
    for (const ArchiveEntry& e : prefix.entries) {
        if (e.level >= levels.size()) levels.resize(size_t(e.level) + 1);
        Level& l = levels[e.level];
        l.nodes++;
        l.primitives += e.count;
        l.bytes += e.size;
        l.error = std::max(l.error, double(e.error));
    }
    std::printf("dataset:   %s\n", location.c_str());
    std::printf("format:    %s (container version %u)\n", archive_kind_name(h.kind), unsigned(h.version));
    std::printf("size:      %llu bytes, of which %llu of header, metadata and index\n", (unsigned long long)h.file_size,
                (unsigned long long)(h.index_offset + h.index_size));
    const FirstFrame first = archive_first_frame(h, prefix.entries);
    std::printf("first frame: %llu bytes (the prefix, and level 0: %llu)\n", (unsigned long long)first.bytes(),
                (unsigned long long)first.level0_bytes);
    std::printf("nodes:     %u %s in %zu levels%s\n", unsigned(h.node_count), summary.node_noun.c_str(), levels.size(),
                summary.levels_note.empty() ? "" : (" (" + summary.levels_note + ")").c_str());
    if (!module) std::printf("client:    none in this build for %s datasets\n", archive_kind_name(h.kind));
    for (const auto& [label, text] : summary.lines) std::printf("%-11s%s\n", (label + ":").c_str(), text.c_str());
    std::printf("%6s %9s %11s %12s %12s\n", "level", summary.node_noun.c_str(), summary.primitive_noun.c_str(), "bytes",
                "max error");
    for (size_t l = 0; l < levels.size(); ++l)
        if (levels[l].nodes)
            std::printf("%6zu %9zu %11llu %12llu %12.4g\n", l, levels[l].nodes, (unsigned long long)levels[l].primitives,
                        (unsigned long long)levels[l].bytes, levels[l].error);
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
