#pragma once
// Writes a file under a temporary name in the same directory and renames it over the final
// path on commit(), so readers never see a half-written output. If the object is destroyed
// without commit() (an error was thrown), the temporary file is removed.
#include <cstdint>
#include <cstdio>
#include <string>

namespace catpaq {

class AtomicFile {
public:
    explicit AtomicFile(std::string path);  // throws Error if the temporary cannot be created
    ~AtomicFile();
    AtomicFile(const AtomicFile&) = delete;
    AtomicFile& operator=(const AtomicFile&) = delete;

    void write(const void* data, size_t size);  // throws Error on failure (disk full, ...)
    uint64_t size() const { return size_; }
    void commit();  // flush, fsync, rename; throws Error on failure

    const std::string& path() const { return path_; }

private:
    std::string path_, temp_path_;
    FILE* file_ = nullptr;
    uint64_t size_ = 0;
};

// Convenience: writes a whole buffer atomically.
void write_file_atomic(const std::string& path, const void* data, size_t size);

// Reads a whole file; throws Error naming the file on failure.
std::string read_file(const std::string& path);

}  // namespace catpaq
