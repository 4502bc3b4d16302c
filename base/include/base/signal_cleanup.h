#pragma once
// Files removed when the process is ended by SIGINT, SIGTERM or SIGHUP: the handler unlinks
// every registered path (async-signal-safe) and then lets the signal's default action end the
// process, so an interrupted run leaves no half-written file behind. (SIGKILL cannot be caught:
// outputs are anonymous files until they are complete, base/atomic_file.h, and
// remove_stale_temporaries in base/output_path.h clears what older runs left.)
#include <string>

namespace catpaq {

// Registers `path` (at most 32 paths at once; more are not registered). Thread-safe.
void remove_on_signal(const std::string& path);
// Unregisters `path` (after it was renamed into place or removed). Thread-safe.
void forget_on_signal(const std::string& path);

}  // namespace catpaq
