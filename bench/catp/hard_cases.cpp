// hard_cases: the numerical-robustness suite, one line per case. Each generated hard case
// (mesh/generators.h) goes through the converter, `verify`'s checks and distance measures, and
// the crack check of the tests (catp/crack_check.h) on the finest, the coarsest and N random
// cuts. A case passes when the converter accepts it, verify finds no broken invariant, no cut
// has a border edge away from the original border (a crack), and every level's measured
// distance to the original is within its stored bound; or it is refused with a message. The
// report (scripts/report/run.sh) tabulates the output.
//
// usage: hard_cases [--cuts N] [--case NAME] [--keep DIR]
// Output: a header, then per case one line
//   case|NAME|TRIANGLES|INPUT_BORDER_EDGES|OUTCOME|CUTS|BORDER_FOUND_MAX|OFF_BORDER_MAX|
//       MAX_ERROR_REL|MAX_ERROR_OVER_BOUND|DETAIL
// OUTCOME is "passes", "refused" (DETAIL: the converter's message) or "FAILS" (DETAIL: why).
// Exit status 1 if any case fails, 2 on bad arguments.
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "base/error.h"
#include "catp/builder.h"
#include "catp/crack_check.h"
#include "catp/verify.h"
#include "mesh/generators.h"

using namespace catpaq;
namespace fs = std::filesystem;

namespace {

struct CaseResult {
    std::string outcome = "passes", detail;
    size_t cuts = 0, border_found_max = 0, off_border_max = 0;
    double max_error_rel = 0, max_error_over_bound = 0;
};

void fails(CaseResult& r, const std::string& why) {
    r.outcome = "FAILS";
    r.detail += (r.detail.empty() ? "" : "; ") + why;
}

// Border edges of a cut in total (for the table) and away from the original border (cracks).
void check_cut(const CatpFile& file, const RefinedSet& cut, const Mesh& mesh, double tolerance,
               std::unordered_map<uint64_t, DiamondFragments>& cache, CaseResult& r) {
    CutTopology topo = cut_topology(file, cut, cache);
    size_t off = border_edges_off_original_border(file, cut, mesh, tolerance, cache);
    r.cuts++;
    r.border_found_max = std::max(r.border_found_max, topo.border_edges);
    r.off_border_max = std::max(r.off_border_max, off);
}

// The same settings as the crack and error tests: a deep leaf level (7), so many lattice planes,
// edges and corners cut each model.
CaseResult run_case(HardCase c, const Mesh& mesh, const std::string& path, int cuts) {
    CaseResult r;
    CatpBuildSettings settings;
    settings.leaf_triangles = 200;
    settings.leaf_level = 7;
    settings.progress = false;
    // Centred, as the cases are built: their geometry lies on the lattice planes of every level
    // (the default placement shifts models off them; tests/catp check both).
    settings.centred_placement = true;
    try {
        build_catp(mesh, path, settings);
    } catch (const Error& e) {
        r.outcome = "refused";
        r.detail = e.what();
        if (r.detail.empty()) fails(r, "refused without a message");
        return r;
    }
    VerifySettings vs;
    vs.samples_per_level = 5000;
    VerifyReport v = verify_catp(path, &mesh, vs);
    if (v.checksum_failures + v.corrupt_nodes + v.bad_flags + v.monotonicity_violations)
        fails(r, "verify: " + (v.problems.empty() ? std::string("broken invariant") : v.problems[0]));
    // verify's local face check assumes a closed manifold; other inputs rely on the global
    // crack check below (border edges only on the original border), as in the tests.
    bool closed_manifold = count_border_edges(mesh.indices) == 0 && c != HardCase::NonManifoldEdges;
    if (closed_manifold && v.face_mismatches)
        fails(r, "verify: " + (v.problems.empty() ? std::string("face mismatch") : v.problems[0]));
    for (const VerifyLevel& l : v.levels) {
        if (!l.diamonds || l.distance_to_original_max < 0) continue;
        r.max_error_rel = std::max(r.max_error_rel, l.distance_to_original_max / v.diagonal);
        double ratio = l.stored_error > 0 ? l.distance_to_original_max / l.stored_error
                                          : (l.distance_to_original_max > 0 ? 1e300 : 0);
        r.max_error_over_bound = std::max(r.max_error_over_bound, ratio);
    }
    if (r.max_error_over_bound > 1) fails(r, strprintf("measured error %.3gx its stored bound", r.max_error_over_bound));

    CatpFile file(path);
    double tolerance = 0;  // coarse levels may slide an open border along itself by their error
    for (const ArchiveEntry& e : file.index().entries()) tolerance = std::max(tolerance, double(e.error));
    std::unordered_map<uint64_t, DiamondFragments> cache;
    RefinedSet all;
    for (const ArchiveEntry& e : file.index().entries())
        if (!(e.flags & kCatpLeafFlag)) all.refine(DiamondId{e.key});
    check_cut(file, all, mesh, tolerance, cache, r);
    check_cut(file, RefinedSet{}, mesh, tolerance, cache, r);
    std::mt19937_64 rng(11);
    for (int t = 0; t < cuts; ++t) check_cut(file, random_cut(file.index(), rng, t % 2 == 1), mesh, tolerance, cache, r);
    if (r.off_border_max) fails(r, strprintf("cracks: up to %zu border edges off the original border", r.off_border_max));
    return r;
}

}  // namespace

