#include "base/progress.h"

#include <cstdio>
#include <cstdlib>
#include <unistd.h>

namespace catpaq {

bool Progress::enabled() {
    static const bool on = isatty(fileno(stderr)) && std::getenv("CI") == nullptr;
    return on;
}

Progress::Progress(std::string label, uint64_t total, std::string unit)
    : label_(std::move(label)), unit_(std::move(unit)), total_(total),
      start_(std::chrono::steady_clock::now()), last_draw_(start_), enabled_(enabled()) {}

Progress::~Progress() { finish(); }

void Progress::set_total(uint64_t total) { total_ = total; }

void Progress::add(uint64_t units) {
    done_ += units;
    if (!enabled_) return;
    auto now = std::chrono::steady_clock::now();
    std::unique_lock lock(mutex_, std::try_to_lock);
    if (!lock.owns_lock() || now - last_draw_ < std::chrono::milliseconds(100)) return;
    last_draw_ = now;
    draw(false);
}

void Progress::finish() {
    std::lock_guard lock(mutex_);
    if (finished_) return;
    finished_ = true;
    if (enabled_) draw(true);
}

static void human(double value, char* out, size_t size) {
    const char* suffix[] = {"", "k", "M", "G", "T"};
    int i = 0;
    while (value >= 1000.0 && i < 4) { value /= 1000.0; ++i; }
    std::snprintf(out, size, "%.1f%s", value, suffix[i]);
}

void Progress::draw(bool final_draw) {
    double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    uint64_t done = done_, total = total_;
    double fraction = total ? double(done) / double(total) : 0.0;
    if (fraction > 1.0) fraction = 1.0;
    const int width = 30;
    int filled = int(fraction * width);
    char bar[width + 1];
    for (int i = 0; i < width; ++i) bar[i] = i < filled ? '#' : '.';
    bar[width] = 0;
    double rate = elapsed > 0 ? double(done) / elapsed : 0.0;
    char rate_text[32], done_text[32];
    human(rate, rate_text, sizeof rate_text);
    human(double(done), done_text, sizeof done_text);
    char eta[32] = "--";
    if (rate > 0 && total > done) {
        double seconds = double(total - done) / rate;
        std::snprintf(eta, sizeof eta, "%dm%02ds", int(seconds) / 60, int(seconds) % 60);
    } else if (final_draw || done >= total) {
        std::snprintf(eta, sizeof eta, "%.1fs", elapsed);
    }
    std::fprintf(stderr, "\r%-18s [%s] %5.1f%% %s %s, %s %s/s, ETA %s   %s", label_.c_str(), bar,
                 fraction * 100.0, done_text, unit_.c_str(), rate_text, unit_.c_str(), eta,
                 final_draw ? "\n" : "");
    std::fflush(stderr);
}

}  // namespace catpaq
