#include "base/temp_file.h"

#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include "base/error.h"
#include "base/output_path.h"

namespace catpaq {

TempFile::TempFile(const std::string& near_path) : dir_(directory_of(near_path)) {
    // O_TMPFILE gives a file that never had a name; mkstemp + unlink is the fallback for file
    // systems without it.
    fd_ = ::open(dir_.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
    if (fd_ < 0) {
        std::string pattern = dir_ + "/.catpaq-scratch-XXXXXX";
        fd_ = ::mkstemp(pattern.data());
        if (fd_ >= 0) ::unlink(pattern.c_str());
    }
    if (fd_ < 0) fail("cannot create a scratch file in '%s': %s", dir_.c_str(), std::strerror(errno));
}

TempFile::~TempFile() {
    if (fd_ >= 0) ::close(fd_);
}

void TempFile::write_at(uint64_t offset, const void* data, size_t size) {
    const char* p = static_cast<const char*>(data);
    while (size > 0) {
        ssize_t n = ::pwrite(fd_, p, size, off_t(offset));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0)
            fail("cannot write scratch data in '%s': %s", dir_.c_str(), n < 0 ? std::strerror(errno) : "no progress");
        p += n;
        offset += uint64_t(n);
        size -= size_t(n);
    }
}

// Reads until `size` bytes or the end of the file; returns the bytes read.
size_t TempFile::read_up_to(uint64_t offset, void* data, size_t size) const {
    char* p = static_cast<char*>(data);
    size_t done = 0;
    while (done < size) {
        ssize_t n = ::pread(fd_, p + done, size - done, off_t(offset + done));
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) fail("cannot read scratch data in '%s': %s", dir_.c_str(), std::strerror(errno));
        if (n == 0) break;
        done += size_t(n);
    }
    return done;
}

void TempFile::read_at(uint64_t offset, void* data, size_t size) const {
    if (read_up_to(offset, data, size) != size) fail("cannot read scratch data in '%s': file too short", dir_.c_str());
}

void TempFile::read_or_zero(uint64_t offset, void* data, size_t size) const {
    size_t done = read_up_to(offset, data, size);
    std::memset(static_cast<char*>(data) + done, 0, size - done);
}

void* TempFile::map(uint64_t size) {
    if (size == 0) return nullptr;
    void* data = ::mmap(nullptr, size_t(size), PROT_READ | PROT_WRITE, MAP_SHARED, fd_, 0);
    if (data == MAP_FAILED) fail("cannot map scratch data in '%s': %s", dir_.c_str(), std::strerror(errno));
    return data;
}

void unmap_file(void* data, uint64_t size) {
    if (data) ::munmap(data, size_t(size));
}

void release_mapped_pages(void* data, uint64_t size) {
    if (data) ::madvise(data, size_t(size), MADV_DONTNEED);
}

uint64_t physical_memory_bytes() {
    long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
    return pages > 0 && page > 0 ? uint64_t(pages) * uint64_t(page) : 0;
}

}  // namespace catpaq
