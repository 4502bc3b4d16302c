// catpaq verify on a point dataset: decodes every node and checks the hierarchy's invariants
// (points/format.h); with the original point file, that every input point is within each depth's
// error bound of a splat centre of that depth's cut.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "apps/verify_formats.h"
#include "base/error.h"
#include "base/progress.h"
#include "points/dataset.h"
#include "points/point_cloud.h"

namespace catpaq {

namespace {

struct PointsChecks {
    size_t nodes = 0, corrupt = 0, monotonicity = 0, nesting = 0, outside_box = 0, leaf_count_mismatch = 0;
    uint64_t leaf_points = 0, stored_points = 0;
    std::vector<std::string> problems;
    bool ok() const { return corrupt + monotonicity + nesting + outside_box + leaf_count_mismatch == 0; }
    void note(const std::string& p) {
        if (problems.size() < 8) problems.push_back(p);
    }
};

bool box_contains(const PointNodeInfo& outer, const PointNodeInfo& inner) {
    for (int a = 0; a < 3; ++a)
        if (inner.box_min[a] < outer.box_min[a] || inner.box_max[a] > outer.box_max[a]) return false;
    return true;
}

// Centres (world coordinates) of the splats of the cut that takes every node at `depth` and
// every leaf above it, and the largest error bound among those nodes.
struct DepthCut {
    std::vector<std::array<double, 3>> centres;
    double bound = 0;
};

// Whether each point has a centre within `radius` (a uniform grid of cells of that size; the
// 27 cells around a point hold every centre within it). Cells are counted from `origin` in
// integers: far from the world's origin (1e6, with cells of 1e-7) the cell of p + cell, divided
// out in doubles, was at times p's own, and points beside a centre were reported uncovered.
size_t count_uncovered(const std::vector<std::array<double, 3>>& centres, const std::vector<Vec3d>& points,
                       const double origin[3], double radius, Progress* progress) {
    const double cell = std::max(radius, 1e-300);
    auto cell_of = [&](const double* p) {
        std::array<int64_t, 3> c;
        for (int a = 0; a < 3; ++a)
            c[size_t(a)] = int64_t(std::clamp(std::floor((p[a] - origin[a]) / cell), -1e15, 1e15));
        return c;
    };
    auto key = [](const std::array<int64_t, 3>& c) {
        return (uint64_t(c[0]) & 0x1fffff) << 42 | (uint64_t(c[1]) & 0x1fffff) << 21 | (uint64_t(c[2]) & 0x1fffff);
    };
    std::unordered_multimap<uint64_t, uint32_t> grid;
    grid.reserve(centres.size());
    for (size_t i = 0; i < centres.size(); ++i) grid.emplace(key(cell_of(centres[i].data())), uint32_t(i));
    std::vector<uint8_t> covered(points.size(), 0);
    const double r2 = radius * radius;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, points.size(), 4096), [&](const tbb::blocked_range<size_t>& range) {
        for (size_t i = range.begin(); i < range.end(); ++i) {
            const Vec3d& p = points[i];
            const std::array<int64_t, 3> home = cell_of(p.data());
            for (int dz = -1; dz <= 1 && !covered[i]; ++dz)
                for (int dy = -1; dy <= 1 && !covered[i]; ++dy)
                    for (int dx = -1; dx <= 1 && !covered[i]; ++dx) {
                        auto [first, last] = grid.equal_range(key({home[0] + dx, home[1] + dy, home[2] + dz}));
                        for (auto it = first; it != last; ++it) {
                            const auto& c = centres[it->second];
                            const double d2 = (c[0] - p[0]) * (c[0] - p[0]) + (c[1] - p[1]) * (c[1] - p[1]) +
                                              (c[2] - p[2]) * (c[2] - p[2]);
                            if (d2 <= r2) {
                                covered[i] = 1;
                                break;
                            }
                        }
                    }
        }
        if (progress) progress->add(range.size());
    });
    return size_t(std::count(covered.begin(), covered.end(), uint8_t(0)));
}

}  // namespace

