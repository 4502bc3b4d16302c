#pragma once
// Lossless PNG images of data (not pictures) through libpng's low-level API: 1 to 4 channels
// (gray, gray + alpha, RGB, RGBA) of 8 or 16 bits, no gamma, no colour management, and no
// premultiplied alpha (the simplified png_image API premultiplies 16-bit alpha; this never does),
// so decode(encode(x)) == x bit for bit. 16-bit samples are big-endian in the file, as PNG says.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace catpaq::aqp {

struct PngImage {
    int width = 0, height = 0;
    int channels = 1;   // 1 to 4
    int bit_depth = 8;  // 8 or 16
    std::vector<uint16_t> values;  // row-major, channels interleaved; each < 2^bit_depth

    size_t value_count() const { return size_t(width) * size_t(height) * size_t(channels); }
};

// Encodes `image` (caller bug if its fields are inconsistent). `compression` is zlib's level
// (0-9). `adaptive_filters`: libpng's heuristic over all five row filters; false: no filter
// (for data that is already a prediction residual, where the heuristic's picks cost bytes).
// Throws Error if libpng fails.
std::vector<uint8_t> png_encode(const PngImage& image, int compression = 6, bool adaptive_filters = true);

// Decodes PNG bytes, which must hold exactly the expected size, channels and bit depth (a data
// image of another shape is an error, not something to convert). Safe on untrusted bytes: returns
// an empty string on success, else what is wrong (bad signature, truncated, corrupt, other shape).
std::string png_decode(const uint8_t* data, size_t size, int width, int height, int channels, int bit_depth,
                       PngImage& out);

}  // namespace catpaq::aqp
