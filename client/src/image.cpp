// PNG via libpng's simplified API (no setjmp), written atomically.
#include "client/image.h"

#include <png.h>

#include <cstring>

#include "base/atomic_file.h"
#include "base/error.h"

namespace catpaq {

void write_png(const std::string& path, int width, int height, const std::vector<uint8_t>& rgba) {
    if (width <= 0 || height <= 0 || width > (1 << 20) || height > (1 << 20))
        fail("'%s': cannot write a %dx%d image", path.c_str(), width, height);
    if (rgba.size() != size_t(width) * size_t(height) * 4)
        fail("'%s': %zu bytes of pixels for a %dx%d RGBA image (expected %zu)", path.c_str(), rgba.size(), width, height,
             size_t(width) * size_t(height) * 4);
    png_image image;
    std::memset(&image, 0, sizeof image);
    image.version = PNG_IMAGE_VERSION;
    image.width = png_uint_32(width);
    image.height = png_uint_32(height);
    image.format = PNG_FORMAT_RGBA;
    png_alloc_size_t size = 0;
    // First call sizes the output, second writes it.
    if (!png_image_write_to_memory(&image, nullptr, &size, 0, rgba.data(), 0, nullptr))
        fail("'%s': libpng cannot encode the image: %s", path.c_str(), image.message);
    std::vector<uint8_t> bytes(size);
    if (!png_image_write_to_memory(&image, bytes.data(), &size, 0, rgba.data(), 0, nullptr))
        fail("'%s': libpng cannot encode the image: %s", path.c_str(), image.message);
    bytes.resize(size);
    write_file_atomic(path, bytes.data(), bytes.size());
}

RgbaImage read_png(const std::string& path) {
    std::string bytes = read_file(path);
    png_image image;
    std::memset(&image, 0, sizeof image);
    image.version = PNG_IMAGE_VERSION;
    if (!png_image_begin_read_from_memory(&image, bytes.data(), bytes.size()))
        fail("'%s' is not a readable PNG: %s", path.c_str(), image.message);
    image.format = PNG_FORMAT_RGBA;
    if (image.width == 0 || image.height == 0 || image.width > (1u << 16) || image.height > (1u << 16)) {
        png_image_free(&image);
        fail("'%s': PNG size %ux%u is out of range", path.c_str(), unsigned(image.width), unsigned(image.height));
    }
    RgbaImage out;
    out.width = int(image.width);
    out.height = int(image.height);
    out.rgba.resize(PNG_IMAGE_SIZE(image));
    if (!png_image_finish_read(&image, nullptr, out.rgba.data(), 0, nullptr)) {
        std::string message = image.message;
        png_image_free(&image);
        fail("'%s': cannot decode PNG: %s", path.c_str(), message.c_str());
    }
    return out;
}

}  // namespace catpaq