int main(int argc, char** argv) try {
    int cuts = 30;
    std::string only, keep;
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        if (a == "--cuts" && i + 1 < argc) {
            cuts = std::atoi(argv[++i]);
            if (cuts < 0 || cuts > 100000) fail("--cuts: expected 0..100000");
        } else if (a == "--case" && i + 1 < argc) {
            only = argv[++i];
        } else if (a == "--keep" && i + 1 < argc) {
            keep = argv[++i];
        } else if (a == "-h" || a == "--help") {
            std::printf("usage: hard_cases [--cuts N] [--case NAME] [--keep DIR]\n");
            return 0;
        } else {
            std::fprintf(stderr, "hard_cases: unknown argument '%s' (see --help)\n", a.c_str());
            return 2;
        }
    }
    fs::path dir = keep.size() ? fs::path(keep) : fs::temp_directory_path() / ("catpaq_hard_cases_" + std::to_string(getpid()));
    fs::create_directories(dir);
    std::printf("# converter: leaf level 7, leaf_triangles 200; verify: 5000 samples per level; cuts: finest, "
                "coarsest and %d random (half spatial)\n",
                cuts);
    std::printf("# case|name|triangles|input border edges|outcome|cuts|border edges found (max)|"
                "border edges off the original border (max)|max error / diagonal|max error / stored bound|detail\n");
    bool all_ok = true, found = false;
    for (HardCase c : kAllHardCases) {
        if (only.size() && only != hard_case_name(c)) continue;
        found = true;
        Mesh mesh = make_hard_case(c, 1);
        CaseResult r = run_case(c, mesh, (dir / (std::string(hard_case_name(c)) + ".cpq")).string(), cuts);
        all_ok &= r.outcome != "FAILS";
        std::replace(r.detail.begin(), r.detail.end(), '|', '/');
        std::replace(r.detail.begin(), r.detail.end(), '\n', ' ');
        std::printf("case|%s|%zu|%zu|%s|%zu|%zu|%zu|%.3g|%.3g|%s\n", hard_case_name(c), mesh.triangle_count(),
                    count_border_edges(mesh.indices), r.outcome.c_str(), r.cuts, r.border_found_max, r.off_border_max,
                    r.max_error_rel, r.max_error_over_bound, r.detail.c_str());
        std::fflush(stdout);
    }
    if (keep.empty()) fs::remove_all(dir);
    if (!found) fail("no hard case named '%s'", only.c_str());
    return all_ok ? 0 : 1;
} catch (const std::exception& e) {
    std::fprintf(stderr, "hard_cases: %s\n", e.what());
    return 1;
}
