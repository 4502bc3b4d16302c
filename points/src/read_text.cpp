// XYZ and PTS text point files (points/point_cloud.h): streamed line by line through a buffer of
// a few MiB, batch by batch (point_source.h).
#include <charconv>
#include <cmath>
#include <cstring>
#include <fcntl.h>
#include <string_view>
#include <sys/stat.h>
#include <unistd.h>

#include "base/error.h"
#include "point_source.h"
#include "points/point_cloud.h"

namespace catpaq {
namespace {

using ull = unsigned long long;

// Reads a text file in large chunks and hands out its lines (without "\n" or "\r\n").
class LineReader {
public:
    explicit LineReader(std::string path) : path_(std::move(path)) {
        fd_ = ::open(path_.c_str(), O_RDONLY);
        if (fd_ < 0) fail("cannot open '%s': %s", path_.c_str(), std::strerror(errno));
        struct stat st {};
        if (fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
            ::close(fd_);
            fail("'%s' is not a regular file", path_.c_str());
        }
        size_ = uint64_t(st.st_size);
    }
    ~LineReader() { ::close(fd_); }
    LineReader(const LineReader&) = delete;
    LineReader& operator=(const LineReader&) = delete;

    uint64_t size() const { return size_; }
    size_t line_number() const { return line_; }
    const std::string& path() const { return path_; }

    bool next(std::string_view& line) {
        for (;;) {
            const char* newline =
                end_ > begin_ ? static_cast<const char*>(std::memchr(buffer_.data() + begin_, '\n', end_ - begin_)) : nullptr;
            if (newline || eof_) {
                if (!newline && begin_ == end_) return false;
                size_t stop = newline ? size_t(newline - buffer_.data()) : end_;
                line = std::string_view(buffer_.data() + begin_, stop - begin_);
                if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
                begin_ = newline ? stop + 1 : stop;
                ++line_;
                return true;
            }
            refill();
        }
    }

    [[noreturn]] void fail_line(const std::string& problem) const {
        fail("'%s' line %zu: %s", path_.c_str(), line_, problem.c_str());
    }

private:
    void refill() {
        if (end_ > begin_) std::memmove(buffer_.data(), buffer_.data() + begin_, end_ - begin_);
        end_ -= begin_;
        begin_ = 0;
        if (buffer_.size() - end_ < kChunk) {
            if (buffer_.size() >= kMaxLine) fail("'%s' line %zu: line too long", path_.c_str(), line_ + 1);
            buffer_.resize(std::max(buffer_.size() * 2, kChunk * 2));
        }
        ssize_t got = ::read(fd_, buffer_.data() + end_, buffer_.size() - end_);
        if (got < 0) fail("cannot read '%s': %s", path_.c_str(), std::strerror(errno));
        if (got == 0) eof_ = true;
        end_ += size_t(got);
    }

    static constexpr size_t kChunk = size_t(1) << 22;
    static constexpr size_t kMaxLine = size_t(1) << 26;
    std::string path_;
    int fd_ = -1;
    uint64_t size_ = 0;
    std::vector<char> buffer_;
    size_t begin_ = 0, end_ = 0, line_ = 0;
    bool eof_ = false;
};

bool is_blank(char c) { return c == ' ' || c == '\t' || c == ',' || c == ';' || c == '\r'; }

// Splits a line into at most `max` numbers; returns how many, or max + 1 if there are more.
// Fails (naming the token) on anything that is not a number.
size_t parse_numbers(const LineReader& file, std::string_view line, double* out, size_t max) {
    size_t count = 0, i = 0;
    for (;;) {
        while (i < line.size() && is_blank(line[i])) ++i;
        if (i == line.size()) return count;
        size_t j = i;
        while (j < line.size() && !is_blank(line[j])) ++j;
        if (count == max) return max + 1;
        std::string_view token = line.substr(i, j - i);
        if (token.front() == '+') token.remove_prefix(1);
        double value = 0;
        auto [end, error] = std::from_chars(token.data(), token.data() + token.size(), value);
        if (error != std::errc() || end != token.data() + token.size() || token.empty())
            file.fail_line("expected a number, found '" + std::string(line.substr(i, std::min<size_t>(j - i, 40))) + "'");
        out[count++] = value;
        i = j;
    }
}

std::string_view strip_comment(std::string_view line) {
    size_t hash = line.find('#');
    if (hash != std::string_view::npos) line = line.substr(0, hash);
    return line;
}

bool only_blanks(std::string_view line) {
    for (char c : line)
        if (!is_blank(c)) return false;
    return true;
}

// Reads point lines of 3, 4, 6 or 7 numbers (the first line fixes the layout, for every batch).
class PointLines {
public:
    PointLines(LineReader& file, PointReadInfo& info) : file_(file), info_(info) {}

    bool has_colors() const { return columns_ >= 6; }  // once the first point is read

    // Appends the point on `line` to the cloud (the line is not blank).
    void add(std::string_view line, PointCloud& cloud) {
        double v[8];
        size_t n = parse_numbers(file_, line, v, 7);
        if (columns_ == 0) {
            if (n != 3 && n != 4 && n != 6 && n != 7)
                file_.fail_line(strprintf("expected x y z [intensity] [r g b] (3, 4, 6 or 7 numbers), found %zu", n));
            columns_ = n;
            if (columns_ == 4 || columns_ == 7) info_.dropped.push_back("intensity (not kept)");
        } else if (n != columns_) {
            file_.fail_line(strprintf("expected %zu numbers like the first point, found %s", columns_,
                                      n > 7 ? "more than 7" : std::to_string(n).c_str()));
        }
        if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2]))
            file_.fail_line(strprintf("non-finite coordinate (%g, %g, %g)", v[0], v[1], v[2]));
        cloud.positions.push_back({v[0], v[1], v[2]});
        if (columns_ >= 6) {
            const double* rgb = v + (columns_ == 7 ? 4 : 3);
            Rgb8 color;
            for (int c = 0; c < 3; ++c) {
                if (!(rgb[c] >= 0 && rgb[c] <= 255 && rgb[c] == std::floor(rgb[c])))
                    file_.fail_line(strprintf("colour values must be integers 0..255, found %g", rgb[c]));
                color[c] = uint8_t(rgb[c]);
            }
            cloud.colors.push_back(color);
        }
    }

