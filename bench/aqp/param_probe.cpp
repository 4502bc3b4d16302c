#include <chrono>
#include <cstdio>
#include <string>
#include "aqp/build.h"
#include "aqp/dataset.h"
#include "aqp/verify.h"
#include "base/error.h"
#include "mesh/generators.h"
#include "mesh/io.h"
using namespace catpaq;
using namespace catpaq::aqp;
int main(int argc, char** argv) {
    std::string what = argc > 1 ? argv[1] : "sphere";
    size_t n = argc > 2 ? std::stoul(argv[2]) : 20000;
    AqpBuildOptions o;
    o.domain_triangles = argc > 3 ? std::stoul(argv[3]) : 0;
    o.patch_level = argc > 4 ? std::stoi(argv[4]) : -1;
    o.progress = false;
    if (getenv("SWEEPS")) o.smoothing_sweeps = atoi(getenv("SWEEPS"));
    if (getenv("PREC")) o.precision.mean_edges = atof(getenv("PREC"));
    Mesh m = what == "sphere" ? make_sphere(n) : what == "torus" ? make_torus(n) : what == "scan" ? make_scan_like(n)
           : what == "bunny" ? read_mesh(std::string(CATPAQ_SOURCE_DIR) + "/data/bunny.ply") : read_mesh(what);
    try {
        AqpBuildReport r;
        build_aqp_dataset(m, "/tmp/aqp_probe.cpq", o, &r);
        printf("patches %zu k %d samples %zu step %g bytes %llu bits/sample %.2f misses %zu peak %llu MiB\n", r.patches, r.patch_level, r.samples, r.step, (unsigned long long)r.file_bytes, r.bits_per_sample, r.location_misses, (unsigned long long)(r.peak_rss >> 20));
        printf("times: total %.2f clean %.2f param %.2f resample %.2f errors %.2f encode %.2f\n", r.seconds, r.seconds_clean, r.seconds_parameterize, r.seconds_resample, r.seconds_errors, r.seconds_encode);
        printf("param: %s\n", r.domain.check.describe().c_str());
        printf("domain: %zu tris, simplify %.2f s smooth %.2f s, collapses %zu rejected %zu\n", r.domain.base_triangles, r.domain.seconds_simplify, r.domain.seconds_smooth, r.domain.collapses, r.domain.rejected_collapses);
        for (auto& l : r.levels) printf("  level %d: bytes %llu max err %.3g (%.2e diag) mean %.3g\n", l.level, (unsigned long long)l.bytes, l.max_error, l.max_error / r.diagonal, l.mean_error);
        for (auto& w : r.warnings) printf("warning: %s\n", w.c_str());
        AqpDataset d("/tmp/aqp_probe.cpq");
        AqpVerifyReport v = verify_aqp(d);
        printf("verify: ok %d nodes %zu shared %zu nest %zu mono %zu ext %zu\n", v.ok(), v.nodes, v.shared_sample_mismatches, v.nesting_mismatches, v.monotonicity_violations, v.extent_violations);
        for (auto& p : v.problems) printf("  %s\n", p.c_str());
        for (int l = 0; l <= d.finest_level(); ++l) {
            Mesh lm = aqp_level_mesh(d, l);
            printf("  level %d mesh: %zu verts %zu tris border %zu\n", l, lm.vertex_count(), lm.triangle_count(), count_border_edges(lm.indices));
        }
    } catch (const Error& e) { printf("refused: %s\n", e.what()); return 1; }
}
