#pragma once
// 64-bit content checksum (XXH3) used by every on-disk and on-wire chunk.
#include <cstddef>
#include <cstdint>

namespace catpaq {

uint64_t checksum64(const void* data, size_t size);

}  // namespace catpaq
