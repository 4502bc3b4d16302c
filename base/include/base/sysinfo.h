#pragma once
// Small facts about the running process and machine, for benchmark and build reports.
#include <algorithm>
#include <cstdint>
#include <string>

namespace catpaq {

uint64_t peak_rss_bytes();     // high-water mark of resident memory (getrusage)
uint64_t current_rss_bytes();  // resident memory now (/proc/self/statm)
std::string cpu_model();       // from /proc/cpuinfo, or "unknown"
double now_seconds();          // monotonic clock
double cpu_seconds();          // user + system CPU time of the process so far (all threads)
double thread_cpu_seconds();   // CPU time of the calling thread (other processes only steal wall time)

// The shortest of `runs` timings of fn(), by `clock` (now_seconds or thread_cpu_seconds).
template <typename Fn>
double best_of(int runs, Fn&& fn, double (*clock)() = now_seconds) {
    double best = 1e300;
    for (int r = 0; r < runs; ++r) {
        double t0 = clock();
        fn();
        best = std::min(best, clock() - t0);
    }
    return best;
}

}  // namespace catpaq
