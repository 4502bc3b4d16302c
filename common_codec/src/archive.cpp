#include "common_codec/archive.h"

#include <algorithm>
#include <cmath>
#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <mutex>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#include <utility>

#include "base/atomic_file.h"
#include "base/bytes.h"
#include "base/checksum.h"
#include "base/error.h"
#include "base/output_path.h"
#include "base/signal_cleanup.h"
#include "common_codec/deflate.h"

namespace catpaq {

const char* archive_kind_name(ArchiveKind kind) {
    switch (kind) {
        case ArchiveKind::Catp: return "catp";
        case ArchiveKind::Aqp: return "aqp";
        case ArchiveKind::Points: return "points";
    }
    return "unknown";
}

uint64_t archive_node_checksum(uint32_t version, const uint8_t* data, size_t size) {
    const uint64_t h = checksum64(data, size);
    return version >= 2 ? h & 0xffffffffu : h;
}

bool archive_checksum_matches(uint64_t stored, const uint8_t* data, size_t size) {
    const uint64_t h = checksum64(data, size);
    return stored == h || (stored >> 32 == 0 && stored == (h & 0xffffffffu));
}

static void write_header(ByteWriter& w, const ArchiveHeader& h) {
    w.raw(kArchiveMagic, 8);
    w.u32(h.version);
    w.u32(uint32_t(h.kind));
    w.u64(h.file_size);
    w.u64(h.meta_offset);
    w.u32(h.meta_size);
    w.u32(h.node_count);
    w.u64(h.index_offset);
    w.u64(h.index_size);
    w.u64(h.meta_checksum);
    w.u64(h.index_checksum);
    w.u64(0);
    w.u64(0);
    w.u64(checksum64(w.bytes().data(), w.size()));
}

// Version 2's index before deflate: column by column, every entry's level (as a difference from
// the previous entry's), key (zigzag difference from the previous entry's, wrapping), size,
// flags and count as varints; then the errors as four byte planes (low bytes of every error
// first) and the checksums, 4 bytes each (archive_node_checksum). Offsets are not stored: payloads follow the index in
// index order without gaps. In columns deflate finds alike values together: on a 2M-triangle
// AQP dataset (2982 nodes) the index went from 119,280 bytes (version 1's 40 a node) to
// 26,778, of which the checksums (4 bytes a node, which do not compress) are 11,928.
static std::vector<uint8_t> packed_index(const std::vector<ArchiveEntry>& entries) {
    ByteWriter w;
    uint64_t previous_level = 0, previous_key = 0;
    for (const ArchiveEntry& e : entries) w.varint(e.level - std::exchange(previous_level, e.level));
    for (const ArchiveEntry& e : entries) {
        w.varint(zigzag64(int64_t(e.key - std::exchange(previous_key, e.key))));
    }
    for (const ArchiveEntry& e : entries) w.varint(e.size);
    for (const ArchiveEntry& e : entries) w.varint(e.flags);
    for (const ArchiveEntry& e : entries) w.varint(e.count);
    for (int b = 0; b < 4; ++b)
        for (const ArchiveEntry& e : entries) {
            uint32_t bits;
            std::memcpy(&bits, &e.error, 4);
            w.u8(uint8_t(bits >> (8 * b)));
        }
    for (const ArchiveEntry& e : entries) w.u32(uint32_t(e.checksum));
    return deflate_bytes(w.bytes());
}

// The inverse of packed_index for `count` entries; offsets from `payload_start` on. An empty
// string, or what is wrong.
static std::string read_packed_index(const uint8_t* data, size_t size, uint32_t count, uint64_t payload_start,
                                     std::vector<ArchiveEntry>& out) {
    std::vector<uint8_t> raw;
    if (!inflate_bytes(data, size, size_t(count) * kMaxPackedEntryBytes, raw))
        return "index is not a valid deflate stream of the expected size (corrupt dataset)";
    ByteReader r(raw.data(), raw.size());
    out.assign(count, ArchiveEntry{});
    uint64_t level = 0, key = 0, offset = payload_start;
    for (ArchiveEntry& e : out) {
        level += r.varint();
        if (level > UINT16_MAX) return "index has a level out of range";
        e.level = uint16_t(level);
    }
    for (ArchiveEntry& e : out) {
        key += uint64_t(unzigzag64(r.varint()));
        e.key = key;
    }
    for (ArchiveEntry& e : out) {
        const uint64_t v = r.varint();
        if (v > UINT32_MAX) return "index has a node size out of range";
        e.size = uint32_t(v);
        e.offset = offset;
        offset += v;
    }
    for (ArchiveEntry& e : out) {
        const uint64_t v = r.varint();
        if (v > UINT16_MAX) return "index has node flags out of range";
        e.flags = uint16_t(v);
    }
    for (ArchiveEntry& e : out) {
        const uint64_t v = r.varint();
        if (v > UINT32_MAX) return "index has a node count out of range";
        e.count = uint32_t(v);
    }
    std::vector<uint32_t> bits(count, 0);
    for (int b = 0; b < 4; ++b)
        for (uint32_t& x : bits) x |= uint32_t(r.u8()) << (8 * b);
    for (uint32_t i = 0; i < count; ++i) std::memcpy(&out[i].error, &bits[i], 4);
    for (ArchiveEntry& e : out) e.checksum = r.u32();
    if (!r.ok()) return "index truncated";
    if (r.remaining() != 0) return "index has bytes left over";
    return "";
}

static bool entry_less(const ArchiveEntry& a, const ArchiveEntry& b) {
    return a.level != b.level ? a.level < b.level : a.key < b.key;
}

std::string parse_archive_header(const uint8_t* data, size_t size, ArchiveHeader& h) {
    if (size < kArchiveHeaderSize) return "file too short for an archive header";
    if (std::memcmp(data, kArchiveMagic, 8) != 0) return "not a catpaq dataset (bad magic)";
    ByteReader r(data + 8, kArchiveHeaderSize - 8);
    h.version = r.u32();
    if (h.version < 1 || h.version > kArchiveVersion)
        return strprintf("unsupported dataset version %u (this build reads versions 1 to %u)", h.version, kArchiveVersion);
    uint32_t kind = r.u32();
    h.file_size = r.u64();
    h.meta_offset = r.u64();
    h.meta_size = r.u32();
    h.node_count = r.u32();
    h.index_offset = r.u64();
    h.index_size = r.u64();
    h.meta_checksum = r.u64();
    h.index_checksum = r.u64();
    r.u64();
    r.u64();
    uint64_t stored = r.u64();
    if (stored != checksum64(data, kArchiveHeaderSize - 8)) return "header checksum mismatch (corrupt dataset)";
    if (kind < 1 || kind > 3) return strprintf("unknown dataset kind %u", kind);
    h.kind = ArchiveKind(kind);
    if (h.meta_offset != kArchiveHeaderSize) return "bad meta offset";
    if (h.index_offset != h.meta_offset + h.meta_size) return "bad index offset";
    if (h.version == 1 && h.index_size != uint64_t(h.node_count) * kArchiveEntrySize)
        return "index size does not match node count";
    // Version 2: a node count no index of this size could hold is refused before anything is
    // allocated for it (an entry is at least kMinPackedEntryBytes before deflate).
    if (h.version >= 2 && !deflate_can_hold(uint64_t(h.node_count) * kMinPackedEntryBytes, h.index_size))
        return "index too short for its node count";
    if (h.index_offset + h.index_size > h.file_size) return "index extends past the end of the file";
    return "";
}

std::string parse_archive_index(const ArchiveHeader& h, const uint8_t* data, size_t size, std::vector<ArchiveEntry>& out) {
    if (size != h.index_size) return "index has the wrong size";
    if (checksum64(data, size) != h.index_checksum) return "index checksum mismatch (corrupt dataset)";
    const uint64_t payload_start = h.index_offset + h.index_size;
    if (h.version >= 2) {
        if (std::string e = read_packed_index(data, size, h.node_count, payload_start, out); !e.empty()) return e;
    } else {
        ByteReader r(data, size);
        out.resize(h.node_count);
        for (ArchiveEntry& e : out) {
            e.key = r.u64();
            e.offset = r.u64();
            e.size = r.u32();
            e.level = r.u16();
            e.flags = r.u16();
            e.count = r.u32();
            e.error = r.f32();
            e.checksum = r.u64();
        }
        if (!r.ok()) return "index truncated";
    }
    for (uint32_t i = 0; i < h.node_count; ++i) {
        const ArchiveEntry& e = out[i];
        if (e.size > 0 && (e.offset < payload_start || e.offset + e.size > h.file_size))
            return strprintf("node %u lies outside the file", i);
        if (!(e.error >= 0.0f) || !std::isfinite(e.error)) return strprintf("node %u has an invalid error", i);
        if (i > 0 && !entry_less(out[i - 1], e)) return "index is not sorted by (level, key) or has duplicates";
    }
    return "";
}

// ---------------------------------------------------------------------------------------------

struct ArchiveWriter::Impl {
    std::string path, spill_path;
    ArchiveKind kind;
    FILE* spill = nullptr;
    uint64_t spill_size = 0;
    std::vector<ArchiveEntry> entries;  // offsets point into the spill file until finish()
    std::mutex mutex;
};

ArchiveWriter::ArchiveWriter(std::string path, ArchiveKind kind) : impl_(new Impl) {
    impl_->path = std::move(path);
    impl_->kind = kind;
    impl_->spill_path = impl_->path + ".nodes.tmp." + std::to_string(getpid());
    // The spill is only ever used through the open stream, so it needs no name: an anonymous
    // file in the output's directory (O_TMPFILE) where the file system has them. A named file
    // unlinked at once still showed in the directory for that moment, which a test listing the
    // directory while a conversion ran caught under load. Its name stays for messages.
    if (const int fd = ::open(directory_of(impl_->path).c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600); fd >= 0) {
        impl_->spill = ::fdopen(fd, "w+b");
        if (impl_->spill) return;
        const int error = errno;
        ::close(fd);
        fail("cannot create '%s': %s", impl_->spill_path.c_str(), std::strerror(error));
    }
    // Elsewhere a named file, registered for removal on signals before it exists and unlinked as
    // soon as it does, so that no way of ending the run (a signal, an error, a crash) leaves it
    // next to the output.
    remove_on_signal(impl_->spill_path);
    impl_->spill = std::fopen(impl_->spill_path.c_str(), "w+b");
    const int error = errno;
    ::unlink(impl_->spill_path.c_str());
    forget_on_signal(impl_->spill_path);
    if (!impl_->spill) fail("cannot create '%s': %s", impl_->spill_path.c_str(), std::strerror(error));
}

ArchiveWriter::~ArchiveWriter() {
    if (impl_->spill) std::fclose(impl_->spill);
}

void ArchiveWriter::add_node(ArchiveEntry entry, const uint8_t* data, size_t size) {
    entry.size = uint32_t(size);
    entry.checksum = archive_node_checksum(kArchiveVersion, data, size);
    std::lock_guard lock(impl_->mutex);
    entry.offset = impl_->spill_size;
    if (size && std::fwrite(data, 1, size, impl_->spill) != size)
        fail("cannot write '%s': %s", impl_->spill_path.c_str(), std::strerror(errno));
    impl_->spill_size += size;
    impl_->entries.push_back(entry);
}

uint64_t ArchiveWriter::payload_bytes() const { return impl_->spill_size; }

uint64_t ArchiveWriter::finish(const std::vector<uint8_t>& meta) {
    Impl& m = *impl_;
    std::sort(m.entries.begin(), m.entries.end(), entry_less);
    for (size_t i = 1; i < m.entries.size(); ++i)
        if (!entry_less(m.entries[i - 1], m.entries[i])) fail("archive: duplicate node key %llu", (unsigned long long)m.entries[i].key);

    ArchiveHeader h;
    h.kind = m.kind;
    h.meta_offset = kArchiveHeaderSize;
    h.meta_size = uint32_t(meta.size());
    h.node_count = uint32_t(m.entries.size());
    h.index_offset = h.meta_offset + h.meta_size;
    // The index's size depends on the sizes only (offsets are implied), so it is packed first.
    const std::vector<uint8_t> index = packed_index(m.entries);
    h.index_size = index.size();
    uint64_t offset = h.index_offset + h.index_size;
    std::vector<uint64_t> spill_offsets(m.entries.size());
    for (size_t i = 0; i < m.entries.size(); ++i) {
        spill_offsets[i] = m.entries[i].offset;
        m.entries[i].offset = offset;
        offset += m.entries[i].size;
    }
    h.file_size = offset;
    h.meta_checksum = checksum64(meta.data(), meta.size());
    h.index_checksum = checksum64(index.data(), index.size());
    ByteWriter header;
    write_header(header, h);

    if (std::fflush(m.spill) != 0) fail("cannot flush '%s'", m.spill_path.c_str());
    AtomicFile out(m.path);
    out.write(header.bytes().data(), header.size());
    out.write(meta.data(), meta.size());
    out.write(index.data(), index.size());
    std::vector<uint8_t> buffer;
    for (size_t i = 0; i < m.entries.size(); ++i) {
        buffer.resize(m.entries[i].size);
        if (buffer.empty()) continue;
        if (fseeko(m.spill, off_t(spill_offsets[i]), SEEK_SET) != 0 ||
            std::fread(buffer.data(), 1, buffer.size(), m.spill) != buffer.size())
            fail("cannot read back '%s'", m.spill_path.c_str());
        out.write(buffer.data(), buffer.size());
    }
    out.commit();
    std::fclose(m.spill);
    m.spill = nullptr;
    return h.file_size;
}

// ---------------------------------------------------------------------------------------------

struct ArchiveReader::Impl {
    std::string path;
    const uint8_t* map = nullptr;
    uint64_t size = 0;
    ArchiveHeader header;
    std::vector<uint8_t> meta;
    std::vector<ArchiveEntry> entries;
};

ArchiveReader::ArchiveReader(const std::string& path) : impl_(new Impl) {
    Impl& m = *impl_;
    m.path = path;
    int fd = ::open(path.c_str(), O_RDONLY);
    if (fd < 0) fail("cannot open '%s': %s", path.c_str(), std::strerror(errno));
    struct stat st{};
    if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
        ::close(fd);
        fail("'%s' is not a regular file", path.c_str());
    }
    m.size = uint64_t(st.st_size);
    if (m.size < kArchiveHeaderSize) {
        ::close(fd);
        fail("'%s': file too short to be a catpaq dataset (%llu bytes)", path.c_str(), (unsigned long long)m.size);
    }
    void* map = mmap(nullptr, m.size, PROT_READ, MAP_PRIVATE, fd, 0);
    ::close(fd);
    if (map == MAP_FAILED) fail("cannot map '%s': %s", path.c_str(), std::strerror(errno));
    m.map = static_cast<const uint8_t*>(map);
    std::string problem = parse_archive_header(m.map, m.size, m.header);
    if (problem.empty() && m.header.file_size != m.size)
        problem = strprintf("file is %llu bytes but its header says %llu (truncated or appended to)",
                            (unsigned long long)m.size, (unsigned long long)m.header.file_size);
    if (problem.empty() && checksum64(m.map + m.header.meta_offset, m.header.meta_size) != m.header.meta_checksum)
        problem = "metadata checksum mismatch (corrupt dataset)";
    if (problem.empty())
        problem = parse_archive_index(m.header, m.map + m.header.index_offset, m.header.index_size, m.entries);
    if (!problem.empty()) {
        munmap(const_cast<uint8_t*>(m.map), m.size);
        m.map = nullptr;
        fail("'%s': %s", path.c_str(), problem.c_str());
    }
    m.meta.assign(m.map + m.header.meta_offset, m.map + m.header.meta_offset + m.header.meta_size);
}

