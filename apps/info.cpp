// catpaq info MESH: reads a mesh and prints what a user wants to know before converting it.
#include <cstdio>

#include "apps/commands.h"
#include "base/options.h"
#include "mesh/io.h"
#include "mesh/mesh.h"

namespace catpaq {

int cmd_info(int argc, char** argv) {
    Options options(argc, argv, "usage: catpaq info MESH\n  Prints counts, bounds and attributes of a mesh file.\n");
    if (options.help()) {
        std::printf("%s", options.usage().c_str());
        return 0;
    }
    options.finish();
    if (options.positional().size() != 1) {
        std::fprintf(stderr, "%s", options.usage().c_str());
        return 2;
    }
    const std::string& path = options.positional()[0];
    Mesh mesh = read_mesh(path);
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
    return 0;
}

}  // namespace catpaq
