#include "base/signal_cleanup.h"

#include <atomic>
#include <csignal>
#include <cstring>
#include <mutex>
#include <unistd.h>

namespace catpaq {

namespace {

constexpr int kSlots = 32;
constexpr size_t kPathMax = 4096;

// A slot is written only while `used` is false (under the mutex), and read by the handler
// only while it is true.
struct Slot {
    std::atomic<bool> used{false};
    char path[kPathMax];
};
Slot g_slots[kSlots];
std::mutex g_mutex;
bool g_installed = false;

extern "C" void remove_registered(int sig) {
    for (Slot& s : g_slots)
        if (s.used.load()) ::unlink(s.path);
    // SA_RESETHAND restored the default action: end the process as the signal would have.
    ::raise(sig);
}

void install() {
    struct sigaction action{};
    action.sa_handler = remove_registered;
    sigemptyset(&action.sa_mask);
    action.sa_flags = SA_RESETHAND;
    for (int sig : {SIGINT, SIGTERM, SIGHUP}) {
        struct sigaction old{};
        // A handler someone else installed (or an ignored signal) is left alone.
        if (sigaction(sig, nullptr, &old) == 0 && old.sa_handler == SIG_DFL) sigaction(sig, &action, nullptr);
    }
}

}  // namespace

void remove_on_signal(const std::string& path) {
    if (path.size() >= kPathMax) return;
    std::lock_guard lock(g_mutex);
    if (!g_installed) {
        install();
        g_installed = true;
    }
    for (Slot& s : g_slots) {
        if (s.used.load()) continue;
        std::memcpy(s.path, path.c_str(), path.size() + 1);
        s.used.store(true);
        return;
    }
}

void forget_on_signal(const std::string& path) {
    std::lock_guard lock(g_mutex);
    for (Slot& s : g_slots)
        if (s.used.load() && path == s.path) {
            s.used.store(false);
            return;
        }
}

}  // namespace catpaq
