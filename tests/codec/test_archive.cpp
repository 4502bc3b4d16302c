// The dataset container (common_codec/archive.h): the packed index of version 2 round trips
// every field and implies the offsets, version-1 files still read, and corrupt indexes, nodes
// and node counts are refused with a message.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "base/bytes.h"
#include "base/checksum.h"
#include "base/error.h"
#include "common_codec/archive.h"
#include "scratch_directory.h"

using namespace catpaq;
namespace fs = std::filesystem;

namespace {

fs::path scratch(const std::string& name) {
    static const catpaq::test::ScratchDirectory dir("catpaq_archive_test_");
    return dir / name;
}

std::vector<uint8_t> read_all(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    return std::vector<uint8_t>((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

void write_all(const fs::path& path, const std::vector<uint8_t>& bytes) {
    std::ofstream out(path, std::ios::binary);
    out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

struct Node {
    ArchiveEntry entry;
    std::vector<uint8_t> bytes;
};

// Nodes over 4 levels with keys that jump (64-bit keys, keys of a finer level below a coarser
// level's), assorted flags, counts and errors, and an empty node.
std::vector<Node> assorted_nodes() {
    std::mt19937_64 rng(7);
    std::vector<Node> nodes;
    for (uint16_t level = 0; level < 4; ++level)
        for (int i = 0; i < 20 + 30 * level; ++i) {
            Node n;
            n.entry.key = (level % 2 ? rng() : uint64_t(i) * 256 + level);
            n.entry.level = level;
            n.entry.flags = uint16_t(rng() & 0xffff);
            n.entry.count = uint32_t(rng());
            n.entry.error = float(1.0 / (1 + level)) * float(rng() % 1000) / 1000.0f;
            n.bytes.resize((level == 2 && i == 3) ? 0 : size_t(rng() % 3000));
            for (uint8_t& b : n.bytes) b = uint8_t(rng());
            nodes.push_back(n);
        }
    return nodes;
}

fs::path write_archive(const std::vector<Node>& nodes, const std::vector<uint8_t>& meta, const std::string& name) {
    fs::path path = scratch(name);
    ArchiveWriter w(path.string(), ArchiveKind::Points);
    for (size_t i = nodes.size(); i-- > 0;) w.add_node(nodes[i].entry, nodes[i].bytes.data(), nodes[i].bytes.size());
    w.finish(meta);
    return path;
}

// The same nodes as a version-1 file: 40-byte entries with offsets and XXH3-64 checksums.
std::vector<uint8_t> version_one_file(std::vector<Node> nodes, const std::vector<uint8_t>& meta) {
    std::sort(nodes.begin(), nodes.end(), [](const Node& a, const Node& b) {
        return a.entry.level != b.entry.level ? a.entry.level < b.entry.level : a.entry.key < b.entry.key;
    });
    const uint64_t index_offset = kArchiveHeaderSize + meta.size(), index_size = nodes.size() * kArchiveEntrySize;
    ByteWriter index;
    uint64_t offset = index_offset + index_size;
    for (const Node& n : nodes) {
        index.u64(n.entry.key);
        index.u64(offset);
        index.u32(uint32_t(n.bytes.size()));
        index.u16(n.entry.level);
        index.u16(n.entry.flags);
        index.u32(n.entry.count);
        index.f32(n.entry.error);
        index.u64(checksum64(n.bytes.data(), n.bytes.size()));
        offset += n.bytes.size();
    }
    ByteWriter h;
    h.raw(kArchiveMagic, 8);
    h.u32(1);
    h.u32(uint32_t(ArchiveKind::Points));
    h.u64(offset);
    h.u64(kArchiveHeaderSize);
    h.u32(uint32_t(meta.size()));
    h.u32(uint32_t(nodes.size()));
    h.u64(index_offset);
    h.u64(index_size);
    h.u64(checksum64(meta.data(), meta.size()));
    h.u64(checksum64(index.bytes().data(), index.size()));
    h.u64(0);
    h.u64(0);
    h.u64(checksum64(h.bytes().data(), h.size()));
    std::vector<uint8_t> file = h.bytes();
    file.insert(file.end(), meta.begin(), meta.end());
    file.insert(file.end(), index.bytes().begin(), index.bytes().end());
    for (const Node& n : nodes) file.insert(file.end(), n.bytes.begin(), n.bytes.end());
    return file;
}

// Every node of `nodes` is in the reader with its fields, and its bytes read back verified.
void expect_nodes(const ArchiveReader& reader, const std::vector<Node>& nodes) {
    ASSERT_EQ(reader.entries().size(), nodes.size());
    for (const Node& n : nodes) {
        const int64_t i = reader.find(n.entry.key);
        ASSERT_GE(i, 0) << n.entry.key;
        const ArchiveEntry& e = reader.entries()[size_t(i)];
        EXPECT_EQ(e.level, n.entry.level);
        EXPECT_EQ(e.flags, n.entry.flags);
        EXPECT_EQ(e.count, n.entry.count);
        EXPECT_EQ(e.error, n.entry.error);
        EXPECT_EQ(e.size, n.bytes.size());
        std::string error;
        const uint8_t* p = reader.node(size_t(i), &error);
        ASSERT_NE(p, nullptr) << error;
        EXPECT_EQ(std::vector<uint8_t>(p, p + e.size), n.bytes);
    }
}

}  // namespace

TEST(ArchiveContainer, PackedIndexRoundTripsEveryFieldAndItsOffsetsFollowTheIndex) {
    const std::vector<Node> nodes = assorted_nodes();
    const std::vector<uint8_t> meta{1, 2, 3, 4, 5};
    const fs::path path = write_archive(nodes, meta, "packed.cpq");
    ArchiveReader reader(path.string());
    EXPECT_EQ(reader.header().version, kArchiveVersion);
    EXPECT_EQ(reader.meta(), meta);
    expect_nodes(reader, nodes);
    // Sorted by (level, key); payloads contiguous from the end of the index, in index order.
    uint64_t offset = reader.prefix_size();
    for (const ArchiveEntry& e : reader.entries()) {
        EXPECT_EQ(e.offset, offset);
        offset += e.size;
    }
    EXPECT_EQ(offset, reader.size());
    // Smaller than version 1's 40 bytes an entry (random keys, flags and counts barely compress).
    EXPECT_LT(reader.header().index_size, nodes.size() * kArchiveEntrySize * 3 / 4);
}

TEST(ArchiveContainer, VersionOneFilesStillReadWithTheirSixtyFourBitChecksums) {
    const std::vector<Node> nodes = assorted_nodes();
    const std::vector<uint8_t> meta{9, 8, 7};
    const fs::path path = scratch("version1.cpq");
    std::vector<uint8_t> file = version_one_file(nodes, meta);
    write_all(path, file);
    {
        ArchiveReader reader(path.string());
        EXPECT_EQ(reader.header().version, 1u);
        EXPECT_EQ(reader.meta(), meta);
        expect_nodes(reader, nodes);
        EXPECT_GT(reader.entries().back().checksum >> 32, 0u);  // the full 64 bits (almost surely)
    }
    // A version-1 node's corrupt byte is caught by its 64-bit checksum.
    const size_t last = file.size() - 1;
    file[last] ^= 1;
    write_all(path, file);
    ArchiveReader reader(path.string());
    std::string error;
    EXPECT_EQ(reader.node(reader.entries().size() - 1, &error), nullptr);
    EXPECT_NE(error.find("checksum"), std::string::npos) << error;
}

TEST(ArchiveContainer, NodeChecksumsAreXxh3OrItsLowThirtyTwoBits) {
    const std::vector<uint8_t> bytes{1, 2, 3, 4, 5, 6, 7};
    const uint64_t full = checksum64(bytes.data(), bytes.size());
    EXPECT_EQ(archive_node_checksum(1, bytes.data(), bytes.size()), full);
    EXPECT_EQ(archive_node_checksum(2, bytes.data(), bytes.size()), full & 0xffffffffu);
    EXPECT_TRUE(archive_checksum_matches(full, bytes.data(), bytes.size()));
    EXPECT_TRUE(archive_checksum_matches(full & 0xffffffffu, bytes.data(), bytes.size()));
    EXPECT_FALSE(archive_checksum_matches(full ^ (uint64_t(1) << 40), bytes.data(), bytes.size()));
    EXPECT_FALSE(archive_checksum_matches((full & 0xffffffffu) ^ 1, bytes.data(), bytes.size()));
}

TEST(ArchiveContainer, CorruptIndexNodeOrNodeCountIsRefusedWithAMessage) {
    const std::vector<Node> nodes = assorted_nodes();
    const fs::path path = write_archive(nodes, {1}, "corrupt_source.cpq");
    const std::vector<uint8_t> good = read_all(path);
    ArchiveHeader h;
    ASSERT_EQ(parse_archive_header(good.data(), good.size(), h), "");
    auto refusal = [&](const std::vector<uint8_t>& bytes) -> std::string {
        const fs::path bad = scratch("corrupt.cpq");
        write_all(bad, bytes);
        try {
            ArchiveReader reader(bad.string());
        } catch (const Error& e) {
            return e.what();
        }
        return "";
    };
    // Any flipped index byte: the index checksum.
    for (uint64_t at = h.index_offset; at < h.index_offset + h.index_size; at += 97) {
        std::vector<uint8_t> bytes = good;
        bytes[at] ^= 0x20;
        EXPECT_NE(refusal(bytes).find("index"), std::string::npos) << "byte " << at;
    }
    // A node count the index cannot hold (the header checksum recomputed, as a forger would):
    // refused before anything that large is allocated.
    for (uint32_t count : {uint32_t(nodes.size() + 1), 0x7fffffffu}) {
        std::vector<uint8_t> bytes = good;
        for (int i = 0; i < 4; ++i) bytes[36 + i] = uint8_t(count >> (8 * i));
        const uint64_t sum = checksum64(bytes.data(), kArchiveHeaderSize - 8);
        for (int i = 0; i < 8; ++i) bytes[kArchiveHeaderSize - 8 + i] = uint8_t(sum >> (8 * i));
        EXPECT_NE(refusal(bytes), "") << count << " nodes";
    }
    // A node's flipped byte: its checksum, when it is read.
    std::vector<uint8_t> bytes = good;
    bytes[good.size() - 1] ^= 1;
    const fs::path bad = scratch("corrupt_node.cpq");
    write_all(bad, bytes);
    ArchiveReader reader(bad.string());
    std::string error;
    EXPECT_EQ(reader.node(reader.entries().size() - 1, &error), nullptr);
    EXPECT_NE(error.find("checksum"), std::string::npos) << error;
}

// A server's first answer: the prefix, then level 0's nodes in file order, each whole, within the
// limit; never less than the prefix.
TEST(ArchiveContainer, TheFirstRequestIsThePrefixAndTheWholeLevelZeroNodesThatFit) {
    const std::vector<Node> nodes = assorted_nodes();
    const fs::path path = write_archive(nodes, {1, 2, 3}, "first_request.cpq");
    ArchiveReader reader(path.string());
    const uint64_t prefix = reader.prefix_size();
    std::vector<uint64_t> ends;  // the end of each level-0 node, in file order
    for (const ArchiveEntry& e : reader.entries())
        if (e.level == 0) ends.push_back(e.offset + e.size);
    ASSERT_EQ(ends.size(), 20u);
    ASSERT_LE(ends.back(), kFirstRequestBytes);
    EXPECT_EQ(archive_first_request_size(reader.header(), reader.entries()), ends.back());
    // A limit inside the fourth node: three nodes.
    EXPECT_EQ(archive_first_request_size(reader.header(), reader.entries(), ends[3] - 1), ends[2]);
    EXPECT_EQ(archive_first_request_size(reader.header(), reader.entries(), ends[3]), ends[3]);
    // Below the prefix: the prefix all the same (a client cannot do without it).
    EXPECT_EQ(archive_first_request_size(reader.header(), reader.entries(), 10), prefix);
    EXPECT_EQ(archive_first_request_size(reader.header(), reader.entries(), prefix), prefix);
}