int verify_points_dataset(const VerifyJob& job) {
    const PointDataset d(job.dataset);
    const PointsMeta& m = d.meta();
    const std::vector<ArchiveEntry>& entries = d.entries();
    PointsChecks c;
    int max_depth = 0;
    for (const ArchiveEntry& e : entries) max_depth = std::max(max_depth, int(e.level));
    std::vector<DepthCut> cuts(size_t(max_depth) + 1);
    for (size_t i = 0; i < entries.size(); ++i) {
        const ArchiveEntry& e = entries[i];
        ++c.nodes;
        DecodedPoints points;
        const std::string problem = d.decode(i, points);
        if (!problem.empty()) {
            ++c.corrupt;
            c.note(problem);
            continue;
        }
        c.stored_points += points.count;
        const PointNodeInfo& info = m.nodes[i];
        // Every splat ball lies in the node's box (the box holds the node's and its descendants').
        for (size_t k = 0; k < points.count; ++k) {
            bool inside = true;
            for (int a = 0; a < 3; ++a) {
                const float x = points.positions[3 * k + size_t(a)], r = points.radii[k];
                // The box is stored in floats, rounded outwards by the converter; allow the
                // rounding of the comparison's own subtraction.
                const float slack = 1e-6f * std::max({std::fabs(info.box_min[a]), std::fabs(info.box_max[a]), 1.0f});
                inside = inside && x - r >= info.box_min[a] - slack && x + r <= info.box_max[a] + slack;
            }
            if (!inside) {
                ++c.outside_box;
                c.note(strprintf("node %llu: a splat reaches out of the node's box", (unsigned long long)e.key));
                break;
            }
        }
        const bool leaf = e.flags & kPointLeafFlag;
        if (leaf) c.leaf_points += e.count;
        if (e.key != 1) {
            const int64_t parent = d.find(point_node_parent(e.key));
            if (parent >= 0) {
                if (entries[size_t(parent)].error < e.error) {
                    ++c.monotonicity;
                    c.note(strprintf("node %llu's error %g is above its parent's %g", (unsigned long long)e.key,
                                     double(e.error), double(entries[size_t(parent)].error)));
                }
                if (!box_contains(m.nodes[size_t(parent)], info)) {
                    ++c.nesting;
                    c.note(strprintf("node %llu's box is not inside its parent's", (unsigned long long)e.key));
                }
            }
        }
        // Depth cuts this node belongs to: its own depth, and every deeper one if it is a leaf.
        for (int depth = int(e.level); depth <= (leaf ? max_depth : int(e.level)); ++depth) {
            DepthCut& cut = cuts[size_t(depth)];
            cut.bound = std::max(cut.bound, double(e.error));
            for (size_t k = 0; k < points.count; ++k)
                cut.centres.push_back({m.origin[0] + double(points.positions[3 * k]),
                                       m.origin[1] + double(points.positions[3 * k + 1]),
                                       m.origin[2] + double(points.positions[3 * k + 2])});
        }
    }
    if (c.leaf_points != m.input_points) {
        ++c.leaf_count_mismatch;
        c.note(strprintf("the leaves hold %llu points, the input had %llu", (unsigned long long)c.leaf_points,
                         (unsigned long long)m.input_points));
    }
    std::printf("dataset:  %s: points, %zu nodes (depth %d), %llu stored points for %llu input points\n",
                job.dataset.c_str(), c.nodes, max_depth, (unsigned long long)c.stored_points,
                (unsigned long long)m.input_points);
    std::printf("checks:   decode %s, monotone errors %s, nested boxes %s, splats in their boxes %s, leaves hold the "
                "input %s\n",
                c.corrupt ? "FAIL" : "ok", c.monotonicity ? "FAIL" : "ok", c.nesting ? "FAIL" : "ok",
                c.outside_box ? "FAIL" : "ok", c.leaf_count_mismatch ? "FAIL" : "ok");
    bool ok = c.ok();
    if (!job.original.empty() && c.corrupt == 0) {
        const PointCloud original = read_point_cloud(job.original);
        std::printf("original: %s: %zu points%s\n", job.original.c_str(), original.size(),
                    original.size() == m.input_points ? "" : " (NOT the dataset's input count)");
        if (original.size() != m.input_points) ok = false;
        std::unique_ptr<Progress> bar;
        std::printf("%5s %12s %12s %12s\n", "depth", "splats", "bound", "uncovered");
        for (int depth = 0; depth <= max_depth; ++depth) {
            const DepthCut& cut = cuts[size_t(depth)];
            if (job.progress) {
                const std::string phase = "depth " + std::to_string(depth) + " of " + std::to_string(max_depth);
                if (!bar)
                    bar = std::make_unique<Progress>("verify", phase, original.size(), "pt");
                else
                    bar->phase(phase, original.size(), "pt");
            }
            // Relative slack: the bound is computed in doubles from float positions.
            const double radius = cut.bound * (1 + 1e-6) + 1e-9;
            const size_t uncovered = count_uncovered(cut.centres, original.positions, m.origin, radius, bar.get());
            std::printf("%5d %12zu %12.4g %12zu\n", depth, cut.centres.size(), cut.bound, uncovered);
            if (uncovered) {
                ok = false;
                std::printf("problem: at depth %d, %zu input points are farther than the bound %.6g from every splat\n",
                            depth, uncovered, cut.bound);
            }
        }
    }
    for (const std::string& p : c.problems) std::printf("problem: %s\n", p.c_str());
    std::printf("%s\n", ok ? "verify: OK" : "verify: FAILED");
    return ok ? 0 : 1;
}

}  // namespace catpaq