ArchiveReader::~ArchiveReader() {
    if (impl_->map) munmap(const_cast<uint8_t*>(impl_->map), impl_->size);
}

const ArchiveHeader& ArchiveReader::header() const { return impl_->header; }
const std::vector<uint8_t>& ArchiveReader::meta() const { return impl_->meta; }
const std::vector<ArchiveEntry>& ArchiveReader::entries() const { return impl_->entries; }
const uint8_t* ArchiveReader::data() const { return impl_->map; }
uint64_t ArchiveReader::size() const { return impl_->size; }
FirstFrame archive_first_frame(const ArchiveHeader& header, const std::vector<ArchiveEntry>& entries) {
    FirstFrame f;
    f.prefix_bytes = header.index_offset + header.index_size;
    for (const ArchiveEntry& e : entries)
        if (e.level == 0) f.level0_bytes += e.size;
    return f;
}

uint64_t archive_first_request_size(const ArchiveHeader& header, const std::vector<ArchiveEntry>& entries,
                                    uint64_t limit) {
    uint64_t end = header.index_offset + header.index_size;
    for (const ArchiveEntry& e : entries) {
        if (e.level != 0 || e.offset != end || e.offset + e.size > limit) break;
        end += e.size;
    }
    return end;
}

uint64_t ArchiveReader::prefix_size() const { return impl_->header.index_offset + impl_->header.index_size; }

