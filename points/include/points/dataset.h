#pragma once
// Reading a point dataset (points/format.h) from a local file: metadata, nodes, decoding.
#include <memory>
#include <string>
#include <vector>

#include "common_codec/archive.h"
#include "points/codec.h"
#include "points/format.h"

namespace catpaq {

class PointDataset {
public:
    // Opens and validates the archive (kind Points), its metadata and the agreement of the two:
    // one node record per index entry with the same key, entry levels equal to key depths,
    // inner nodes with both children present. Throws Error naming the file and the problem.
    explicit PointDataset(const std::string& path);
    ~PointDataset();

    const PointsMeta& meta() const { return meta_; }
    const std::vector<ArchiveEntry>& entries() const { return archive_->entries(); }
    size_t node_count() const { return meta_.nodes.size(); }
    // Index of the node with id `key`, or -1.
    int64_t find(uint64_t key) const { return archive_->find(key); }
    // Decodes node i (checksum, then decode_point_node). Empty string on success, else what is
    // wrong, naming the file and the node. Thread-safe for distinct `out`.
    std::string decode(size_t i, DecodedPoints& out) const;
    // The node's raw bytes (checksum verified) or nullptr with `error` set.
    const uint8_t* node_bytes(size_t i, std::string* error) const { return archive_->node(i, error); }

private:
    std::string path_;
    std::unique_ptr<ArchiveReader> archive_;
    PointsMeta meta_;
};

}  // namespace catpaq
