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

#include "base/atomic_file.h"
#include "base/bytes.h"
#include "base/checksum.h"
#include "base/error.h"

namespace catpaq {

const char* archive_kind_name(ArchiveKind kind) {
    switch (kind) {
        case ArchiveKind::Catp: return "catp";
        case ArchiveKind::Aqp: return "aqp";
        case ArchiveKind::Points: return "points";
    }
    return "unknown";
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

static void write_entry(ByteWriter& w, const ArchiveEntry& e) {
    w.u64(e.key);
    w.u64(e.offset);
    w.u32(e.size);
    w.u16(e.level);
    w.u16(e.flags);
    w.u32(e.count);
    w.f32(e.error);
    w.u64(e.checksum);
}

static bool entry_less(const ArchiveEntry& a, const ArchiveEntry& b) {
    return a.level != b.level ? a.level < b.level : a.key < b.key;
}

std::string parse_archive_header(const uint8_t* data, size_t size, ArchiveHeader& h) {
    if (size < kArchiveHeaderSize) return "file too short for an archive header";
    if (std::memcmp(data, kArchiveMagic, 8) != 0) return "not a catpaq dataset (bad magic)";
    ByteReader r(data + 8, kArchiveHeaderSize - 8);
    h.version = r.u32();
    if (h.version != kArchiveVersion)
        return strprintf("unsupported dataset version %u (this build reads version %u)", h.version, kArchiveVersion);
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
    if (h.index_size != uint64_t(h.node_count) * kArchiveEntrySize) return "index size does not match node count";
    if (h.index_offset + h.index_size > h.file_size) return "index extends past the end of the file";
    return "";
}

std::string parse_archive_index(const ArchiveHeader& h, const uint8_t* data, size_t size, std::vector<ArchiveEntry>& out) {
    if (size != h.index_size) return "index has the wrong size";
    if (checksum64(data, size) != h.index_checksum) return "index checksum mismatch (corrupt dataset)";
    ByteReader r(data, size);
    out.resize(h.node_count);
    uint64_t payload_start = h.index_offset + h.index_size;
    for (uint32_t i = 0; i < h.node_count; ++i) {
        ArchiveEntry& e = out[i];
        e.key = r.u64();
        e.offset = r.u64();
        e.size = r.u32();
        e.level = r.u16();
        e.flags = r.u16();
        e.count = r.u32();
        e.error = r.f32();
        e.checksum = r.u64();
        if (e.size > 0 && (e.offset < payload_start || e.offset + e.size > h.file_size))
            return strprintf("node %u lies outside the file", i);
        if (!(e.error >= 0.0f) || !std::isfinite(e.error)) return strprintf("node %u has an invalid error", i);
        if (i > 0 && !entry_less(out[i - 1], e)) return "index is not sorted by (level, key) or has duplicates";
    }
    return r.ok() ? "" : "index truncated";
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
    impl_->spill = std::fopen(impl_->spill_path.c_str(), "w+b");
    if (!impl_->spill) fail("cannot create '%s': %s", impl_->spill_path.c_str(), std::strerror(errno));
}

ArchiveWriter::~ArchiveWriter() {
    if (impl_->spill) {
        std::fclose(impl_->spill);
        std::remove(impl_->spill_path.c_str());
    }
}

void ArchiveWriter::add_node(ArchiveEntry entry, const uint8_t* data, size_t size) {
    entry.size = uint32_t(size);
    entry.checksum = checksum64(data, size);
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
    h.index_size = uint64_t(h.node_count) * kArchiveEntrySize;
    uint64_t offset = h.index_offset + h.index_size;
    std::vector<uint64_t> spill_offsets(m.entries.size());
    for (size_t i = 0; i < m.entries.size(); ++i) {
        spill_offsets[i] = m.entries[i].offset;
        m.entries[i].offset = offset;
        offset += m.entries[i].size;
    }
    h.file_size = offset;
    ByteWriter index;
    for (const ArchiveEntry& e : m.entries) write_entry(index, e);
    h.meta_checksum = checksum64(meta.data(), meta.size());
    h.index_checksum = checksum64(index.bytes().data(), index.size());
    ByteWriter header;
    write_header(header, h);

    if (std::fflush(m.spill) != 0) fail("cannot flush '%s'", m.spill_path.c_str());
    AtomicFile out(m.path);
    out.write(header.bytes().data(), header.size());
    out.write(meta.data(), meta.size());
    out.write(index.bytes().data(), index.size());
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
    std::remove(m.spill_path.c_str());
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
    if (checksum64(p, e.size) != e.checksum) {
        if (error) *error = strprintf("'%s': node %llu checksum mismatch (corrupt dataset)", impl_->path.c_str(),
                                      (unsigned long long)e.key);
        return nullptr;
    }
    return p;
}

}  // namespace catpaq
