#pragma once
// A terminal progress bar with rate and ETA. It draws only when stderr is a terminal and
// the CI environment variable is unset; otherwise it stays quiet. Thread-safe: add() may be
// called from worker threads (it redraws at most 10 times a second).
#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace catpaq {

class Progress {
public:
    // label: what is being done; total: units of work; unit: name of one unit ("tri").
    Progress(std::string label, uint64_t total, std::string unit);
    ~Progress();

    void add(uint64_t units);
    void set_total(uint64_t total);
    // Draws the final state and a newline (if drawing at all). Called by the destructor.
    void finish();

    static bool enabled();

private:
    void draw(bool final_draw);

    std::string label_, unit_;
    std::atomic<uint64_t> total_, done_{0};
    std::chrono::steady_clock::time_point start_, last_draw_;
    std::mutex mutex_;
    bool enabled_, finished_ = false;
};

}  // namespace catpaq
