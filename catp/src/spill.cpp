#include "spill.h"

#include <cstring>

#include "base/error.h"

namespace catpaq {

// ---- TriangleBins -----------------------------------------------------------------------------

template <typename Record>
TriangleBins<Record>::TriangleBins(const std::string& near_path, uint64_t memory_cap)
    : near_path_(near_path), memory_cap_(memory_cap) {}

template <typename Record>
void TriangleBins<Record>::add(uint64_t block, const Record& record) {
    // Consecutive triangles mostly go to the same block: skip the hash lookup then.
    size_t b = last_block_;
    if (b == SIZE_MAX || keys_[b] != block) {
        auto it = index_.find(block);
        if (it == index_.end()) {
            it = index_.emplace(block, uint32_t(keys_.size())).first;
            keys_.push_back(block);
            counts_.push_back(0);
            buffers_.emplace_back();
            chunks_.emplace_back();
        }
        b = last_block_ = it->second;
    }
    std::vector<Chunk>& chunks = buffers_[b];
    if (chunks.empty() || chunks.back().fill == chunks.back().capacity) {
        uint32_t capacity = chunks.empty() ? kFirstChunkRecords : std::min(kMaxChunkRecords, 2 * chunks.back().capacity);
        chunks.push_back({std::unique_ptr<Record[]>(new Record[capacity]), capacity, 0});
        buffered_ += capacity * sizeof(Record);
    }
    Chunk& chunk = chunks.back();
    chunk.records[chunk.fill++] = record;
    counts_[b]++;
    if (buffered_ > memory_cap_) flush();
}

// Writes every block's buffered records out as one run: sequential writes of large runs.
template <typename Record>
void TriangleBins<Record>::flush() {
    if (!file_) file_ = std::make_unique<TempFile>(near_path_);
    for (size_t b = 0; b < buffers_.size(); ++b) {
        std::vector<Chunk>& chunks = buffers_[b];
        if (chunks.empty()) continue;
        // The block's chunks land back to back: one run to read later.
        uint64_t start = file_end_;
        for (const Chunk& c : chunks) {
            file_->write_at(file_end_, c.records.get(), c.fill * sizeof(Record));
            file_end_ += c.fill * sizeof(Record);
        }
        chunks_[b].push_back({start, uint32_t((file_end_ - start) / sizeof(Record))});
        chunks.clear();
    }
    buffered_ = 0;
}

template <typename Record>
void TriangleBins<Record>::load(size_t b, std::vector<Record>& out) {
    out.clear();
    out.reserve(size_t(counts_[b]));
    for (auto [offset, count] : chunks_[b]) {
        size_t at = out.size();
        out.resize(at + count);
        file_->read_at(offset, out.data() + at, size_t(count) * sizeof(Record));
    }
    std::vector<Chunk>& chunks = buffers_[b];
    for (const Chunk& c : chunks) {
        out.insert(out.end(), c.records.get(), c.records.get() + c.fill);
        buffered_ -= c.capacity * sizeof(Record);
    }
    std::vector<Chunk>().swap(chunks);
}

template class TriangleBins<TriangleRecord>;
template class TriangleBins<TriangleCorners>;

// ---- FragmentSpill ----------------------------------------------------------------------------

namespace {

// Layout: vertex count, index count, positions, normals, colours, indices.
std::vector<uint8_t> serialize(const WorkFragment& f) {
    uint32_t nv = uint32_t(f.positions.size()), ni = uint32_t(f.indices.size());
    size_t bytes = 8 + size_t(nv) * (sizeof(Vec3d) + sizeof(Vec3f) + sizeof(Rgb8)) + size_t(ni) * 4;
    std::vector<uint8_t> out(bytes);
    uint8_t* p = out.data();
    auto put = [&](const void* data, size_t n) {
        if (n) std::memcpy(p, data, n);
        p += n;
    };
    put(&nv, 4);
    put(&ni, 4);
    put(f.positions.data(), nv * sizeof(Vec3d));
    put(f.normals.data(), nv * sizeof(Vec3f));
    put(f.colors.data(), nv * sizeof(Rgb8));
    put(f.indices.data(), ni * 4);
    return out;
}

void deserialize(const uint8_t* p, size_t size, WorkFragment& f) {
    uint32_t nv, ni;
    if (size < 8) fail("corrupt scratch data: fragment record too short");
    std::memcpy(&nv, p, 4);
    std::memcpy(&ni, p + 4, 4);
    if (size != 8 + size_t(nv) * (sizeof(Vec3d) + sizeof(Vec3f) + sizeof(Rgb8)) + size_t(ni) * 4)
        fail("corrupt scratch data: fragment record size mismatch");
    p += 8;
    auto get = [&](void* data, size_t n) {
        if (n) std::memcpy(data, p, n);
        p += n;
    };
    f.positions.resize(nv);
    f.normals.resize(nv);
    f.colors.resize(nv);
    f.indices.resize(ni);
    get(f.positions.data(), nv * sizeof(Vec3d));
    get(f.normals.data(), nv * sizeof(Vec3f));
    get(f.colors.data(), nv * sizeof(Rgb8));
    get(f.indices.data(), ni * 4);
}

}  // namespace

FragmentSpill::FragmentSpill(const std::string& near_path, uint64_t memory_cap)
    : near_path_(near_path), memory_cap_(memory_cap) {}

namespace {

uint64_t memory_bytes(const WorkFragment& f) {
    return f.positions.capacity() * sizeof(Vec3d) + f.normals.capacity() * sizeof(Vec3f) +
           f.colors.capacity() * sizeof(Rgb8) + f.indices.capacity() * sizeof(uint32_t);
}

}  // namespace

// In memory the fragment is moved, not serialized: copying every fragment in and out of a byte
// buffer was most of the spill's cost when nothing went to disk.
void FragmentSpill::put(const SlotKey& key, WorkFragment&& fragment) {
    const uint64_t bytes = memory_bytes(fragment);
    SpilledFragment ref;
    ref.key = key;
    ref.vertices = uint32_t(fragment.positions.size());
    ref.triangles = uint32_t(fragment.indices.size() / 3);
    {
        std::lock_guard lock(mutex_);
        if (memory_bytes_ + bytes <= memory_cap_) {
            memory_bytes_ += bytes;
            ref.memory_index = uint32_t(memory_.size());
            memory_.push_back(std::move(fragment));
            index_.push_back(ref);
            return;
        }
    }
    std::vector<uint8_t> serialized = serialize(fragment);
    ref.bytes = uint32_t(serialized.size());
    std::lock_guard lock(mutex_);
    if (!file_) file_ = std::make_unique<TempFile>(near_path_);
    ref.file_offset = int64_t(file_end_);
    file_->write_at(file_end_, serialized.data(), serialized.size());
    file_end_ += serialized.size();
    index_.push_back(ref);
}

const WorkFragment& FragmentSpill::get(const SpilledFragment& ref, WorkFragment& scratch) const {
    if (ref.file_offset < 0) return memory_[ref.memory_index];
    std::vector<uint8_t> bytes(ref.bytes);
    file_->read_at(uint64_t(ref.file_offset), bytes.data(), bytes.size());
    deserialize(bytes.data(), bytes.size(), scratch);
    return scratch;
}

void FragmentSpill::release(const SpilledFragment& ref) {
    if (ref.file_offset < 0) memory_[ref.memory_index] = WorkFragment{};
}

}  // namespace catpaq
