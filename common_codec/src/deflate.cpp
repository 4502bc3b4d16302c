#include "common_codec/deflate.h"

#include <zlib.h>

#include "base/error.h"

namespace catpaq {

std::vector<uint8_t> deflate_bytes(const std::vector<uint8_t>& in) {
    uLongf size = compressBound(uLong(in.size()));
    std::vector<uint8_t> out(size);
    if (compress2(out.data(), &size, in.data(), uLong(in.size()), Z_BEST_COMPRESSION) != Z_OK) fail("cannot deflate %zu bytes", in.size());
    out.resize(size);
    return out;
}

bool inflate_bytes(const uint8_t* data, size_t size, size_t limit, std::vector<uint8_t>& out) {
    out.resize(limit + 1);
    uLongf produced = uLongf(out.size());
    uLong consumed = uLong(size);
    if (uncompress2(out.data(), &produced, data, &consumed) != Z_OK || consumed != size || produced > limit) return false;
    out.resize(produced);
    return true;
}

}  // namespace catpaq
