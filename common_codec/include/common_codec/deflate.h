#pragma once
// One zlib stream (RFC 1950) in and out: what the packed archive index and AQP's packed
// metadata are stored as (zlib, which libpng needs anyway, is on every machine that decodes PNG).
#include <cstddef>
#include <cstdint>
#include <vector>

namespace catpaq {

// The bytes deflated at the best compression; throws Error if zlib fails.
std::vector<uint8_t> deflate_bytes(const std::vector<uint8_t>& in);
// Inflates exactly `size` bytes of one zlib stream into at most `limit` bytes (a corrupt or
// forged stream cannot make it allocate more); false when the stream is broken, does not end
// where the bytes do, or inflates to more.
bool inflate_bytes(const uint8_t* data, size_t size, size_t limit, std::vector<uint8_t>& out);
// Whether `deflated` bytes of a zlib stream can inflate to `inflated`: deflate packs at most
// about 1032 to 1. Readers refuse counts in a header that their stream cannot hold before
// allocating for them.
inline bool deflate_can_hold(uint64_t inflated, uint64_t deflated) { return inflated <= deflated * 1032 + 64; }

}  // namespace catpaq
