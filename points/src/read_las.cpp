// LAS 1.0-1.4 reader and a LAS writer for tests (points/point_cloud.h). The layout follows the
// ASPRS LAS specifications 1.2 and 1.4 R15: a public header block, variable length records,
// then fixed-size point records whose first 12 bytes are X, Y, Z as int32 (coordinate =
// integer * scale + offset) and whose RGB, where the format has it, is three uint16. Records
// are read with pread in blocks of about 1 MiB, batch by batch (point_source.h).
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "base/atomic_file.h"
#include "base/bytes.h"
#include "base/error.h"
#include "point_source.h"
#include "points/point_cloud.h"

namespace catpaq {
namespace {

using ull = unsigned long long;

constexpr size_t kHeader12 = 227;  // LAS 1.0-1.2 public header
constexpr size_t kHeader14 = 375;  // LAS 1.4 public header
// Minimum record size of point formats 0..10, and where their RGB starts (0: no colour).
constexpr uint16_t kRecordSize[11] = {20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67};
constexpr uint16_t kRgbOffset[11] = {0, 0, 20, 28, 0, 28, 0, 30, 30, 0, 30};

class File {
public:
    explicit File(const std::string& path) : path_(path) {
        fd_ = ::open(path.c_str(), O_RDONLY);
        if (fd_ < 0) fail("cannot open '%s': %s", path.c_str(), std::strerror(errno));
        struct stat st {};
        if (fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
            ::close(fd_);
            fail("'%s' is not a regular file", path.c_str());
        }
        size_ = uint64_t(st.st_size);
    }
    ~File() { ::close(fd_); }
    uint64_t size() const { return size_; }
    void read(uint64_t offset, void* out, size_t n) const {
        uint8_t* p = static_cast<uint8_t*>(out);
        while (n > 0) {
            ssize_t got = ::pread(fd_, p, n, off_t(offset));
            if (got < 0 && errno == EINTR) continue;
            if (got <= 0) fail("cannot read '%s': %s", path_.c_str(), got < 0 ? std::strerror(errno) : "unexpected end");
            p += got;
            n -= size_t(got);
            offset += uint64_t(got);
        }
    }

private:
    std::string path_;
    int fd_ = -1;
    uint64_t size_ = 0;
};

struct LasHeader {
    int major = 0, minor = 0;
    uint16_t header_size = 0;
    uint32_t point_offset = 0;
    int format = 0;
    uint16_t record_size = 0;
    uint64_t count = 0;
    double scale[3], offset[3];
};

LasHeader parse_header(const File& file, const std::string& path) {
    if (file.size() == 0) fail("'%s': empty file (no points)", path.c_str());
    if (file.size() < kHeader12) fail("'%s': not a LAS file (too short for a LAS header)", path.c_str());
    uint8_t raw[kHeader14] = {};
    file.read(0, raw, std::min<uint64_t>(file.size(), kHeader14));
    if (std::memcmp(raw, "LASF", 4) != 0) fail("'%s': not a LAS file (no 'LASF' signature)", path.c_str());
    LasHeader h;
    ByteReader r(raw, sizeof raw);
    r.take(24);
    h.major = r.u8();
    h.minor = r.u8();
    if (h.major != 1 || h.minor > 4) fail("'%s': unsupported LAS version %d.%d (this reader reads 1.0-1.4)", path.c_str(), h.major, h.minor);
    r.take(64 + 4);
    h.header_size = r.u16();
    h.point_offset = r.u32();
    r.u32();  // number of variable length records
    uint8_t format = r.u8();
    h.record_size = r.u16();
    uint32_t legacy_count = r.u32();
    r.take(20);
    for (double& s : h.scale) s = r.f64();
    for (double& o : h.offset) o = r.f64();
    if (format & 0xc0)
        fail("'%s': compressed LAS (LAZ, point format %u): no LAZ decoder is available; decompress it first "
             "(e.g. laszip -i in.laz -o out.las)", path.c_str(), format);
    if (format > 10) fail("'%s': unknown LAS point format %u", path.c_str(), format);
    h.format = format;
    if (h.header_size < kHeader12 || h.point_offset < h.header_size)
        fail("'%s': corrupt LAS header (header size %u, point data offset %u)", path.c_str(), h.header_size, h.point_offset);
    if (h.record_size < kRecordSize[format])
        fail("'%s': LAS point format %d needs records of at least %u bytes, the header says %u", path.c_str(), format,
             kRecordSize[format], h.record_size);
    h.count = legacy_count;
    if (h.minor >= 4 && h.header_size >= kHeader14) {
        ByteReader r14(raw + 247, 8);
        uint64_t count14 = r14.u64();
        if (count14 != 0) h.count = count14;
    }
    for (int a = 0; a < 3; ++a)
        if (!std::isfinite(h.scale[a]) || h.scale[a] == 0 || !std::isfinite(h.offset[a]))
            fail("'%s': corrupt LAS header (scale %g, offset %g on axis %c)", path.c_str(), h.scale[a], h.offset[a], "xyz"[a]);
    return h;
}

// The point records in file order. Whether colours are scaled from 16 to 8 bits depends on every
// record (files whose colours all fit in 0..255 keep them as is), so the constructor reads the
// RGB fields of all records first, block by block; the batches then read the records again.
class LasSource final : public PointSource {
public:
    explicit LasSource(const std::string& path) : PointSource(path), file_(path), header_(parse_header(file_, path)) {
        const LasHeader& h = header_;
        if (h.count == 0) fail("'%s': the LAS header counts no points", path.c_str());
        const uint64_t available = file_.size() > h.point_offset ? (file_.size() - h.point_offset) / h.record_size : 0;
        if (available < h.count)
            fail("'%s': truncated: the LAS header says %llu points, the file holds %llu", path.c_str(), ull(h.count), ull(available));
        block_records_ = std::max<size_t>(1, kBlockBytes / h.record_size);
        rgb_at_ = kRgbOffset[h.format];
        const uint16_t largest_rgb = rgb_at_ ? largest_color() : 0;
        colors = largest_rgb > 0;  // all black: treated as absent
        shift_ = largest_rgb > 255 ? 8 : 0;
        expected = h.count;
        info.format = strprintf("LAS %d.%d format %d", h.major, h.minor, h.format);
        info.z_up = true;
        info.dropped.push_back("intensity, classification, returns and other LAS attributes (not kept)");
        if (rgb_at_ && largest_rgb == 0) info.dropped.push_back("colours (all black: treated as absent)");
    }

