// gen_mesh: writes a generated mesh (mesh/generators.h) as binary PLY, for the report's larger
// datasets: the same arguments give the same bytes on every machine.
//
// usage: gen_mesh scan|uneven|sphere|torus TRIANGLES OUT.ply [--seed S]
//        gen_mesh hard CASE OUT.ply [--seed S]    (a hard case of mesh/generators.h by name)
#include <cstdio>
#include <cstdlib>
#include <string>

#include "base/error.h"
#include "mesh/generators.h"
#include "mesh/io.h"

using namespace catpaq;

int main(int argc, char** argv) try {
    const char* usage = "usage: gen_mesh scan|uneven|sphere|torus TRIANGLES OUT.ply [--seed S]\n"
                        "       gen_mesh hard CASE OUT.ply [--seed S]\n";
    if (argc == 2 && (std::string(argv[1]) == "-h" || std::string(argv[1]) == "--help")) {
        std::printf("%s", usage);
        return 0;
    }
    if (argc != 4 && !(argc == 6 && std::string(argv[4]) == "--seed")) fail("%s", usage);
    std::string kind = argv[1];
    uint64_t seed = argc == 6 ? std::strtoull(argv[5], nullptr, 10) : 1;
    if (kind == "hard") {
        for (HardCase c : kAllHardCases)
            if (argv[2] == std::string(hard_case_name(c))) {
                Mesh mesh = make_hard_case(c, seed);
                write_ply(argv[3], mesh, true);
                std::printf("%s: %zu vertices, %zu triangles\n", argv[3], mesh.vertex_count(), mesh.triangle_count());
                return 0;
            }
        fail("unknown hard case '%s'", argv[2]);
    }
    char* end = nullptr;
    unsigned long long triangles = std::strtoull(argv[2], &end, 10);
    if (*end || triangles < 12 || triangles > 2000000000ull) fail("TRIANGLES: '%s' is not a count in 12..2e9", argv[2]);
    Mesh mesh;
    if (kind == "scan")
        mesh = make_scan_like(triangles, seed);
    else if (kind == "uneven")
        mesh = make_uneven_density(triangles, seed);
    else if (kind == "sphere")
        mesh = make_sphere(triangles, seed);
    else if (kind == "torus")
        mesh = make_torus(triangles, seed);
    else
        fail("unknown mesh kind '%s' (scan, uneven, sphere or torus)", kind.c_str());
    write_ply(argv[3], mesh, true);
    std::printf("%s: %zu vertices, %zu triangles\n", argv[3], mesh.vertex_count(), mesh.triangle_count());
    return 0;
} catch (const std::exception& e) {
    std::fprintf(stderr, "gen_mesh: %s\n", e.what());
    return 1;
}