int64_t ArchiveReader::find(uint64_t key) const {
    // Sorted by (level, key): scan each level's run with a binary search.
    const auto& e = impl_->entries;
    size_t begin = 0;
    while (begin < e.size()) {
        uint16_t level = e[begin].level;
        size_t end = begin;
        // Find the end of this level's run by galloping binary search.
        size_t lo = begin, hi = e.size();
        while (lo < hi) {
            size_t mid = (lo + hi) / 2;
            if (e[mid].level <= level) lo = mid + 1;
            else hi = mid;
        }
        end = lo;
        auto it = std::lower_bound(e.begin() + begin, e.begin() + end, key,
                                   [](const ArchiveEntry& a, uint64_t k) { return a.key < k; });
        if (it != e.begin() + end && it->key == key) return int64_t(it - e.begin());
        begin = end;
    }
    return -1;
}

const uint8_t* ArchiveReader::node(size_t i, std::string* error) const {
    const ArchiveEntry& e = impl_->entries.at(i);
    const uint8_t* p = impl_->map + e.offset;
    if (!archive_checksum_matches(e.checksum, p, e.size)) {
        if (error) *error = strprintf("'%s': node %llu checksum mismatch (corrupt dataset)", impl_->path.c_str(),
                                      (unsigned long long)e.key);
        return nullptr;
    }
    return p;
}

}  // namespace catpaq
