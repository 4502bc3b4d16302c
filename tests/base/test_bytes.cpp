#include <gtest/gtest.h>

#include "base/bytes.h"

using namespace catpaq;

TEST(Bytes, RoundTripsFixedWidthAndVarints) {
    ByteWriter w;
    w.u8(7);
    w.u16(0xBEEF);
    w.u32(0xDEADBEEF);
    w.u64(0x0123456789ABCDEFull);
    w.f32(1.5f);
    w.varint(0);
    w.varint(300);
    w.varint(~0ull);
    ByteReader r(w.bytes().data(), w.size());
    EXPECT_EQ(r.u8(), 7);
    EXPECT_EQ(r.u16(), 0xBEEF);
    EXPECT_EQ(r.u32(), 0xDEADBEEFu);
    EXPECT_EQ(r.u64(), 0x0123456789ABCDEFull);
    EXPECT_EQ(r.f32(), 1.5f);
    EXPECT_EQ(r.varint(), 0u);
    EXPECT_EQ(r.varint(), 300u);
    EXPECT_EQ(r.varint(), ~0ull);
    EXPECT_TRUE(r.ok());
    EXPECT_EQ(r.remaining(), 0u);
}

TEST(Bytes, ReaderNeverReadsPastTheEndOfTruncatedInput) {
    ByteWriter w;
    w.u64(42);
    w.varint(1ull << 40);
    for (size_t cut = 0; cut < w.size(); ++cut) {
        ByteReader r(w.bytes().data(), cut);
        r.u64();
        r.varint();
        EXPECT_FALSE(r.ok()) << "cut at " << cut;
        EXPECT_EQ(r.remaining(), 0u);
    }
}

TEST(Bytes, LittleEndianLayoutIsFixed) {
    ByteWriter w;
    w.u32(0x04030201);
    ASSERT_EQ(w.size(), 4u);
    EXPECT_EQ(w.bytes()[0], 1);
    EXPECT_EQ(w.bytes()[3], 4);
}
