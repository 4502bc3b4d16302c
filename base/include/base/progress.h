#pragma once
// A terminal progress display in named phases: each phase has its own bar, count and rate, and
// ends with a line of its own ("convert: clipping leaves: 2.1M tri in 1.4 s, 1.5M tri/s"), so
// the terminal keeps a log of where the time went. It draws only when stderr is a terminal and
// the CI environment variable is unset; otherwise it stays quiet. Thread-safe: add() may be
// called from worker threads (it redraws at most 10 times a second).
//
// Honest numbers: the percentage and the count never pass the phase's total (work that runs
// over an estimate shows as 100% until the phase ends), and no ETA is shown until it means
// something (kEtaAfterSeconds into the phase and kEtaAfterFraction of it done): the first
// moments of a phase do not predict its end.
#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace catpaq {

// One line of the display, without the leading carriage return (pure, for tests).
struct ProgressState {
    std::string task, phase, unit;
    uint64_t done = 0, total = 0;  // total 0: unknown (no bar, no percentage, no ETA)
    double elapsed = 0;            // seconds since the phase began
    bool finished = false;         // the phase's closing line
};
std::string format_progress_line(const ProgressState& state);

constexpr double kEtaAfterSeconds = 2.0;
constexpr double kEtaAfterFraction = 0.05;

class Progress {
public:
    // task: what the whole run does ("convert"); the first phase is `phase` with `total` units
    // named `unit` ("tri").
    Progress(std::string task, std::string phase, uint64_t total, std::string unit);
    ~Progress();

    // Ends the current phase (its closing line) and begins the next, counting from zero.
    void phase(std::string name, uint64_t total, std::string unit);
    void add(uint64_t units);
    void set_total(uint64_t total);
    // Ends the current phase and the display. Called by the destructor.
    void finish();
    // Never draws, from now on (for --quiet).
    void silence();

    static bool enabled();

private:
    void draw(bool final_draw);  // with mutex_ held

    std::string task_, phase_, unit_;
    std::atomic<uint64_t> total_, done_{0};
    std::chrono::steady_clock::time_point start_, last_draw_;
    std::mutex mutex_;
    bool enabled_, finished_ = false;
};

}  // namespace catpaq
