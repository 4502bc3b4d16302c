#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <utility>

#include "base/large_buffer.h"

using namespace catpaq;

namespace {

// Whether every byte of [data, data + bytes) is zero.
bool all_zero(const std::byte* data, size_t bytes) {
    for (size_t i = 0; i < bytes; ++i)
        if (data[i] != std::byte{0}) return false;
    return true;
}

}  // namespace

// Small blocks come from the heap, large ones are mapped: both zero-filled, 64-byte aligned,
// writable end to end.
TEST(LargeBuffer, ZeroFilledAlignedAndWritableAtEverySize) {
    for (size_t bytes : {size_t(1), size_t(4096), size_t(1) << 20, size_t(9) << 20, (size_t(17) << 20) + 3}) {
        SCOPED_TRACE(bytes);
        LargeBuffer buffer(bytes);
        ASSERT_EQ(buffer.size(), bytes);
        EXPECT_EQ(reinterpret_cast<uintptr_t>(buffer.data()) % 64, 0u);
        EXPECT_TRUE(all_zero(buffer.data(), bytes));
        std::memset(buffer.data(), 0xab, bytes);
        EXPECT_EQ(buffer.data()[bytes - 1], std::byte{0xab});
    }
}

// A block populated ahead is written while its populator runs: the populator never changes a
// byte, so everything written is read back.
TEST(LargeBuffer, PopulatingAheadKeepsWhatTheOwnerWrites) {
    const size_t bytes = size_t(64) << 20;
    LargeBuffer buffer(bytes, LargeBuffer::Populate::kAhead);
    uint64_t* words = reinterpret_cast<uint64_t*>(buffer.data());
    const size_t count = bytes / sizeof(uint64_t);
    for (size_t i = 0; i < count; ++i) words[i] = i * 0x9e3779b97f4a7c15ull;
    size_t wrong = 0;
    for (size_t i = 0; i < count; ++i) wrong += words[i] != i * 0x9e3779b97f4a7c15ull;
    EXPECT_EQ(wrong, 0u);
}

// Freeing or moving a block whose populator is still running stops it first (no hang, no write
// into freed memory: the sanitizer builds would catch one).
TEST(LargeBuffer, FreedOrMovedWhilePopulating) {
    for (int round = 0; round < 4; ++round) {
        LargeBuffer first(size_t(256) << 20, LargeBuffer::Populate::kAhead);
        first.data()[0] = std::byte{1};
        LargeBuffer second = std::move(first);
        EXPECT_EQ(first.data(), nullptr);
        EXPECT_EQ(second.data()[0], std::byte{1});
        second = LargeBuffer(size_t(16) << 20, LargeBuffer::Populate::kAhead);
        EXPECT_TRUE(all_zero(second.data(), size_t(16) << 20));
    }
}