    size_t read(PointCloud& batch, size_t max) override {
        const LasHeader& h = header_;
        const size_t n = size_t(std::min<uint64_t>(max, h.count - next_));
        for (size_t done = 0; done < n;) {
            const size_t k = read_block(next_, n - done);
            for (size_t i = 0; i < k; ++i) {
                const uint8_t* record = buffer_.data() + i * h.record_size;
                ByteReader r(record, h.record_size);
                Vec3d p;
                for (int a = 0; a < 3; ++a) p[a] = double(int32_t(r.u32())) * h.scale[a] + h.offset[a];
                if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]))
                    fail("'%s': point %llu has a non-finite coordinate", path().c_str(), ull(next_ + i));
                batch.positions.push_back(p);
                if (colors) {
                    ByteReader c(record + rgb_at_, 6);
                    Rgb8 color;
                    for (int channel = 0; channel < 3; ++channel) color[channel] = uint8_t(c.u16() >> shift_);
                    batch.colors.push_back(color);
                }
            }
            done += k;
            next_ += k;
        }
        return n;
    }

private:
    static constexpr size_t kBlockBytes = size_t(1) << 20;

    // Reads up to `max` records from record `first` into the buffer (at most one block); returns
    // how many.
    size_t read_block(uint64_t first, size_t max) {
        const size_t k = std::min(max, block_records_);
        buffer_.resize(k * header_.record_size);
        file_.read(header_.point_offset + first * header_.record_size, buffer_.data(), buffer_.size());
        return k;
    }

    // The pre-scan: the largest 16-bit colour component of all records.
    uint16_t largest_color() {
        uint16_t largest = 0;
        for (uint64_t first = 0; first < header_.count;) {
            const size_t k = read_block(first, size_t(std::min<uint64_t>(block_records_, header_.count - first)));
            for (size_t i = 0; i < k; ++i) {
                ByteReader c(buffer_.data() + i * header_.record_size + rgb_at_, 6);
                for (int channel = 0; channel < 3; ++channel) largest = std::max(largest, c.u16());
            }
            first += k;
        }
        return largest;
    }

    File file_;
    LasHeader header_;
    size_t block_records_ = 1;
    uint16_t rgb_at_ = 0;  // where a record's RGB starts, 0 if the format has none
    int shift_ = 0;        // 8 to scale 16-bit colours to 8 bits, 0 to keep 8-bit ones
    uint64_t next_ = 0;    // the next record to hand out
    std::vector<uint8_t> buffer_;
};

}  // namespace

