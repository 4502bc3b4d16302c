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

    // Maps the file's first `size` bytes (which must exist) shared and writable: pages are read
    // in as they are touched, and written back by the kernel. Throws Error if mapping fails.
    // Unmap with unmap_file().
    void* map(uint64_t size);

private:
    size_t read_up_to(uint64_t offset, void* data, size_t size) const;

    int fd_ = -1;
    std::string dir_;
};

// Unmaps what TempFile::map returned.
void unmap_file(void* data, uint64_t size);
// Drops the mapping's resident pages from the process (the data stays in the file and the page
// cache): what a phase touched stops counting towards the process's resident memory.
void release_mapped_pages(void* data, uint64_t size);

// Physical memory of the machine in bytes (0 if unknown).
uint64_t physical_memory_bytes();

}  // namespace catpaq
