// catpaq verify on an AQP dataset: the format's invariants (aqp/verify.h) and, with the original
// mesh, each level's distance to it in both directions against the stored bounds.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <string>

#include "apps/verify_formats.h"
#include "aqp/clean.h"
#include "aqp/dataset.h"
#include "aqp/verify.h"
#include "base/progress.h"
#include "catp/distance.h"
#include "mesh/io.h"

namespace catpaq {

namespace {

struct LevelDistances {
    int level = 0;
    double bound = 0;  // the largest stored node bound of the level
    DistanceStats to_original, from_original;
    size_t triangles = 0;
};

// Distances from `points` to a level's surface. Grid triangles quantization left without area
// draw as lines (aqp/build.h): a point that is farther than `bound` from the triangles is also
// measured to the level's edges.
DistanceStats measure_to_level(const Mesh& level, const std::vector<std::array<double, 3>>& points, double bound,
                               Progress* progress) {
    const SurfaceDistance to_triangles(level.positions, level.indices);
    std::vector<std::pair<std::array<double, 3>, std::array<double, 3>>> edges;
    edges.reserve(level.indices.size());
    for (size_t t = 0; t < level.triangle_count(); ++t)
        for (int k = 0; k < 3; ++k)
            edges.push_back({level.positions[level.indices[3 * t + k]], level.positions[level.indices[3 * t + (k + 1) % 3]]});
    const SegmentDistance to_edges(edges);
    std::vector<double> distance(points.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, points.size(), 1024), [&](const tbb::blocked_range<size_t>& range) {
        for (size_t i = range.begin(); i < range.end(); ++i) {
            distance[i] = to_triangles.distance(points[i]);
            if (distance[i] > bound) distance[i] = std::min(distance[i], to_edges.distance(points[i]));
        }
        if (progress) progress->add(range.size());
    });
    DistanceStats stats;
    double sum2 = 0;
    for (double d : distance) {
        stats.max = std::max(stats.max, d);
        sum2 += d * d;
    }
    stats.rms = points.empty() ? 0 : std::sqrt(sum2 / double(points.size()));
    return stats;
}

// The stored bound of a node is the largest distance between corresponding points of the level
// surface and the input surface (same domain point): it bounds the distance from any point of
// the level to the input (level -> original), and from any point of the input the converter
// kept to the level (original -> level). The original is cleaned as the converter cleans it
// (the same default options: convert has no option that changes them), so what cleaning
// removed (small components, non-manifold parts; convert's report lists them) is not measured.
std::vector<LevelDistances> measure_levels(const aqp::AqpDataset& d, const Mesh& cleaned, size_t samples,
                                           bool progress) {
    SurfaceDistance to_original(cleaned.positions, cleaned.indices);
    const std::vector<std::array<double, 3>> original_points = sample_surface(cleaned.positions, cleaned.indices, samples);
    std::vector<LevelDistances> out;
    std::unique_ptr<Progress> bar;
    const size_t levels = size_t(d.finest_level() + 1);
    if (progress) bar = std::make_unique<Progress>("verify", "level 0 of " + std::to_string(levels - 1), 2 * samples, "pt");
    for (int l = 0; l <= d.finest_level(); ++l) {
        if (bar && l > 0) bar->phase("level " + std::to_string(l) + " of " + std::to_string(levels - 1), 2 * samples, "pt");
        LevelDistances ld;
        ld.level = l;
        for (uint32_t p = 0; p < d.patch_count(); ++p) ld.bound = std::max(ld.bound, double(d.entry(p, l).error));
        const Mesh level = aqp::aqp_level_mesh(d, l, false);
        ld.triangles = level.triangle_count();
        ld.to_original = measure_distances(to_original, sample_surface(level.positions, level.indices, samples), bar.get());
        ld.from_original = measure_to_level(level, original_points, ld.bound, bar.get());
        out.push_back(ld);
    }
    return out;
}

}  // namespace

int verify_aqp_dataset(const VerifyJob& job) {
    aqp::AqpDataset d(job.dataset);
    const aqp::AqpMeta& m = d.meta();
    const aqp::AqpVerifyReport r = aqp::verify_aqp(d);
    uint64_t payload = 0;
    for (const ArchiveEntry& e : d.archive().entries()) payload += e.size;
    const int size = (1 << d.finest_level()) + 1;
    std::printf("dataset:  %s: AQP, %zu patches of %d x %d samples (level %d), %zu nodes, %llu payload bytes\n",
                job.dataset.c_str(), d.patch_count(), size, size, d.finest_level(), r.nodes,
                (unsigned long long)payload);
    std::printf("checks:   decode %s, shared edges and corners %s, nested levels %s, monotone bounds %s, extents %s\n",
                r.corrupt_nodes ? "FAIL" : "ok", r.shared_sample_mismatches ? "FAIL" : "ok",
                r.nesting_mismatches ? "FAIL" : "ok", r.monotonicity_violations ? "FAIL" : "ok",
                r.extent_violations ? "FAIL" : "ok");
    bool ok = r.ok();
    if (!job.original.empty() && r.corrupt_nodes == 0) {
        const Mesh original = read_mesh(job.original);
        aqp::CleanReport clean;
        const aqp::CleanMesh cleaned = aqp::clean_to_manifold(original, aqp::CleanOptions{}, &clean);
        const double diag = std::max(1e-300, std::sqrt(std::pow(m.bounds_max[0] - m.bounds_min[0], 2) +
                                                        std::pow(m.bounds_max[1] - m.bounds_min[1], 2) +
                                                        std::pow(m.bounds_max[2] - m.bounds_min[2], 2)));
        const std::vector<LevelDistances> levels = measure_levels(d, cleaned.mesh, job.samples, job.progress);
        std::printf("original: %s, cleaned as convert cleans it: %zu of %zu triangles kept", job.original.c_str(),
                    clean.triangles, clean.input_triangles);
        for (const std::string& line : clean.summary()) std::printf("; %s", line.c_str());
        std::printf("\nerrors in model units (and relative to the bounding-box diagonal %.6g):\n", diag);
        std::printf("%5s %10s %11s %21s %21s %21s %21s\n", "level", "triangles", "stored", "level->original max",
                    "original->level max", "level->original rms", "original->level rms");
        auto cell = [diag](double v) {
            char text[64];
            std::snprintf(text, sizeof text, "%.3g (%.1e)", v, v / diag);
            return std::string(text);
        };
        for (const LevelDistances& l : levels) {
            std::printf("%5d %10zu %11.3g %21s %21s %21s %21s\n", l.level, l.triangles, l.bound,
                        cell(l.to_original.max).c_str(), cell(l.from_original.max).c_str(),
                        cell(l.to_original.rms).c_str(), cell(l.from_original.rms).c_str());
            // The bound is exact arithmetic on doubles; the measure samples, so it can only be
            // below: a tiny relative slack absorbs the distance computation's rounding.
            const double limit = l.bound * (1 + 1e-9) + 1e-12 * diag;
            if (l.to_original.max > limit || l.from_original.max > limit) {
                ok = false;
                std::printf("problem: level %d measured %.6g, above its stored bound %.6g\n", l.level,
                            std::max(l.to_original.max, l.from_original.max), l.bound);
            }
        }
        std::printf("precision: %.4g (quantization's largest distance; step %.4g)\n", m.precision, m.step);
    }
    for (const std::string& p : r.problems) std::printf("problem: %s\n", p.c_str());
    std::printf("%s\n", ok ? "verify: OK" : "verify: FAILED");
    return ok ? 0 : 1;
}

}  // namespace catpaq
