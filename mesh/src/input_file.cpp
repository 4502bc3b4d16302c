#include "input_file.h"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "base/error.h"

namespace catpaq::mesh_io {
namespace {

constexpr size_t kBufferSize = size_t(4) << 20;  // large reads keep the binary path at disk speed
constexpr size_t kMaxLine = size_t(64) << 20;    // a longer "line" is a binary file read as text

std::string vformat(const char* format, va_list args) {
    va_list copy;
    va_copy(copy, args);
    int n = std::vsnprintf(nullptr, 0, format, copy);
    va_end(copy);
    std::string out(n > 0 ? size_t(n) : 0, '\0');
    if (n > 0) std::vsnprintf(out.data(), out.size() + 1, format, args);
    return out;
}

bool is_ascii_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v'; }

}  // namespace

InputFile::InputFile(std::string path) : path_(std::move(path)) {
    fd_ = ::open(path_.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) fail("cannot open: %s", std::strerror(errno));
    struct stat st;
    if (::fstat(fd_, &st) != 0) fail("cannot stat: %s", std::strerror(errno));
    if (S_ISDIR(st.st_mode)) fail("is a directory, not a mesh file");
    if (!S_ISREG(st.st_mode)) fail("not a regular file");
    size_ = uint64_t(st.st_size);
    // Small files get a small buffer: tests and tools open many of them.
    buffer_.resize(size_t(std::clamp<uint64_t>(size_ + 1, 4096, kBufferSize)));
    pos_ = end_ = buffer_.data();
}

InputFile::~InputFile() {
    if (fd_ >= 0) ::close(fd_);
}

bool InputFile::refill(size_t wanted) {
    size_t have = available();
    // Move the unconsumed tail to the front so the buffer never needs to exceed `wanted`.
    if (pos_ != buffer_.data()) std::memmove(buffer_.data(), pos_, have);
    if (buffer_.size() < wanted) buffer_.resize(std::max(wanted, buffer_.size() * 2));
    pos_ = buffer_.data();
    end_ = pos_ + have;
    while (!eof_ && size_t(end_ - pos_) < buffer_.size()) {
        ssize_t n = ::read(fd_, end_, buffer_.size() - size_t(end_ - pos_));
        if (n < 0) {
            if (errno == EINTR) continue;
            fail("read error: %s", std::strerror(errno));
        }
        if (n == 0) eof_ = true;
        end_ += n;
        if (size_t(end_ - pos_) >= wanted && size_t(end_ - pos_) >= buffer_.size() / 2) break;
    }
    return size_t(end_ - pos_) >= wanted;
}

bool InputFile::next_line(std::string_view& line) {
    size_t scanned = 0;
    for (;;) {
        const char* newline = static_cast<const char*>(std::memchr(pos_ + scanned, '\n', available() - scanned));
        if (newline || eof_) {
            // Without a newline at end of file, the rest of the file is the last line.
            if (!newline && available() == 0) return false;
            size_t length = newline ? size_t(newline - pos_) : available();
            line = std::string_view(pos_, length);
            if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
            consume(newline ? length + 1 : length);
            ++line_;
            return true;
        }
        scanned = available();
        if (scanned >= kMaxLine) {
            size_t next = line_ + 1;
            fail("line %zu: line longer than %zu MB (binary data in a text file?)", next, kMaxLine >> 20);
        }
        refill(scanned + 1);
    }
}

uint64_t InputFile::skip(uint64_t n) {
    uint64_t skipped = 0;
    while (skipped < n) {
        if (available() == 0 && !refill(1)) break;
        size_t take = size_t(std::min<uint64_t>(n - skipped, available()));
        consume(take);
        skipped += take;
    }
    return skipped;
}

bool InputFile::only_whitespace_left() {
    for (;;) {
        if (available() == 0 && !refill(1)) return true;
        for (const char* p = pos_; p < end_; ++p)
            if (!is_ascii_space(*p)) return false;
        consume(available());
    }
}

void InputFile::fail(const char* format, ...) const {
    va_list args;
    va_start(args, format);
    std::string message = vformat(format, args);
    va_end(args);
    throw Error("'" + path_ + "': " + message);
}

void InputFile::fail_line(const char* format, ...) const {
    va_list args;
    va_start(args, format);
    std::string message = vformat(format, args);
    va_end(args);
    throw Error("'" + path_ + "' line " + std::to_string(line_) + ": " + message);
}

void advise_huge_pages(void* data, size_t bytes) {
    constexpr uintptr_t kHuge = uintptr_t(2) << 20;
    uintptr_t begin = (reinterpret_cast<uintptr_t>(data) + kHuge - 1) & ~(kHuge - 1);
    uintptr_t end = (reinterpret_cast<uintptr_t>(data) + bytes) & ~(kHuge - 1);
    if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);  // a hint: errors are fine
}

}  // namespace catpaq::mesh_io
