#include "base/atomic_file.h"

#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <unistd.h>

#include "base/error.h"

namespace catpaq {

AtomicFile::AtomicFile(std::string path) : path_(std::move(path)) {
    temp_path_ = path_ + ".tmp." + std::to_string(getpid());
    file_ = std::fopen(temp_path_.c_str(), "wb");
    if (!file_) fail("cannot create '%s': %s", temp_path_.c_str(), std::strerror(errno));
}

AtomicFile::~AtomicFile() {
    if (file_) {
        std::fclose(file_);
        std::remove(temp_path_.c_str());
    }
}

void AtomicFile::write(const void* data, size_t size) {
    if (size == 0) return;
    if (std::fwrite(data, 1, size, file_) != size)
        fail("cannot write '%s': %s", temp_path_.c_str(), std::strerror(errno));
    size_ += size;
}

void AtomicFile::commit() {
    if (std::fflush(file_) != 0 || fsync(fileno(file_)) != 0)
        fail("cannot flush '%s': %s", temp_path_.c_str(), std::strerror(errno));
    if (std::fclose(file_) != 0) {
        file_ = nullptr;
        std::remove(temp_path_.c_str());
        fail("cannot close '%s': %s", temp_path_.c_str(), std::strerror(errno));
    }
    file_ = nullptr;
    if (std::rename(temp_path_.c_str(), path_.c_str()) != 0) {
        int err = errno;
        std::remove(temp_path_.c_str());
        fail("cannot rename '%s' to '%s': %s", temp_path_.c_str(), path_.c_str(), std::strerror(err));
    }
}

void write_file_atomic(const std::string& path, const void* data, size_t size) {
    AtomicFile file(path);
    file.write(data, size);
    file.commit();
}

std::string read_file(const std::string& path) {
    FILE* f = std::fopen(path.c_str(), "rb");
    if (!f) fail("cannot open '%s': %s", path.c_str(), std::strerror(errno));
    std::string out;
    char buffer[1 << 16];
    size_t n;
    while ((n = std::fread(buffer, 1, sizeof buffer, f)) > 0) out.append(buffer, n);
    bool bad = std::ferror(f);
    std::fclose(f);
    if (bad) fail("cannot read '%s'", path.c_str());
    return out;
}

}  // namespace catpaq
