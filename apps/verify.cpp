// catpaq verify DATASET [--mesh ORIGINAL]: checks a dataset's invariants and measures its error,
// with the verifier of the dataset's format.
#include <algorithm>
#include <cstdio>
#include <fstream>

#include "apps/commands.h"
#include "apps/verify_formats.h"
#include "base/error.h"
#include "base/options.h"
#include "catp/verify.h"
#include "common_codec/archive.h"
#include "mesh/io.h"

namespace catpaq {

static const char* kVerifyUsage =
    "usage: catpaq verify DATASET.cpq [--mesh ORIGINAL] [--samples N]\n"
    "  Runs the checks of the dataset's format. CATP: decodes every node and checks checksums,\n"
    "  slot masks, triangle counts, monotone errors and\n"
    "  that the fragments on both sides of every shared face have identical borders (on each\n"
    "  uniform level cut and a random mixed cut). With --mesh, measures per level the distance\n"
    "  between the level's surface and the original (both directions, largest and root mean\n"
    "  square over surface samples), in model units and relative to the bounding-box diagonal,\n"
    "  fails a level whose measured distance exceeds its stored error bound, and fails border\n"
    "  edges of the cuts that are not on the original's border (cracks, missing geometry).\n"
    "  AQP: decodes every node and checks that shared edges and corners are identical in both\n"
    "  patches at every level, levels nest, bounds are monotone; with --mesh, measures each level\n"
    "  against the original (cleaned as convert cleans it) in both directions and fails a level\n"
    "  beyond its stored bound. Points: decodes every node and checks monotone errors, nested\n"
    "  boxes, splats inside their boxes and that the leaves hold every input point; with --mesh\n"
    "  (the original point file), that every input point is within each depth's bound of a splat.\n"
    "  Exit status 1 if any check fails.\n"
    "options:\n"
    "  --mesh FILE     the original input (a mesh: PLY, OBJ, OFF, STL; for points any point file)\n"
    "  --samples N     surface samples per level and direction (default 50000)\n"
    "  --quiet         no progress display\n";

// CATP: decodes every diamond, checks the invariants and, with the original, measures each
// level's distance to it (catp/verify.h); prints the report.
int verify_catp_dataset(const VerifyJob& job) {
    const std::string& dataset = job.dataset;
    const std::string& mesh_path = job.original;
    VerifySettings settings;
    settings.samples_per_level = job.samples;
    settings.progress = job.progress;
    Mesh original;
    if (!mesh_path.empty()) original = read_mesh(mesh_path);
    VerifyReport r = verify_catp(dataset, mesh_path.empty() ? nullptr : &original, settings);

    std::printf("dataset:  %s: %llu bytes, %zu diamonds, %zu fragments, %zu triangles\n", dataset.c_str(),
                (unsigned long long)r.file_bytes, r.nodes, r.fragments, r.triangles);
    std::printf("checks:   checksums %s, decode %s, flags %s, monotone errors %s, shared faces %s (%zu checked)\n",
                r.checksum_failures ? "FAIL" : "ok", r.corrupt_nodes ? "FAIL" : "ok", r.bad_flags ? "FAIL" : "ok",
                r.monotonicity_violations ? "FAIL" : "ok", r.face_mismatches ? "FAIL" : "ok", r.faces_checked);
    if (r.border_checked)
        std::printf("          stored bounds %s (measured distances within them), borders %s (cut borders on the "
                    "original's border)\n",
                    r.bound_violations ? "FAIL" : "ok", r.border_cracks ? "FAIL" : "ok");
    if (r.face_border_edges)
        std::printf("note:     %zu border edges lie in shared faces with nothing on the other side: the input's own "
                    "border in a lattice plane (open or non-manifold input), or missing geometry; %s\n",
                    r.face_border_edges,
                    r.border_checked ? "the border check above tells them apart"
                                     : "run with --mesh ORIGINAL to check them against the original's border");
    double diag = r.diagonal > 0 ? r.diagonal : 1.0;
    std::printf("errors in model units (and relative to the bounding-box diagonal %.6g):\n", r.diagonal);
    std::printf("%5s %8s %9s %9s %12s %11s %11s %21s %21s %21s %21s\n", "level", "diamonds", "triangles", "vertices",
                "bytes", "stored", "quant.step", "level->original max", "original->level max", "level->original rms",
                "original->level rms");
    auto cell = [diag](char* out, size_t size, double v) {
        if (v < 0)
            std::snprintf(out, size, "-");
        else
            std::snprintf(out, size, "%.3g (%.1e)", v, v / diag);
    };
    for (const VerifyLevel& l : r.levels) {
        if (!l.diamonds) continue;
        char to[64], from[64], to_rms[64], from_rms[64];
        cell(to, sizeof to, l.distance_to_original_max);
        cell(from, sizeof from, l.distance_from_original_max);
        cell(to_rms, sizeof to_rms, l.distance_to_original_rms);
        cell(from_rms, sizeof from_rms, l.distance_from_original_rms);
        // vertices: of the level's uniform cut, welded (what a renderer of that cut would hold).
        std::printf("%5d %8zu %9zu %9zu %12llu %11.3g %11.3g %21s %21s %21s %21s\n", l.level, l.diamonds, l.triangles,
                    l.cut_vertices, (unsigned long long)l.bytes, l.stored_error, l.quantization_step, to, from, to_rms,
                    from_rms);
    }
    std::printf("vertices: %s layout, grid %d\n", r.layout.name(), r.layout.grid);
    if (r.precision > 0) {
        std::printf("precision: %.4g", r.precision);
        if (r.mean_edge > 0) std::printf(" (%.3g mean input edges of %.4g)", r.precision / r.mean_edge, r.mean_edge);
        const VerifyLevel& finest = r.levels.back();
        if (finest.distance_to_original_max >= 0) {
            const double measured = std::max(finest.distance_to_original_max, finest.distance_from_original_max);
            std::printf("; finest level measured %.4g (%.2f of it): %s", measured, measured / r.precision,
                        r.precision_exceeded ? "EXCEEDED" : "ok");
        }
        std::printf("\n");
    }
    for (const std::string& p : r.problems) std::printf("problem: %s\n", p.c_str());
    std::printf("%s\n", r.ok() ? "verify: OK" : "verify: FAILED");
    return r.ok() ? 0 : 1;
}

// The verifier of each dataset kind this build has (the format's own checks: the container's
// checksums are one of them).
struct Verifier {
    ArchiveKind kind;
    int (*run)(const VerifyJob& job);
};
static const Verifier kVerifiers[] = {
    {ArchiveKind::Catp, verify_catp_dataset},
    {ArchiveKind::Aqp, verify_aqp_dataset},
    {ArchiveKind::Points, verify_points_dataset},
};

// The kind named in a dataset's header; CATP when the header cannot be read, so that its verifier
// reports the problem (a missing file, a corrupt header) as it always has.
static ArchiveKind dataset_kind(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    uint8_t header[kArchiveHeaderSize] = {};
    in.read(reinterpret_cast<char*>(header), sizeof header);
    ArchiveHeader h;
    if (!in || !parse_archive_header(header, sizeof header, h).empty()) return ArchiveKind::Catp;
    return h.kind;
}

int cmd_verify(int argc, char** argv) {
    Options options(argc, argv, kVerifyUsage, {"quiet"});
    if (options.help()) {
        std::printf("%s", kVerifyUsage);
        return 0;
    }
    if (options.positional().size() != 1) usage_error("expected one dataset");
    VerifyJob job;
    job.dataset = options.positional()[0];
    job.original = options.get("mesh", "");
    job.samples = size_t(options.integer("samples", 50000, 100, 100000000));
    job.progress = !options.flag("quiet");
    options.finish();
    const ArchiveKind kind = dataset_kind(job.dataset);
    for (const Verifier& v : kVerifiers)
        if (v.kind == kind) return v.run(job);
    fail("'%s' holds a dataset of kind %s: this build has no verifier for it", job.dataset.c_str(),
         archive_kind_name(kind));
}

}  // namespace catpaq
