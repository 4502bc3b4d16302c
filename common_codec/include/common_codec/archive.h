#pragma once
// The dataset container shared by every format (CATP now, AQP and points later), the server
// and the client. One file, laid out so that a stock static web server can serve it with HTTP
// Range requests: the header, the format's metadata and the node index come first, then the node
// payloads ordered coarse to fine, so a client's first request (the first 64 KiB) holds the index
// and the coarsest nodes.
//
//   offset 0   Header (96 bytes, below)
//   meta       format-specific metadata (catp/format.h documents CATP's), meta_size bytes
//   index      node_count entries sorted by (level, key): version 2 one deflate stream of their
//              fields column by column (no offsets: payloads follow in index order), version 1
//              40 bytes an entry
//   payload    node bytes, in index order
//
// Every part carries an XXH3-64 checksum; readers reject unknown magic and versions.
// Byte tables: docs/formats/archive.md.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace catpaq {

constexpr char kArchiveMagic[8] = {'C', 'P', 'Q', 'A', 'R', 'C', 'H', '\x1a'};
constexpr uint32_t kArchiveVersion = 2;  // version 1 (40-byte index entries) still reads
constexpr size_t kArchiveHeaderSize = 96;
constexpr size_t kArchiveEntrySize = 40;  // version 1
// Version 2's entries before deflate: at least a byte per varint (level, key, size, flags,
// count), 4 of error and 4 of checksum; at most 10 per 64-bit varint, 5 per 32-bit, 3 per 16-bit.
constexpr size_t kMinPackedEntryBytes = 5 + 4 + 4;
constexpr size_t kMaxPackedEntryBytes = 3 + 10 + 5 + 3 + 5 + 4 + 4;

enum class ArchiveKind : uint32_t { Catp = 1, Aqp = 2, Points = 3 };
const char* archive_kind_name(ArchiveKind kind);

struct ArchiveHeader {
    uint32_t version = kArchiveVersion;
    ArchiveKind kind = ArchiveKind::Catp;
    uint64_t file_size = 0;
    uint64_t meta_offset = 0;
    uint32_t meta_size = 0;
    uint32_t node_count = 0;
    uint64_t index_offset = 0;
    uint64_t index_size = 0;
    uint64_t meta_checksum = 0;
    uint64_t index_checksum = 0;
};

// One node of the hierarchy. `key` is the format's node id (CATP: DiamondId bits); `level` orders
// coarse to fine; `flags` and `count` are format-specific (CATP: slot mask and leaf bit; triangles);
// `error` is the node's object-space error bound (monotone: parent >= child).
struct ArchiveEntry {
    uint64_t key = 0;
    uint64_t offset = 0;
    uint32_t size = 0;
    uint16_t level = 0;
    uint16_t flags = 0;
    uint32_t count = 0;
    float error = 0.0f;
    uint64_t checksum = 0;  // of the node's bytes: archive_node_checksum
};

// The checksum an index entry keeps of a node's bytes: XXH3-64 in version 1, its low 32 bits in
// version 2. 32 bits still catch a corrupt or misplaced range (but for one in 4 billion), the
// formats' payloads carry checks of their own, and 8 bytes a node were most of a packed index.
uint64_t archive_node_checksum(uint32_t version, const uint8_t* data, size_t size);
// Whether `data` matches an entry's checksum of either version: a version-2 checksum has no
// high bits, and is compared with XXH3-64's low 32 (so is a version-1 checksum that happens to
// have none, one in 4 billion).
bool archive_checksum_matches(uint64_t stored, const uint8_t* data, size_t size);

// Parses and validates a header from the first bytes of a file. Returns an empty string on
// success, else a message saying what is wrong (bad magic, unsupported version, checksum, sizes).
std::string parse_archive_header(const uint8_t* data, size_t size, ArchiveHeader& out);
// Parses the index bytes (validated against the header's checksum and size). Entries must lie
// inside the file, be sorted by (level, key) and unique. Empty string on success.
std::string parse_archive_index(const ArchiveHeader& header, const uint8_t* data, size_t size,
                                std::vector<ArchiveEntry>& out);

// Builds an archive: nodes are appended in any order (spilled to a temporary file next to the
// output, so memory stays bounded; unlinked as soon as it is open, so nothing is left behind
// however the run ends), then finish() writes header, meta, index and the payload in
// (level, key) order under a temporary name and renames it into place.
class ArchiveWriter {
public:
    ArchiveWriter(std::string path, ArchiveKind kind);  // throws Error
    ~ArchiveWriter();

    // Thread-safe. `entry.offset`, `size` and `checksum` are filled in by the writer.
    void add_node(ArchiveEntry entry, const uint8_t* data, size_t size);
    // Returns the final file size. Throws Error on I/O failure (nothing is left behind).
    uint64_t finish(const std::vector<uint8_t>& meta);

    uint64_t payload_bytes() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// The first frame: what a client fetches before it draws the whole model, coarsely: the prefix
// (header, metadata, index) and the payloads of level 0 (every format's coarsest level covers
// the model: CATP's root diamond, AQP's level-0 tiles, the point tree's root). The mission asks
// for at most 64 KiB.
struct FirstFrame {
    uint64_t prefix_bytes = 0, level0_bytes = 0;
    uint64_t bytes() const { return prefix_bytes + level0_bytes; }
};
FirstFrame archive_first_frame(const ArchiveHeader& header, const std::vector<ArchiveEntry>& entries);

// What a client's first request asks for: the first 64 KiB of the file (the mission's first
// frame). A server answers it with archive_first_request_size bytes; a static file server with
// the 64 KiB (or the whole file when smaller).
constexpr uint64_t kFirstRequestBytes = 64 * 1024;
// The first request's bytes from a server that knows the index: the prefix, then level 0's
// payloads (they follow the index in file order), whole, while the total stays within `limit`;
// at least the prefix (which may itself be larger). A client draws the first frame from them
// without a second request.
uint64_t archive_first_request_size(const ArchiveHeader& header, const std::vector<ArchiveEntry>& entries,
                                    uint64_t limit = kFirstRequestBytes);

// Reads an archive from a local file (memory-mapped). Validates header, meta and index on open;
// node bytes are checked against their checksum when read.
class ArchiveReader {
public:
    explicit ArchiveReader(const std::string& path);  // throws Error naming the file and the problem
    ~ArchiveReader();

    const ArchiveHeader& header() const;
    const std::vector<uint8_t>& meta() const;
    const std::vector<ArchiveEntry>& entries() const;
    // Index of the entry with `key`, or -1.
    int64_t find(uint64_t key) const;
    // The node's bytes inside the mapping (valid while the reader lives). Returns nullptr and
    // sets `error` if the checksum does not match.
    const uint8_t* node(size_t entry_index, std::string* error) const;
    // The whole file, for serving raw ranges.
    const uint8_t* data() const;
    uint64_t size() const;
    // Bytes from the start of the file up to the end of the index (what a client needs first).
    uint64_t prefix_size() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace catpaq
