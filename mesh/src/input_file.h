#pragma once
// Private to the mesh module: a sequential reader over one file with a large buffer, serving
// both whole lines (text formats, headers) and raw byte runs (binary bodies) from the same
// position, so a PLY header and its binary body are read through one buffer. All errors name
// the file ("'path': ...", or "'path' line N: ..." for text).
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace catpaq::mesh_io {

class InputFile {
public:
    // Opens `path` for reading; throws Error if it does not exist, is a directory or unreadable.
    explicit InputFile(std::string path);
    ~InputFile();
    InputFile(const InputFile&) = delete;
    InputFile& operator=(const InputFile&) = delete;

    const std::string& path() const { return path_; }
    uint64_t size() const { return size_; }  // file size at open time
    // Bytes not yet consumed (from the current position to the end of the file).
    uint64_t remaining() const { return size_ - consumed_; }

    // Text: the next line without its terminator ("\n" or "\r\n"); false at end of file.
    // The view stays valid until the next call. Lines longer than 64 MB are an error.
    bool next_line(std::string_view& line);
    // Number of the line last returned by next_line (1-based), for error messages.
    size_t line_number() const { return line_; }

    // Binary: makes `n` bytes available at data() and returns true, or returns false when the
    // file ends first. `n` must be moderate (the buffer grows to hold it).
    bool ensure(size_t n) {
        if (size_t(end_ - pos_) >= n) return true;
        return refill(n);
    }
    const char* data() const { return pos_; }
    size_t available() const { return size_t(end_ - pos_); }
    void consume(size_t n) {  // after ensure(n)
        pos_ += n;
        consumed_ += n;
    }
    // Skips up to `n` bytes and returns how many were skipped (fewer only at end of file).
    uint64_t skip(uint64_t n);
    // True if everything left in the file is ASCII whitespace (or nothing is left).
    bool only_whitespace_left();

    // Throw Error with "'path': " (or "'path' line N: ") prepended to the printf message.
    [[noreturn]] void fail(const char* format, ...) const __attribute__((format(printf, 2, 3)));
    [[noreturn]] void fail_line(const char* format, ...) const __attribute__((format(printf, 2, 3)));

private:
    bool refill(size_t wanted);

    std::string path_;
    int fd_ = -1;
    uint64_t size_ = 0, consumed_ = 0;
    std::vector<char> buffer_;
    char* pos_ = nullptr;
    char* end_ = nullptr;
    bool eof_ = false;
    size_t line_ = 0;
};

}  // namespace catpaq::mesh_io
