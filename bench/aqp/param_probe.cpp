#include <chrono>
#include <cstdio>
#include <string>
#include "aqp/clean.h"
#include "aqp/domain.h"
#include "base/error.h"
#include "mesh/generators.h"
#include "mesh/io.h"
using namespace catpaq;
using namespace catpaq::aqp;
int main(int argc, char** argv) {
    std::string what = argc > 1 ? argv[1] : "sphere";
    size_t n = argc > 2 ? std::stoul(argv[2]) : 20000;
    size_t target = argc > 3 ? std::stoul(argv[3]) : 0;
    int sweeps = argc > 4 ? std::stoi(argv[4]) : 8;
    Mesh m = what == "sphere" ? make_sphere(n) : what == "torus" ? make_torus(n) : what == "scan" ? make_scan_like(n)
           : what == "bunny" ? read_mesh(std::string(CATPAQ_SOURCE_DIR) + "/data/bunny.ply") : read_mesh(what);
    try {
        auto t0 = std::chrono::steady_clock::now();
        CleanReport cr;
        CleanMesh c = clean_to_manifold(m, {}, &cr);
        auto t1 = std::chrono::steady_clock::now();
        printf("clean: %zu -> %zu tris, genus %d, comps %zu, border %zu (%.2fs)\n", cr.input_triangles, cr.triangles, cr.genus, cr.components, cr.border_edges, std::chrono::duration<double>(t1-t0).count());
        for (auto& l : cr.summary()) printf("  %s\n", l.c_str());
        DomainOptions o; o.target_triangles = target; o.smoothing_sweeps = sweeps;
        DomainReport dr;
        Parameterization p;
        try { p = build_parameterization(c.mesh, o, &dr); } catch (const Error& e) { printf("ERROR %s\n", e.what()); return 1; }
        printf("domain: %zu tris %zu verts, collapses %zu rejected %zu, simplify %.2fs smooth %.2fs\n", dr.base_triangles, dr.base_vertices, dr.collapses, dr.rejected_collapses, dr.seconds_simplify, dr.seconds_smooth);
        ParamCheck pc = check_parameterization(c.mesh, p);
        printf("check: %s\n", pc.describe().c_str());
    } catch (const Error& e) { printf("refused: %s\n", e.what()); return 1; }
}
// debug helpers appended