private:
    LineReader& file_;
    PointReadInfo& info_;
    size_t columns_ = 0;
};

// A text point file: the lines, the point layout, and the first point, which the constructor of
// each format reads ahead so that colours (6 or 7 columns) are known before the first batch.
class TextSource : public PointSource {
public:
    TextSource(const std::string& path, const char* format) : PointSource(path), file_(path), lines_(file_, info) {
        if (file_.size() == 0) fail("'%s': empty file (no points)", path.c_str());
        info.format = format;
    }

    size_t read(PointCloud& batch, size_t max) override {
        size_t n = 0;
        if (!first_.positions.empty()) {
            batch.positions.push_back(first_.positions[0]);
            if (colors) batch.colors.push_back(first_.colors[0]);
            first_ = {};
            n = 1;
        }
        if (n < max && !exhausted_) {
            const size_t more = read_lines(batch, max - n);
            exhausted_ = more < max - n;  // only the end of the file stops a read short
            n += more;
        }
        return n;
    }

protected:
    // Appends up to `max` points from the lines that follow; fewer only at the end of the file,
    // after the format's end-of-file checks.
    virtual size_t read_lines(PointCloud& batch, size_t max) = 0;

    // The derived constructor's last step: reads the first point (or, in a file with none, runs
    // the end-of-file checks, which throw).
    void read_first_point() {
        exhausted_ = read_lines(first_, 1) == 0;
        colors = lines_.has_colors();
    }

    // The next line that holds something: comments stripped, blank lines skipped.
    bool next_content_line(std::string_view& line) {
        while (file_.next(line)) {
            line = strip_comment(line);
            if (!only_blanks(line)) return true;
        }
        return false;
    }

    LineReader file_;
    PointLines lines_;

private:
    PointCloud first_;  // the point read ahead, until the first batch takes it
    bool exhausted_ = false;
};

class XyzSource final : public TextSource {
public:
    explicit XyzSource(const std::string& path) : TextSource(path, "XYZ") { read_first_point(); }

private:
    size_t read_lines(PointCloud& batch, size_t max) override {
        size_t n = 0;
        std::string_view line;
        while (n < max && next_content_line(line)) {
            lines_.add(line, batch);
            ++n;
            ++seen_;
        }
        if (n < max && seen_ == 0) fail("'%s': no points (only blank or comment lines)", path().c_str());
        return n;
    }

    uint64_t seen_ = 0;
};

// PTS: a count line, then that many point lines, possibly several times; the scan being read
// carries over from one batch to the next.
class PtsSource final : public TextSource {
public:
    explicit PtsSource(const std::string& path) : TextSource(path, "PTS") { read_first_point(); }

private:
    size_t read_lines(PointCloud& batch, size_t max) override {
        size_t n = 0;
        std::string_view line;
        while (n < max && next_content_line(line)) {
            if (!have_count_ || seen_ == expected_) {
                read_count(line);
                continue;
            }
            lines_.add(line, batch);
            ++n;
            ++seen_;
            ++total_;
        }
        if (n < max) check_end();
        return n;
    }

    // The line that starts a scan: its point count, or an error if the previous scan is full.
    void read_count(std::string_view line) {
        double v[2];
        if (parse_numbers(file_, line, v, 1) != 1 || !(v[0] >= 0) || v[0] != std::floor(v[0]) || v[0] > 1e15) {
            if (!have_count_) file_.fail_line("expected the point count (PTS starts with a count line)");
            file_.fail_line(strprintf("more points than the count on line %zu says (%llu)", count_line_, ull(expected_)));
        }
        expected_ = uint64_t(v[0]);
        seen_ = 0;
        count_line_ = file_.line_number();
        have_count_ = true;
    }

    void check_end() const {
        const char* name = path().c_str();
        if (!have_count_) fail("'%s': no point count (only blank or comment lines)", name);
        if (seen_ != expected_)
            fail("'%s': truncated: line %zu counts %llu points but the file holds %llu", name, count_line_,
                 ull(expected_), ull(seen_));
        if (total_ == 0) fail("'%s': no points (the counts are zero)", name);
    }

    uint64_t expected_ = 0, seen_ = 0;  // of the current scan
    uint64_t total_ = 0;
    size_t count_line_ = 0;
    bool have_count_ = false;
};

}  // namespace

std::unique_ptr<PointSource> open_xyz_source(const std::string& path) { return std::make_unique<XyzSource>(path); }
std::unique_ptr<PointSource> open_pts_source(const std::string& path) { return std::make_unique<PtsSource>(path); }

PointCloud read_xyz(const std::string& path, PointReadInfo* info) {
    PointFileReader reader(open_xyz_source(path));
    return read_whole_file(reader, info);
}

PointCloud read_pts(const std::string& path, PointReadInfo* info) {
    PointFileReader reader(open_pts_source(path));
    return read_whole_file(reader, info);
}

}  // namespace catpaq
