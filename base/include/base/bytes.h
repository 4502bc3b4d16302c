#pragma once
// Little-endian byte buffers: ByteWriter appends fixed-width fields and varints;
// ByteReader parses them from (pointer, size) with bounds checks and never reads past
// the end (it sets a sticky failure flag instead), so untrusted bytes are safe to parse.
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace catpaq {

// Signed values for varints: 0, -1, 1, -2, ... -> 0, 1, 2, 3, ...
inline uint64_t zigzag64(int64_t v) { return (uint64_t(v) << 1) ^ uint64_t(v >> 63); }
inline int64_t unzigzag64(uint64_t z) { return int64_t(z >> 1) ^ -int64_t(z & 1); }

class ByteWriter {
public:
    std::vector<uint8_t>& bytes() { return bytes_; }
    const std::vector<uint8_t>& bytes() const { return bytes_; }
    size_t size() const { return bytes_.size(); }

    void u8(uint8_t v) { bytes_.push_back(v); }
    void u16(uint16_t v) { put(v, 2); }
    void u32(uint32_t v) { put(v, 4); }
    void u64(uint64_t v) { put(v, 8); }
    void f32(float v) { uint32_t u; std::memcpy(&u, &v, 4); u32(u); }
    void f64(double v) { uint64_t u; std::memcpy(&u, &v, 8); u64(u); }
    void varint(uint64_t v) {
        while (v >= 0x80) { bytes_.push_back(uint8_t(v | 0x80)); v >>= 7; }
        bytes_.push_back(uint8_t(v));
    }
    void raw(const void* data, size_t size) {
        const uint8_t* p = static_cast<const uint8_t*>(data);
        bytes_.insert(bytes_.end(), p, p + size);
    }
    // Overwrites a previously written u32/u64 at byte offset `at`.
    void patch_u32(size_t at, uint32_t v) { for (int i = 0; i < 4; ++i) bytes_[at + i] = uint8_t(v >> (8 * i)); }
    void patch_u64(size_t at, uint64_t v) { for (int i = 0; i < 8; ++i) bytes_[at + i] = uint8_t(v >> (8 * i)); }

private:
    void put(uint64_t v, int n) { for (int i = 0; i < n; ++i) bytes_.push_back(uint8_t(v >> (8 * i))); }
    std::vector<uint8_t> bytes_;
};

class ByteReader {
public:
    ByteReader(const void* data, size_t size) : p_(static_cast<const uint8_t*>(data)), end_(p_ + size) {}

    bool ok() const { return ok_; }
    size_t remaining() const { return size_t(end_ - p_); }
    const uint8_t* cursor() const { return p_; }

    uint8_t u8() { return uint8_t(get(1)); }
    uint16_t u16() { return uint16_t(get(2)); }
    uint32_t u32() { return uint32_t(get(4)); }
    uint64_t u64() { return get(8); }
    float f32() { uint32_t u = u32(); float v; std::memcpy(&v, &u, 4); return v; }
    double f64() { uint64_t u = u64(); double v; std::memcpy(&v, &u, 8); return v; }
    uint64_t varint() {
        uint64_t v = 0;
        for (int shift = 0; shift < 64; shift += 7) {
            if (p_ >= end_) return fail();
            uint8_t b = *p_++;
            v |= uint64_t(b & 0x7f) << shift;
            if (!(b & 0x80)) return v;
        }
        return fail();
    }
    // Returns a pointer to the next `size` bytes and skips them, or nullptr (and fails).
    const uint8_t* take(size_t size) {
        if (size > remaining()) { fail(); return nullptr; }
        const uint8_t* at = p_;
        p_ += size;
        return at;
    }

private:
    uint64_t fail() { ok_ = false; p_ = end_; return 0; }
    uint64_t get(int n) {
        if (remaining() < size_t(n)) return fail();
        uint64_t v = 0;
        for (int i = 0; i < n; ++i) v |= uint64_t(p_[i]) << (8 * i);
        p_ += n;
        return v;
    }
    const uint8_t* p_;
    const uint8_t* end_;
    bool ok_ = true;
};

}  // namespace catpaq
