// PNG data images through libpng's low-level API (aqp/png_codec.h). libpng reports errors by
// longjmp: every function that calls it keeps only trivially destructible locals after setjmp,
// and the C++ buffers it fills live in the caller.
#include "aqp/png_codec.h"

#include <png.h>

#include <cassert>
#include <csetjmp>
#include <cstring>

#include "base/error.h"

namespace catpaq::aqp {
namespace {

struct PngContext {
    char message[160] = "";
    // Writing: the output. Reading: the input and a cursor.
    std::vector<uint8_t>* out = nullptr;
    const uint8_t* in = nullptr;
    size_t in_size = 0, in_at = 0;
    bool out_of_memory = false;
};

void on_error(png_structp png, png_const_charp message) {
    PngContext* c = static_cast<PngContext*>(png_get_error_ptr(png));
    std::snprintf(c->message, sizeof c->message, "%s", message);
    png_longjmp(png, 1);
}

void on_warning(png_structp, png_const_charp) {}

void write_bytes(png_structp png, png_bytep data, png_size_t size) {
    PngContext* c = static_cast<PngContext*>(png_get_io_ptr(png));
    try {
        c->out->insert(c->out->end(), data, data + size);
    } catch (...) {
        c->out_of_memory = true;
    }
    if (c->out_of_memory) png_error(png, "out of memory");
}

void flush_bytes(png_structp) {}

void read_bytes(png_structp png, png_bytep data, png_size_t size) {
    PngContext* c = static_cast<PngContext*>(png_get_io_ptr(png));
    if (size > c->in_size - c->in_at) png_error(png, "truncated");
    std::memcpy(data, c->in + c->in_at, size);
    c->in_at += size;
}

int color_type(int channels) {
    static const int kTypes[5] = {0, PNG_COLOR_TYPE_GRAY, PNG_COLOR_TYPE_GRAY_ALPHA, PNG_COLOR_TYPE_RGB,
                                  PNG_COLOR_TYPE_RGB_ALPHA};
    return kTypes[channels];
}

// Packs row y of `image` into `row` as PNG stores it (16-bit samples big-endian).
void pack_row(const PngImage& image, int y, uint8_t* row) {
    const size_t n = size_t(image.width) * image.channels;
    const uint16_t* v = image.values.data() + size_t(y) * n;
    if (image.bit_depth == 8) {
        for (size_t i = 0; i < n; ++i) row[i] = uint8_t(v[i]);
    } else {
        for (size_t i = 0; i < n; ++i) row[2 * i] = uint8_t(v[i] >> 8), row[2 * i + 1] = uint8_t(v[i]);
    }
}

void unpack_row(PngImage& image, int y, const uint8_t* row) {
    const size_t n = size_t(image.width) * image.channels;
    uint16_t* v = image.values.data() + size_t(y) * n;
    if (image.bit_depth == 8) {
        for (size_t i = 0; i < n; ++i) v[i] = row[i];
    } else {
        for (size_t i = 0; i < n; ++i) v[i] = uint16_t((row[2 * i] << 8) | row[2 * i + 1]);
    }
}

bool encode_rows(png_structp png, png_infop info, const PngImage& image, int compression, bool adaptive_filters,
                 uint8_t* row) {
    if (setjmp(png_jmpbuf(png))) return false;
    png_set_IHDR(png, info, png_uint_32(image.width), png_uint_32(image.height), image.bit_depth,
                 color_type(image.channels), PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_set_compression_level(png, compression);
    png_set_filter(png, PNG_FILTER_TYPE_BASE, adaptive_filters ? PNG_ALL_FILTERS : PNG_FILTER_NONE);
    png_write_info(png, info);
    for (int y = 0; y < image.height; ++y) {
        pack_row(image, y, row);
        png_write_row(png, row);
    }
    png_write_end(png, nullptr);
    return true;
}

bool decode_rows(png_structp png, png_infop info, PngImage& out, uint8_t* row, size_t row_bytes, bool& shape_ok) {
    if (setjmp(png_jmpbuf(png))) return false;
    png_read_info(png, info);
    png_uint_32 width = 0, height = 0;
    int depth = 0, type = 0, interlace = 0, compression = 0, filter = 0;
    png_get_IHDR(png, info, &width, &height, &depth, &type, &interlace, &compression, &filter);
    shape_ok = width == png_uint_32(out.width) && height == png_uint_32(out.height) && depth == out.bit_depth &&
               type == color_type(out.channels) && interlace == PNG_INTERLACE_NONE &&
               png_get_rowbytes(png, info) == row_bytes;
    if (!shape_ok) return false;
    for (int y = 0; y < out.height; ++y) {
        png_read_row(png, row, nullptr);
        unpack_row(out, y, row);
    }
    png_read_end(png, nullptr);
    return true;
}

}  // namespace

std::vector<uint8_t> png_encode(const PngImage& image, int compression, bool adaptive_filters) {
    assert(image.width > 0 && image.height > 0 && image.channels >= 1 && image.channels <= 4);
    assert(image.bit_depth == 8 || image.bit_depth == 16);
    assert(image.values.size() == image.value_count());
    std::vector<uint8_t> out;
    out.reserve(64 + image.value_count() * (image.bit_depth / 8) / 2);
    std::vector<uint8_t> row(size_t(image.width) * image.channels * (image.bit_depth / 8));
    PngContext context;
    context.out = &out;
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &context, on_error, on_warning);
    png_infop info = png ? png_create_info_struct(png) : nullptr;
    if (!png || !info) {
        png_destroy_write_struct(&png, &info);
        fail("PNG encoder: libpng could not start");
    }
    png_set_write_fn(png, &context, write_bytes, flush_bytes);
    const bool ok = encode_rows(png, info, image, compression, adaptive_filters, row.data());
    png_destroy_write_struct(&png, &info);
    if (!ok) fail("PNG encoder: %s", context.message);
    return out;
}

std::string png_decode(const uint8_t* data, size_t size, int width, int height, int channels, int bit_depth,
                       PngImage& out) {
    if (width <= 0 || height <= 0 || channels < 1 || channels > 4 || (bit_depth != 8 && bit_depth != 16))
        return "invalid image shape requested";
    if (size < 8 || png_sig_cmp(data, 0, 8) != 0) return "not a PNG (bad signature)";
    out.width = width;
    out.height = height;
    out.channels = channels;
    out.bit_depth = bit_depth;
    out.values.assign(out.value_count(), 0);
    const size_t row_bytes = size_t(width) * channels * (bit_depth / 8);
    std::vector<uint8_t> row(row_bytes);
    PngContext context;
    context.in = data;
    context.in_size = size;
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &context, on_error, on_warning);
    png_infop info = png ? png_create_info_struct(png) : nullptr;
    if (!png || !info) {
        png_destroy_read_struct(&png, &info, nullptr);
        return "PNG decoder: libpng could not start";
    }
    png_set_read_fn(png, &context, read_bytes);
    // Bound what a hostile header can make libpng allocate.
    png_set_user_limits(png, png_uint_32(width) + 1, png_uint_32(height) + 1);
    png_set_chunk_malloc_max(png, 1 << 20);
    bool shape_ok = true;
    const bool ok = decode_rows(png, info, out, row.data(), row_bytes, shape_ok);
    png_destroy_read_struct(&png, &info, nullptr);
    if (!shape_ok)
        return strprintf("PNG is not a %dx%d image of %d channels at %d bits", width, height, channels, bit_depth);
    if (!ok) return strprintf("corrupt PNG: %s", context.message);
    if (context.in_at != size) return strprintf("%zu bytes after the PNG's end", size - context.in_at);
    return "";
}

}  // namespace catpaq::aqp
