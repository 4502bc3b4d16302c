// mesh_make_sample IN OUT.ply: reads any mesh read_mesh understands and writes it as binary PLY
// with freshly computed area-weighted normals. Used to make data/bunny.ply (see data/README.md).
#include <cstdio>

#include "base/error.h"
#include "mesh/io.h"

int main(int argc, char** argv) {
    if (argc != 3) {
        std::fprintf(stderr, "usage: %s INPUT OUTPUT.ply\n", argv[0]);
        return 2;
    }
    try {
        catpaq::Mesh mesh = catpaq::read_mesh(argv[1]);
        mesh.normals = catpaq::compute_vertex_normals(mesh);
        catpaq::write_ply(argv[2], mesh, true);
        std::printf("%s: %zu vertices, %zu triangles, %zu border edges\n", argv[2], mesh.vertex_count(),
                    mesh.triangle_count(), catpaq::count_border_edges(mesh.indices));
    } catch (const catpaq::Error& e) {
        std::fprintf(stderr, "error: %s\n", e.what());
        return 1;
    }
    return 0;
}
