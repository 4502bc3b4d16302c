// measure_bench: the converter's simplification-error measurement (measured_simplification_error)
// on diamonds captured from real conversions, against the implementation it replaced
// (measure_reference.h), single-threaded, diamond by diamond in alternation. Checks that both
// return the same doubles, bit for bit, on every diamond.
//
// usage: measure_bench CASES.bin [ROUNDS] [new|ref]
//        MIN_OF=N measure_bench CASES.bin   (each diamond's fastest of N runs, caches warm)
// CASES.bin: records of 3 uint64 counts (positions, gathered indices, simplified indices), then
// the positions (3 doubles each), the gathered and the simplified indices (uint32). To capture
// them, convert with a temporary hook at the top of measured_simplification_error:
//     static FILE* f = std::fopen("cases.bin", "wb"); static std::mutex m;
//     { std::lock_guard<std::mutex> lock(m); uint64_t n[3] = {gathered.positions.size(),
//       gathered.indices.size(), simplified.size()}; std::fwrite(n, 8, 3, f);
//       std::fwrite(gathered.positions.data(), 24, n[0], f);
//       std::fwrite(gathered.indices.data(), 4, n[1], f); std::fwrite(simplified.data(), 4, n[2], f); }
// (the 1M-triangle scan gives 212 diamonds, 79 MB).
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <vector>

#include <tbb/global_control.h>

#include "measure_reference.h"

using namespace catpaq;

struct Case {
    WorkFragment gathered;
    std::vector<uint32_t> simplified;
};

static std::vector<Case> read_cases(const char* path) {
    std::vector<Case> cases;
    FILE* f = std::fopen(path, "rb");
    if (!f) {
        std::perror(path);
        std::exit(1);
    }
    uint64_t n[3];
    while (std::fread(n, 8, 3, f) == 3) {
        Case c;
        c.gathered.positions.resize(n[0]);
        c.gathered.indices.resize(n[1]);
        c.simplified.resize(n[2]);
        bool ok = std::fread(c.gathered.positions.data(), sizeof(Vec3d), n[0], f) == n[0] &&
                  std::fread(c.gathered.indices.data(), 4, n[1], f) == n[1] &&
                  std::fread(c.simplified.data(), 4, n[2], f) == n[2];
        if (!ok) break;
        cases.push_back(std::move(c));
    }
    std::fclose(f);
    return cases;
}

static double thread_seconds() {
    timespec t;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

// Times both implementations diamond by diamond, alternating which goes first: the machine is
// shared, and interleaving at this grain exposes both to the same load. Thread CPU time, so
// that time spent descheduled does not count.
static void time_round(const std::vector<Case>& cases, std::vector<double>& ref, std::vector<double>& now, bool run_ref,
                       bool run_new, double& ref_seconds, double& new_seconds) {
    ref.resize(cases.size());
    now.resize(cases.size());
    ref_seconds = new_seconds = 0;
    for (size_t i = 0; i < cases.size(); ++i) {
        const Case& c = cases[i];
        for (int k = 0; k < 2; ++k) {
            const bool reference_turn = (k == 0) == (i % 2 == 0);
            if (reference_turn && run_ref) {
                const double t0 = thread_seconds();
                ref[i] = measure_reference::measured_simplification_error(c.gathered, c.simplified);
                ref_seconds += thread_seconds() - t0;
            } else if (!reference_turn && run_new) {
                const double t0 = thread_seconds();
                now[i] = measured_simplification_error(c.gathered, c.simplified);
                new_seconds += thread_seconds() - t0;
            }
        }
    }
}

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: measure_bench CASES.bin [ROUNDS] [new|ref]\n");
        return 2;
    }
    const int rounds = argc > 2 ? std::atoi(argv[2]) : 5;
    const char* only = argc > 3 ? argv[3] : "";
    tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
    std::vector<Case> cases = read_cases(argv[1]);
    size_t triangles = 0;
    for (const Case& c : cases) triangles += c.gathered.indices.size() / 3;
    std::printf("%zu diamonds, %zu gathered triangles\n", cases.size(), triangles);
    std::vector<double> ref, now;
    double best_ref = 1e300, best_new = 1e300, sum_ratio = 0;
    const bool run_ref = std::strcmp(only, "new") != 0, run_new = std::strcmp(only, "ref") != 0;
    if (std::getenv("MIN_OF")) {
        // Each diamond's fastest of N runs, summed: filters out the bursts of load of a shared
        // machine (caches warm).
        const int n = std::atoi(std::getenv("MIN_OF"));
        double sum_ref = 0, sum_new = 0;
        for (size_t i = 0; i < cases.size(); ++i) {
            double min_ref = 1e300, min_new = 1e300;
            for (int k = 0; k < n; ++k) {
                double t0 = thread_seconds();
                if (run_ref) measure_reference::measured_simplification_error(cases[i].gathered, cases[i].simplified);
                double t1 = thread_seconds();
                if (run_new) measured_simplification_error(cases[i].gathered, cases[i].simplified);
                double t2 = thread_seconds();
                min_ref = std::min(min_ref, t1 - t0);
                min_new = std::min(min_new, t2 - t1);
            }
            sum_ref += min_ref;
            sum_new += min_new;
        }
        std::printf("min of %d: reference %.3f s, new %.3f s, ratio %.3f\n", n, sum_ref, sum_new, sum_ref / sum_new);
        return 0;
    }
    for (int r = 0; r < rounds; ++r) {
        double a = 0, b = 0;
        time_round(cases, ref, now, run_ref, run_new, a, b);
        best_ref = std::min(best_ref, a);
        best_new = std::min(best_new, b);
        sum_ratio += a / b;
        std::printf("round %d: reference %.3f s, new %.3f s, ratio %.3f\n", r, a, b, a / b);
        if (run_ref && run_new)
            for (size_t i = 0; i < cases.size(); ++i)
                if (std::memcmp(&ref[i], &now[i], 8) != 0) {
                    std::printf("MISMATCH diamond %zu: reference %.17g new %.17g\n", i, ref[i], now[i]);
                    return 1;
                }
    }
    std::printf("best: reference %.3f s, new %.3f s; mean ratio %.3f%s\n", best_ref, best_new, sum_ratio / rounds,
                run_ref && run_new ? "; results bit-identical" : "");
    return 0;
}
