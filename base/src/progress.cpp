#include "base/progress.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <unistd.h>

namespace catpaq {

bool Progress::enabled() {
    static const bool on = isatty(fileno(stderr)) && std::getenv("CI") == nullptr;
    return on;
}

static std::string human(double value) {
    const char* suffix[] = {"", "k", "M", "G", "T"};
    int i = 0;
    while (value >= 1000.0 && i < 4) {
        value /= 1000.0;
        ++i;
    }
    char out[32];
    std::snprintf(out, sizeof out, i == 0 ? "%.0f%s" : "%.1f%s", value, suffix[i]);
    return out;
}

static std::string duration(double seconds) {
    char out[32];
    if (seconds < 1) std::snprintf(out, sizeof out, "%.0f ms", seconds * 1000);
    else if (seconds < 60) std::snprintf(out, sizeof out, "%.1f s", seconds);
    else std::snprintf(out, sizeof out, "%dm%02ds", int(seconds) / 60, int(seconds) % 60);
    return out;
}

std::string format_progress_line(const ProgressState& s) {
    // Work past an estimated total is shown as the total: never more than 100%.
    uint64_t done = s.total ? std::min(s.done, s.total) : s.done;
    double rate = s.elapsed > 0 ? double(s.done) / s.elapsed : 0.0;
    std::string line = s.task + ": " + s.phase;
    if (s.finished) {
        if (s.done == 0) return line + ": done in " + duration(s.elapsed);
        line += ": " + human(double(s.done)) + " " + s.unit + " in " + duration(s.elapsed);
        if (s.elapsed >= 0.1 && s.done > 0) line += ", " + human(rate) + " " + s.unit + "/s";
        return line;
    }
    double fraction = s.total ? double(done) / double(s.total) : 0.0;
    if (s.total) {
        const int width = 24;
        int filled = int(fraction * width);
        std::string bar(size_t(width), '.');
        for (int i = 0; i < filled; ++i) bar[size_t(i)] = '#';
        char pct[16];
        std::snprintf(pct, sizeof pct, "%5.1f%%", fraction * 100.0);
        line += " [" + bar + "] " + pct + " " + human(double(done)) + "/" + human(double(s.total)) + " " + s.unit;
    } else if (s.done > 0) {
        line += ": " + human(double(done)) + " " + s.unit;
    } else {
        return line + " (" + duration(s.elapsed) + ")";
    }
    if (s.elapsed >= 0.5 && s.done > 0) line += ", " + human(rate) + " " + s.unit + "/s";
    if (s.total && s.elapsed >= kEtaAfterSeconds && fraction >= kEtaAfterFraction && fraction < 1.0 && rate > 0)
        line += ", ETA " + duration(double(s.total - done) / rate);
    return line;
}

Progress::Progress(std::string task, std::string phase, uint64_t total, std::string unit)
    : task_(std::move(task)), phase_(std::move(phase)), unit_(std::move(unit)), total_(total),
      start_(std::chrono::steady_clock::now()), last_draw_(start_), enabled_(enabled()) {}

Progress::~Progress() { finish(); }

void Progress::set_total(uint64_t total) { total_ = total; }

void Progress::phase(std::string name, uint64_t total, std::string unit) {
    std::lock_guard lock(mutex_);
    if (finished_) return;
    if (enabled_) draw(true);
    phase_ = std::move(name);
    unit_ = std::move(unit);
    total_ = total;
    done_ = 0;
    start_ = last_draw_ = std::chrono::steady_clock::now();
}

void Progress::add(uint64_t units) {
    done_ += units;
    if (!enabled_) return;
    auto now = std::chrono::steady_clock::now();
    std::unique_lock lock(mutex_, std::try_to_lock);
    if (!lock.owns_lock() || finished_ || now - last_draw_ < std::chrono::milliseconds(100)) return;
    last_draw_ = now;
    draw(false);
}

void Progress::finish() {
    std::lock_guard lock(mutex_);
    if (finished_) return;
    finished_ = true;
    if (enabled_) draw(true);
}

void Progress::silence() {
    std::lock_guard lock(mutex_);
    enabled_ = false;
}

void Progress::draw(bool final_draw) {
    ProgressState s;
    s.task = task_;
    s.phase = phase_;
    s.unit = unit_;
    s.done = done_;
    s.total = total_;
    s.elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    s.finished = final_draw;
    // \033[K clears what a longer previous line left on the right.
    std::fprintf(stderr, "\r%s\033[K%s", format_progress_line(s).c_str(), final_draw ? "\n" : "");
    std::fflush(stderr);
}

}  // namespace catpaq
