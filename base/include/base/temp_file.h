#pragma once
// Scratch files for out-of-core work. The file is created next to a given path (so big scratch
// data lands on the disk the user chose for the output) and unlinked at once: it has no name,
// nothing is left behind if the process dies, and the kernel's page cache — not the process's
// resident memory — holds whatever of it is hot.
#include <cstddef>
#include <cstdint>
#include <string>

namespace catpaq {

class TempFile {
public:
    // Creates an anonymous file in the directory of `near_path` (the current directory if it has
    // none). Throws Error naming the directory if that fails.
    explicit TempFile(const std::string& near_path);
    ~TempFile();
    TempFile(const TempFile&) = delete;
    TempFile& operator=(const TempFile&) = delete;

    // Positional I/O; thread-safe (pread/pwrite). Throw Error on failure (disk full, short read).
    void write_at(uint64_t offset, const void* data, size_t size);
    void read_at(uint64_t offset, void* data, size_t size) const;
    // Reads what exists of [offset, offset + size) and zero-fills the rest (for sparse use).
    void read_or_zero(uint64_t offset, void* data, size_t size) const;

private:
    size_t read_up_to(uint64_t offset, void* data, size_t size) const;

    int fd_ = -1;
    std::string dir_;
};

// Physical memory of the machine in bytes (0 if unknown).
uint64_t physical_memory_bytes();

}  // namespace catpaq
