#include "base/atomic_file.h"

#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "base/error.h"
#include "base/output_path.h"
#include "base/signal_cleanup.h"

namespace catpaq {

AtomicFile::AtomicFile(std::string path) : path_(std::move(path)) {
    struct stat st{};
    if (::stat(path_.c_str(), &st) == 0 && S_ISDIR(st.st_mode)) fail("cannot write '%s': '%s' is a directory", path_.c_str(), path_.c_str());
    const std::string dir = directory_of(path_);
    int fd = ::open(dir.c_str(), O_TMPFILE | O_WRONLY | O_CLOEXEC, 0666);
    if (fd < 0 && (errno == EOPNOTSUPP || errno == EISDIR || errno == EINVAL)) {
        // No O_TMPFILE here: a named temporary, removed on signals and errors.
        temp_path_ = path_ + ".tmp." + std::to_string(getpid());
        fd = ::open(temp_path_.c_str(), O_CREAT | O_TRUNC | O_WRONLY | O_CLOEXEC, 0666);
        if (fd >= 0) remove_on_signal(temp_path_);
    }
    if (fd < 0) fail("cannot create '%s': %s", path_.c_str(), std::strerror(errno));
    file_ = ::fdopen(fd, "wb");
    if (!file_) {
        int err = errno;
        ::close(fd);
        if (!temp_path_.empty()) {
            ::unlink(temp_path_.c_str());
            forget_on_signal(temp_path_);
        }
        fail("cannot create '%s': %s", path_.c_str(), std::strerror(err));
    }
}

AtomicFile::~AtomicFile() {
    if (!file_) return;  // committed
    std::fclose(file_);  // an anonymous file vanishes with its last descriptor
    if (!temp_path_.empty()) {
        ::unlink(temp_path_.c_str());
        forget_on_signal(temp_path_);
    }
}

void AtomicFile::write(const void* data, size_t size) {
    if (size == 0) return;
    if (std::fwrite(data, 1, size, file_) != size) fail("cannot write '%s': %s", path_.c_str(), std::strerror(errno));
    size_ += size;
}

void AtomicFile::commit() {
    if (std::fflush(file_) != 0 || fsync(fileno(file_)) != 0)
        fail("cannot write '%s': %s", path_.c_str(), std::strerror(errno));
    if (temp_path_.empty()) {
        // Give the anonymous file a name: directly when the path is free, else under a temporary
        // name renamed over the old file (linkat cannot replace), so readers see the old or the
        // new file, never a partial one.
        std::string self = "/proc/self/fd/" + std::to_string(fileno(file_));
        if (::linkat(AT_FDCWD, self.c_str(), AT_FDCWD, path_.c_str(), AT_SYMLINK_FOLLOW) != 0) {
            if (errno != EEXIST) fail("cannot write '%s': %s", path_.c_str(), std::strerror(errno));
            std::string temp = path_ + ".tmp." + std::to_string(getpid());
            ::unlink(temp.c_str());
            remove_on_signal(temp);
            int linked = ::linkat(AT_FDCWD, self.c_str(), AT_FDCWD, temp.c_str(), AT_SYMLINK_FOLLOW);
            int err = errno;
            if (linked == 0 && std::rename(temp.c_str(), path_.c_str()) != 0) {
                err = errno;
                ::unlink(temp.c_str());
                linked = -1;
            }
            forget_on_signal(temp);
            if (linked != 0) fail("cannot write '%s': %s", path_.c_str(), std::strerror(err));
        }
    } else if (std::rename(temp_path_.c_str(), path_.c_str()) != 0) {
        fail("cannot write '%s': %s", path_.c_str(), std::strerror(errno));  // the destructor removes it
    } else {
        forget_on_signal(temp_path_);
        temp_path_.clear();
    }
    int closed = std::fclose(file_);
    file_ = nullptr;
    if (closed != 0) fail("cannot write '%s': %s", path_.c_str(), std::strerror(errno));
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
