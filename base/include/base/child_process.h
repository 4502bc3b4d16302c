#pragma once
// Runs a program as a child process and measures it from outside: its exit status, wall time
// and peak resident memory as the kernel counts it (wait4's ru_maxrss, the high-water mark, not
// sampled), and its CPU time. For tests and benchmarks that check what a tool promises about
// its own memory and time.
#include <cstdint>
#include <string>
#include <vector>

namespace catpaq {

struct ChildRun {
    int status = -1;          // exit status; 128 + signal when killed; 127 when it could not start
    uint64_t peak_bytes = 0;  // peak resident memory
    double seconds = 0;       // wall time
    double cpu_seconds = 0;   // user + system time of the child and the children it waited for
    std::string output;       // stdout and stderr, interleaved
};

// Runs argv[0] (a path, not searched in PATH) with arguments argv[1..], its stdout and stderr
// going to `log_path` (read back into output, then removed). Throws catpaq::Error when no child
// can be started or waited for.
ChildRun run_measured(const std::vector<std::string>& argv, const std::string& log_path);

}  // namespace catpaq
