#pragma once
// Writes a file that appears under its final path only when complete. The data goes to an
// anonymous file in the destination's directory (O_TMPFILE: it has no name, so however the
// process ends, nothing half-written is left behind), which commit() flushes, fsyncs and links
// into place, replacing an existing file atomically. On file systems without O_TMPFILE it falls
// back to a temporary name (PATH.tmp.PID), removed on errors, on SIGINT/SIGTERM/SIGHUP
// (base/signal_cleanup.h) and, after a SIGKILL, by remove_stale_temporaries. Errors name the
// final path, never a temporary one.
#include <cstdint>
#include <cstdio>
#include <string>

namespace catpaq {

class AtomicFile {
public:
    explicit AtomicFile(std::string path);  // throws Error if the file cannot be created
    ~AtomicFile();
    AtomicFile(const AtomicFile&) = delete;
    AtomicFile& operator=(const AtomicFile&) = delete;

    void write(const void* data, size_t size);  // throws Error on failure (disk full, ...)
    uint64_t size() const { return size_; }
    void commit();  // flush, fsync, link into place; throws Error on failure

    const std::string& path() const { return path_; }
    // True while the data has no name (O_TMPFILE); false on the named fallback.
    bool anonymous() const { return temp_path_.empty(); }

private:
    std::string path_, temp_path_;  // temp_path_: the fallback's name, else empty
    FILE* file_ = nullptr;
    uint64_t size_ = 0;
};

// Convenience: writes a whole buffer atomically.
void write_file_atomic(const std::string& path, const void* data, size_t size);

// Reads a whole file; throws Error naming the file on failure.
std::string read_file(const std::string& path);

}  // namespace catpaq