std::unique_ptr<PointSource> open_las_source(const std::string& path) { return std::make_unique<LasSource>(path); }

PointCloud read_las(const std::string& path, PointReadInfo* info) {
    PointFileReader reader(open_las_source(path));
    return read_whole_file(reader, info);
}

void write_las(const std::string& path, const PointCloud& cloud, int point_format, double scale) {
    if (!((point_format >= 0 && point_format <= 3) || (point_format >= 6 && point_format <= 8)))
        fail("write_las: point format %d is not supported (0-3, 6-8)", point_format);
    if (cloud.positions.empty()) fail("write_las: no points");
    const bool v14 = point_format >= 6;
    const uint16_t header_size = v14 ? kHeader14 : kHeader12;
    const uint16_t record_size = kRecordSize[point_format];
    Bounds bounds = cloud.bounds();
    ByteWriter w;
    w.raw("LASF", 4);
    w.u16(0);
    w.u16(v14 ? (1u << 4) : 0);  // global encoding: formats 6+ use WKT coordinate systems
    for (int i = 0; i < 16; ++i) w.u8(0);
    w.u8(1);
    w.u8(v14 ? 4 : 2);
    char name[32] = {};
    std::memcpy(name, "catpaq", 6);
    w.raw(name, 32);
    std::memcpy(name, "catpaq write_las", 16);
    w.raw(name, 32);
    w.u16(1);
    w.u16(2024);
    w.u16(header_size);
    w.u32(header_size);  // no variable length records
    w.u32(0);
    w.u8(uint8_t(point_format));
    w.u16(record_size);
    const uint64_t n = cloud.positions.size();
    w.u32(v14 ? 0 : uint32_t(n));
    w.u32(v14 ? 0 : uint32_t(n));
    for (int i = 0; i < 4; ++i) w.u32(0);
    for (int a = 0; a < 3; ++a) w.f64(scale);
    for (int a = 0; a < 3; ++a) w.f64(bounds.min[a]);
    for (int a = 0; a < 3; ++a) {
        w.f64(bounds.max[a]);
        w.f64(bounds.min[a]);
    }
    if (v14) {
        w.u64(0);  // waveform data
        w.u64(0);  // first extended VLR
        w.u32(0);
        w.u64(n);
        w.u64(n);
        for (int i = 0; i < 14; ++i) w.u64(0);
    }
    if (w.size() != header_size) fail("write_las: internal header size mismatch");
    for (size_t i = 0; i < n; ++i) {
        const size_t start = w.size();
        for (int a = 0; a < 3; ++a) {
            double t = std::nearbyint((cloud.positions[i][a] - bounds.min[a]) / scale);
            if (!(t >= INT32_MIN && t <= INT32_MAX)) fail("write_las: coordinate out of range for scale %g", scale);
            w.u32(uint32_t(int32_t(t)));
        }
        w.u16(0);                       // intensity
        w.u8(v14 ? 0x11 : 0x09);        // return 1 of 1
        if (v14) w.u8(0);               // classification flags
        w.u8(1);                        // classification: unclassified
        if (v14) {
            w.u8(0);                    // user data
            w.u16(0);                   // scan angle
        } else {
            w.u8(0);                    // scan angle rank
            w.u8(0);                    // user data
        }
        w.u16(0);                       // point source id
        if (point_format == 1 || point_format == 3 || v14) w.f64(double(i));  // GPS time
        if (kRgbOffset[point_format]) {
            for (int k = 0; k < 3; ++k) w.u16(cloud.colors.empty() ? 0 : uint16_t(cloud.colors[i][k] * 257));
        }
        if (point_format == 8) w.u16(0);  // near infrared
        if (w.size() - start != record_size) fail("write_las: internal record size mismatch");
    }
    write_file_atomic(path, w.bytes().data(), w.size());
}

}  // namespace catpaq
