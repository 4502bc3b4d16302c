// memory_budget_bench: does `catpaq convert --memory B` keep the whole process within B?
//
// Runs the converter as a child process, budgets from the smallest it accepts upwards, several
// times each (the peak varies from run to run: work stealing and the heap's reuse of freed
// blocks differ), and takes each run's peak resident memory from the kernel (wait4's ru_maxrss,
// the high-water mark, not sampled), not from what the tool reports of itself. The baseline is
// the same input at an ample budget (1 GiB) in the same run: times are ratios to it.
//
// usage: memory_budget_bench [--input MESH | --triangles N [--uneven]] [--threads 1,2]
//                            [--steps 0,8,16,32] [--runs 6] [--catpaq PATH]
//   --steps: MiB above the smallest budget the tool accepts for that thread count.
// Prints one line per budget; exits 1 when any run peaked past its budget.
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "base/child_process.h"
#include "base/error.h"
#include "base/options.h"
#include "mesh/generators.h"
#include "mesh/io.h"

using namespace catpaq;
namespace fs = std::filesystem;

namespace {

const char* kUsage =
    "usage: memory_budget_bench [--input MESH | --triangles N [--uneven]] [--threads 1,2]\n"
    "                           [--steps 0,8,16,32] [--runs 6] [--catpaq PATH]\n"
    "  Converts one mesh at budgets from the smallest `catpaq convert --memory` accepts upwards and\n"
    "  checks each run's peak resident memory (wait4) against its budget.\n"
    "  --input MESH    mesh to convert (default: a generated scan-like mesh of --triangles)\n"
    "  --triangles N   size of the generated mesh (default 1000000)\n"
    "  --uneven        generate make_uneven_density (a dense sphere in a sparse blob) instead\n"
    "  --threads LIST  thread counts (default 1,2)\n"
    "  --steps LIST    MiB above the smallest accepted budget (default 0,8,16,32)\n"
    "  --runs N        runs per budget (default 6)\n"
    "  --catpaq PATH   the tool (default: next to this program, ../../apps/catpaq)\n";

std::vector<long> parse_list(const std::string& text, const char* name) {
    std::vector<long> out;
    size_t at = 0;
    while (at <= text.size()) {
        size_t comma = text.find(',', at);
        if (comma == std::string::npos) comma = text.size();
        std::string item = text.substr(at, comma - at);
        char* end = nullptr;
        long v = std::strtol(item.c_str(), &end, 10);
        if (item.empty() || *end || v < 0) fail("--%s: '%s' is not a list of non-negative integers", name, text.c_str());
        out.push_back(v);
        at = comma + 1;
    }
    return out;
}

// The smallest budget the tool accepts with `threads` workers, from its own refusal message.
uint64_t smallest_budget_mib(const std::string& tool, const std::string& input, const fs::path& dir, long threads) {
    ChildRun r = run_measured({tool, "convert", input, "-o", (dir / "refused.cpq").string(), "--memory", "1M",
                               "--threads", std::to_string(threads), "--quiet"},
                              (dir / "refused.txt").string());
    const size_t at = r.output.find("at least ");
    if (r.status == 0 || at == std::string::npos)
        fail("%s did not refuse a 1 MiB budget as expected:\n%s", tool.c_str(), r.output.c_str());
    return std::strtoull(r.output.c_str() + at + 9, nullptr, 10);
}

// True if convert refused `budget_mib` asking for at most one MiB more (see the run loop).
bool refused_by_one_mib(const std::string& output, uint64_t budget_mib) {
    const size_t at = output.find("at least ");
    return at != std::string::npos && std::strtoull(output.c_str() + at + 9, nullptr, 10) <= budget_mib + 1;
}

}  // namespace

