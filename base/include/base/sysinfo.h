#pragma once
// Small facts about the running process and machine, for benchmark and build reports.
#include <cstdint>
#include <string>

namespace catpaq {

uint64_t peak_rss_bytes();     // high-water mark of resident memory (getrusage)
uint64_t current_rss_bytes();  // resident memory now (/proc/self/statm)
std::string cpu_model();       // from /proc/cpuinfo, or "unknown"
double now_seconds();          // monotonic clock
double cpu_seconds();          // user + system CPU time of the process so far (all threads)

}  // namespace catpaq
