#pragma once
// PNG output of rendered frames (libpng), and reading PNGs back for tests.
#include <cstdint>
#include <string>
#include <vector>

namespace catpaq {

struct RgbaImage {
    int width = 0, height = 0;
    std::vector<uint8_t> rgba;  // width * height * 4 bytes, rows top-down
};

// Writes an 8-bit RGBA PNG atomically (temporary file in the same directory, then rename).
// `rgba` holds width * height * 4 bytes, rows top-down. Throws Error naming the file.
void write_png(const std::string& path, int width, int height, const std::vector<uint8_t>& rgba);
// Reads any PNG libpng understands, converted to 8-bit RGBA. Throws Error naming the file.
RgbaImage read_png(const std::string& path);

}  // namespace catpaq