int main(int argc, char** argv) try {
    Options options(argc, argv, kUsage, {"uneven"});
    if (options.help()) {
        std::printf("%s", kUsage);
        return 0;
    }
    const std::string default_tool = (fs::path(argv[0]).parent_path() / "../../apps/catpaq").lexically_normal().string();
    const std::string tool = options.get("catpaq", default_tool);
    std::string input = options.get("input", "");
    const int64_t triangles = options.integer("triangles", 1000000, 1000, 100000000);
    const bool uneven = options.flag("uneven");
    const std::vector<long> thread_counts = parse_list(options.get("threads", "1,2"), "threads");
    const std::vector<long> steps = parse_list(options.get("steps", "0,8,16,32"), "steps");
    const int runs = int(options.integer("runs", 6, 1, 1000));
    options.finish();
    if (access(tool.c_str(), X_OK) != 0) fail("%s: not an executable (pass --catpaq PATH)", tool.c_str());

    const fs::path dir = fs::temp_directory_path() / ("memory_budget_bench." + std::to_string(getpid()));
    fs::create_directories(dir);
    struct Cleanup {
        fs::path dir;
        ~Cleanup() { fs::remove_all(dir); }
    } cleanup{dir};
    if (input.empty()) {
        input = (dir / "scan.ply").string();
        write_ply(input, uneven ? make_uneven_density(size_t(triangles), 7) : make_scan_like(size_t(triangles), 7), true);
        std::printf("input: generated %s mesh of %lld triangles\n", uneven ? "uneven-density" : "scan-like",
                    (long long)triangles);
    } else {
        if (!fs::is_regular_file(input)) fail("--input %s: no such file", input.c_str());
        std::printf("input: %s\n", input.c_str());
    }
    const std::string out = (dir / "out.cpq").string();
    const std::string log = (dir / "log.txt").string();

    bool over = false;
    std::printf("%7s %11s %4s %12s %12s %12s %10s\n", "threads", "budget MiB", "runs", "peak min", "peak max",
                "max/budget", "time x1G");
    for (long threads : thread_counts) {
        const std::vector<std::string> common = {tool, "convert", input, "-o", out, "--quiet", "--threads", std::to_string(threads)};
        auto with_memory = [&](const std::string& memory) {
            std::vector<std::string> a = common;
            a.push_back("--memory");
            a.push_back(memory);
            return a;
        };
        ChildRun base = run_measured(with_memory("1G"), log);
        if (base.status != 0) fail("convert at 1G failed:\n%s", base.output.c_str());
        const uint64_t smallest = smallest_budget_mib(tool, input, dir, threads);
        for (long step : steps) {
            const uint64_t budget_mib = smallest + uint64_t(step);
            const uint64_t budget = budget_mib << 20;
            uint64_t lo = UINT64_MAX, hi = 0;
            double seconds = 0;
            for (int r = 0; r < runs; ++r) {
                ChildRun run = run_measured(with_memory(std::to_string(budget_mib) + "M"), log);
                // The smallest budget counts the tool's own resident size at start, which varies by
                // a few hundred KiB from run to run (shared-library pages already in memory): at
                // the smallest budget about one run in six finds it needs 1 MiB more and refuses at
                // once. Such a refusal says nothing about the budget; the run is tried again.
                for (int again = 0; again < 8 && run.status != 0 && refused_by_one_mib(run.output, budget_mib); ++again)
                    run = run_measured(with_memory(std::to_string(budget_mib) + "M"), log);
                if (run.status != 0) fail("convert at %llu MiB failed:\n%s", (unsigned long long)budget_mib, run.output.c_str());
                lo = std::min(lo, run.peak_bytes);
                hi = std::max(hi, run.peak_bytes);
                seconds += run.seconds;
            }
            over |= hi > budget;
            std::printf("%7ld %11llu %4d %12.1f %12.1f %12.3f %10.2f%s\n", threads, (unsigned long long)budget_mib, runs,
                        double(lo) / (1 << 20), double(hi) / (1 << 20), double(hi) / double(budget),
                        seconds / runs / base.seconds, hi > budget ? "  OVER BUDGET" : "");
            std::fflush(stdout);
        }
    }
    std::printf("%s\n", over ? "FAIL: some runs peaked past their budget" : "OK: every run stayed within its budget");
    return over ? 1 : 0;
} catch (const std::exception& e) {
    std::fprintf(stderr, "memory_budget_bench: %s\n", e.what());
    return 2;
}
