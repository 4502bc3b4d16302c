#pragma once
// Private to the points module: the point converter's out-of-core store (points/builder.h).
//
// A cloud larger than the memory budget is written to scratch files as it is read; the top of
// the kd-tree is decided by passes over them (each split from histograms of the points'
// coordinates, exactly as partition.h decides it in core); the points are then distributed to
// the parts ("chunks") below those splits, each small enough to partition in core; and the
// builder finds every per-point array, in partition order, in shared file mappings whose pages
// it releases after each chunk. The tree, and so the dataset, is the one the in-core converter
// makes (partition.h says why).
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "mesh/mesh.h"
#include "partition.h"
#include "points/point_cloud.h"

namespace catpaq {
class Progress;
class TempFile;
}  // namespace catpaq

namespace catpaq::points_detail {

// The per-point arrays the builder reads, in partition order (every leaf a range); colors is
// null for clouds without colours. normals and radii are written by the leaves' estimates.
struct PointArrays {
    const Vec3d* positions = nullptr;  // relative to the origin
    Vec3f* normals = nullptr;
    const Rgb8* colors = nullptr;
    float* radii = nullptr;
    const float* xyz = nullptr;  // the positions as floats, 3 a point (for the neighbour searches)
};

// What the input held, known once it is read.
struct PointInputSummary {
    size_t count = 0;
    Bounds bounds;
    float largest_radius = 0;
    bool normals = false, colors = false, radii = false;
};

class OutOfCorePoints {
public:
    // Scratch files go next to `near_path`. `chunk_points`: the most points partitioned and built
    // at a time (at least 4 node sizes); `histogram_bytes`: the memory the top splits' histograms
    // may take at once.
    OutOfCorePoints(const std::string& near_path, const PartitionSettings& settings, size_t chunk_points,
                    uint64_t histogram_bytes, Progress* progress);
    ~OutOfCorePoints();

    // 1. The input, in order, one validated batch at a time (every batch has the same attributes).
    void add(const PointCloud& batch);
    const PointInputSummary& summary() const { return summary_; }

    // 2. Partitions the points, moved to `origin` (positions minus origin, in double), into the
    // hierarchy: the nodes (the array partition_items would give for the whole cloud, every
    // node's tight box set), and the per-point arrays in their order. Estimated normals start as
    // +z and estimated radii as 0, as in core.
    void partition(const double origin[3]);
    std::vector<HNode>& nodes() { return nodes_; }
    // Whether nodes()[i] is the root of a chunk (built, then its pages released, one at a time).
    bool is_chunk_root(size_t i) const { return chunk_root_[i] != 0; }
    const PointArrays& arrays() const { return arrays_; }
    size_t chunks() const { return chunk_count_; }
    // Passes over the whole input the top splits took.
    size_t split_passes() const { return split_passes_; }

    // Drops the mapped pages the builder touched from the process's resident memory.
    void release_pages();

private:
    struct TopNode;
    struct InputBlock;
    template <class Tally, class MakeTally, class Visit>
    std::vector<Tally> for_each_input(MakeTally make_tally, Visit visit);
    void decide_top_splits();
    void write_split_positions();
    void decide_group(const std::vector<uint32_t>& group, int width);
    void distribute();
    void partition_chunk(uint32_t top, uint32_t begin, std::vector<HNode>& out);
    void emit(uint32_t top, std::vector<HNode>& out, uint32_t& next_begin);
    void map_arrays();
    uint32_t classify(const float p[3], uint32_t index) const;

    std::string near_path_;
    PartitionSettings settings_;
    size_t chunk_points_;
    uint64_t histogram_bytes_;
    Progress* progress_;
    PointInputSummary summary_;
    double origin_[3] = {0, 0, 0};
    // Input order.
    std::unique_ptr<TempFile> in_positions_, in_normals_, in_colors_, in_radii_;
    std::unique_ptr<TempFile> split_positions_;  // floats relative to the origin, for the split passes
    // Chunk order (input order within a chunk), with the points' input indices.
    std::unique_ptr<TempFile> chunk_positions_, chunk_indices_, chunk_normals_, chunk_colors_, chunk_radii_;
    // Partition order: what arrays() maps.
    std::unique_ptr<TempFile> positions_, normals_, colors_, radii_, xyz_;
    std::vector<TopNode> top_;
    std::vector<uint32_t> chunk_begin_;  // per top node that is a chunk: its first point in chunk order
    size_t chunk_count_ = 0;
    size_t split_passes_ = 0;
    std::vector<HNode> nodes_;
    std::vector<uint8_t> chunk_root_;
    PointArrays arrays_;
    struct Mapped {
        void* data;
        uint64_t size;
    };
    std::vector<Mapped> mapped_;
};

}  // namespace catpaq::points_detail
