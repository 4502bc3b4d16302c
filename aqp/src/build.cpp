// The AQP converter (aqp/build.h).
#include "aqp/build.h"

#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <memory>

#include "aqp/format.h"
#include "patch_errors.h"
#include "aqp/quad_layout.h"
#include "aqp/surface_map.h"
#include "base/error.h"
#include "base/output_path.h"
#include "base/progress.h"
#include "base/sysinfo.h"
#include "common_codec/archive.h"
#include "common_codec/octahedral.h"

namespace catpaq::aqp {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

using Quantized = std::array<uint32_t, 3>;

Vec3d centre_of(const Bounds& b) {
    return {0.5 * (b.min[0] + b.max[0]), 0.5 * (b.min[1] + b.max[1]), 0.5 * (b.min[2] + b.max[2])};
}

double mean_edge_length(const Mesh& m) {
    double sum = 0;
    for (size_t t = 0; t < m.triangle_count(); ++t)
        for (int k = 0; k < 3; ++k) {
            const Vec3d& a = m.positions[m.indices[3 * t + k]];
            const Vec3d& b = m.positions[m.indices[3 * t + (k + 1) % 3]];
            sum += std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
        }
    return m.triangle_count() ? sum / double(3 * m.triangle_count()) : 0.0;
}

// The finest level: asked for, or the power of two per side nearest (in log) to the samples per
// patch asked for, by default about two samples per surface vertex.
int choose_patch_level(const AqpBuildOptions& o, size_t surface_vertices, size_t patches) {
    if (o.patch_level >= 0) return o.patch_level;
    double per_patch = o.samples_per_patch ? double(o.samples_per_patch) : 2.0 * double(surface_vertices) / double(patches);
    int k = int(std::lround(std::log2(std::max(std::sqrt(per_patch) - 1, 1.0))));
    return std::clamp(k, 1, kMaxPatchLevel);
}

// Every distinct sample of the finest level, evaluated once: the first (patch, i, j) showing a
// sample number gives its domain point.
std::vector<SurfaceSample> resample(const QuadLayout& layout, const SampleNumbering& numbering, const SurfaceMap& map,
                                    Progress* progress) {
    const int n = numbering.size() - 1;
    std::vector<uint64_t> owner(numbering.sample_count(), UINT64_MAX);  // patch << 32 | j << 16 | i
    for (uint32_t p = 0; p < layout.patch_count(); ++p)
        for (int j = 0; j <= n; ++j)
            for (int i = 0; i <= n; ++i) {
                uint64_t& o = owner[numbering.id(p, i, j)];
                if (o == UINT64_MAX) o = (uint64_t(p) << 32) | (uint64_t(j) << 16) | uint64_t(i);
            }
    std::vector<SurfaceSample> samples(owner.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, owner.size(), 2048), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t s = r.begin(); s != r.end(); ++s) {
            const uint64_t o = owner[s];
            assert(o != UINT64_MAX);
            const uint32_t p = uint32_t(o >> 32);
            const int j = int((o >> 16) & 0xffff), i = int(o & 0xffff);
            samples[s] = map.sample(layout.point(p, double(i) / n, double(j) / n));
        }
        if (progress) progress->add(r.size());
    });
    return samples;
}

struct Quantization {
    double origin[3] = {0, 0, 0};
    double step = 1;
    std::vector<Quantized> position;               // per distinct sample
    std::vector<Quantized> patch_origin;           // per patch
    std::vector<std::array<uint16_t, 3>> extent;  // per patch
};

// Quantizes positions to a grid of step `step` from the samples' lower corner; the step grows
// until every patch's samples fit 16-bit offsets from the patch's own lowest grid point.
Quantization quantize(const QuadLayout& layout, const SampleNumbering& numbering, const std::vector<SurfaceSample>& samples,
                      double step, const Bounds& bounds) {
    Quantization q;
    for (int a = 0; a < 3; ++a) q.origin[a] = bounds.min[a];
    const int n = numbering.size() - 1;
    const double largest_extent = std::max({bounds.max[0] - bounds.min[0], bounds.max[1] - bounds.min[1], bounds.max[2] - bounds.min[2]});
    step = std::max(step, largest_extent / 4.0e9);  // global grid coordinates fit 32 bits
    for (;;) {
        q.step = step;
        q.position.resize(samples.size());
        tbb::parallel_for(size_t(0), samples.size(), [&](size_t s) {
            for (int a = 0; a < 3; ++a)
                q.position[s][a] = uint32_t(std::llround(std::max(0.0, (samples[s].position[a] - q.origin[a]) / step)));
        });
        q.patch_origin.assign(layout.patch_count(), {UINT32_MAX, UINT32_MAX, UINT32_MAX});
        std::vector<Quantized> high(layout.patch_count(), {0, 0, 0});
        for (uint32_t p = 0; p < layout.patch_count(); ++p)
            for (int j = 0; j <= n; ++j)
                for (int i = 0; i <= n; ++i) {
                    const Quantized& x = q.position[numbering.id(p, i, j)];
                    for (int a = 0; a < 3; ++a) {
                        q.patch_origin[p][a] = std::min(q.patch_origin[p][a], x[a]);
                        high[p][a] = std::max(high[p][a], x[a]);
                    }
                }
        uint64_t widest = 0;
        q.extent.resize(layout.patch_count());
        for (uint32_t p = 0; p < layout.patch_count(); ++p)
            for (int a = 0; a < 3; ++a) {
                const uint64_t e = uint64_t(high[p][a]) - q.patch_origin[p][a];
                widest = std::max(widest, e);
                q.extent[p][a] = uint16_t(std::min<uint64_t>(e, 65535));
            }
        if (widest <= 65535) return q;
        step *= (double(widest) + 2) / 65535.0;
    }
}

// Finest-level grid triangles (cells split along (i,j)-(i+1,j+1)) with two corners at the same
// quantized position.
size_t count_collapsed_triangles(const QuadLayout& layout, const SampleNumbering& numbering, const Quantization& q) {
    const int n = numbering.size() - 1;
    std::vector<size_t> per_patch(layout.patch_count(), 0);
    tbb::parallel_for(size_t(0), layout.patch_count(), [&](size_t p) {
        auto at = [&](int i, int j) -> const Quantized& { return q.position[numbering.id(uint32_t(p), i, j)]; };
        for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i) {
                const Quantized &a = at(i, j), &b = at(i + 1, j), &c = at(i + 1, j + 1), &d = at(i, j + 1);
                per_patch[p] += (a == b || b == c || a == c) + (a == c || c == d || a == d);
            }
    });
    size_t total = 0;
    for (size_t c : per_patch) total += c;
    return total;
}

// World position of a quantized sample (what a reader decodes).
Vec3d world_position(const Quantization& q, const Quantized& x) {
    return {q.origin[0] + q.step * double(x[0]), q.origin[1] + q.step * double(x[1]), q.origin[2] + q.step * double(x[2])};
}

// The smallest float not below x (a stored bound must not round down).
float float_at_least(double x) {
    float f = float(x);
    return double(f) < x ? std::nextafter(f, INFINITY) : f;
}

// The patches in dataset order: sorted along a Morton curve over their boxes' centres on the
// quantization grid, so that a tile's consecutive patches lie together on the surface (a view
// then needs few tiles). order[d] is the layout patch that is dataset patch d.
std::vector<uint32_t> morton_patch_order(const Quantization& q) {
    const size_t patches = q.patch_origin.size();
    std::vector<std::array<uint64_t, 3>> centre(patches);
    uint64_t top = 1;
    for (size_t p = 0; p < patches; ++p)
        for (int a = 0; a < 3; ++a) {
            centre[p][size_t(a)] = 2 * uint64_t(q.patch_origin[p][a]) + q.extent[p][a];
            top = std::max(top, centre[p][size_t(a)] + 1);
        }
    auto spread = [](uint64_t x) {  // 10 bits to every third of 30
        uint64_t out = 0;
        for (int b = 0; b < 10; ++b) out |= ((x >> b) & 1) << (3 * b);
        return out;
    };
    std::vector<std::pair<uint64_t, uint32_t>> code(patches);
    for (size_t p = 0; p < patches; ++p) {
        uint64_t c = 0;
        for (int a = 0; a < 3; ++a) c |= spread(centre[p][size_t(a)] * 1024 / top) << a;  // one scale: cells stay cubes
        code[p] = {c, uint32_t(p)};
    }
    std::sort(code.begin(), code.end());
    std::vector<uint32_t> order(patches);
    for (size_t d = 0; d < patches; ++d) order[d] = code[d].second;
    return order;
}

AqpMeta make_meta(const QuadLayout& layout, const Quantization& q, const std::vector<SurfaceSample>& samples, int k,
                  bool colors, const Mesh& input, double mean_edge, const std::vector<uint32_t>& order) {
    AqpMeta m;
    m.patch_level = uint32_t(k);
    m.base_vertices = uint32_t(layout.domain().vertex_count());
    m.base_triangles = uint32_t(layout.domain().triangle_count());
    m.border_edges = uint32_t(layout.border_edges());
    m.flags = colors ? kAqpColorFlag : 0;
    for (int a = 0; a < 3; ++a) m.origin[a] = q.origin[a];
    m.step = q.step;
    Bounds b;
    for (const SurfaceSample& s : samples) b.add(s.position);
    for (int a = 0; a < 3; ++a) m.bounds_min[a] = b.min[a], m.bounds_max[a] = b.max[a];
    m.input_vertices = input.vertex_count();
    m.input_triangles = input.triangle_count();
    m.precision = q.step * std::sqrt(3.0) / 2;
    m.mean_edge = mean_edge;
    m.atlas_columns = uint32_t(std::ceil(std::sqrt(double(layout.patch_count()))));
    std::vector<uint32_t> dataset_patch(order.size());
    for (uint32_t d = 0; d < order.size(); ++d) dataset_patch[order[d]] = d;
    m.patches.resize(layout.patch_count());
    for (uint32_t d = 0; d < layout.patch_count(); ++d) {
        const uint32_t p = order[d];
        m.patches[d].corner = layout.patches()[p].corner;
        m.patches[d].link = layout.patches()[p].link;
        for (PatchLink& l : m.patches[d].link)
            if (l.patch != kNone) l.patch = dataset_patch[l.patch];
        m.patches[d].origin = q.patch_origin[p];
        m.patches[d].extent = q.extent[p];
    }
    return m;
}

}  // namespace

std::vector<uint8_t> tile_shifts(int finest_level, size_t patches, size_t tile_samples) {
    std::vector<uint8_t> shifts(size_t(finest_level) + 1, 0);
    if (tile_samples == 0) return shifts;
    for (int l = 0; l <= finest_level; ++l) {
        const uint64_t side = (uint64_t(1) << l) + 1, coarse = l > 0 ? (uint64_t(1) << (l - 1)) + 1 : 0;
        const uint64_t stored = side * side - coarse * coarse;
        // The largest tile within the target (one patch when a patch alone exceeds it), no larger
        // than needed to hold every patch.
        int s = 0;
        while (s < kMaxTileShift && (uint64_t(1) << (2 * s + 2)) * stored <= tile_samples && (uint64_t(1) << (2 * s)) < patches)
            ++s;
        shifts[size_t(l)] = uint8_t(l > 0 ? std::min<int>(s, shifts[size_t(l) - 1]) : s);
    }
    return shifts;
}

// Peak resident memory of a conversion, from measurements rounded up (`catpaq convert --format
// aqp` of gen_mesh's scans, the input mesh included, maximum resident size by /usr/bin/time: 112
// MiB at 200k triangles, 189 MiB at 400k, 401 MiB at 1M): 400 bytes per input triangle and 48 MiB.
uint64_t aqp_memory_estimate(uint64_t input_triangles) { return input_triangles * 400 + (uint64_t(48) << 20); }

void check_aqp_memory_budget(uint64_t input_triangles, uint64_t budget) {
    const uint64_t estimate = aqp_memory_estimate(input_triangles);
    if (!budget || estimate <= budget) return;
    fail("converting %llu triangles to AQP needs about %llu MiB (AQP converts in core), above the budget of %llu MiB: "
         "give --memory %lluM or more, give the mesh as PLY (reduced out of core to what fits first), or convert to "
         "CATP or points, which stay within the budget",
         (unsigned long long)input_triangles, (unsigned long long)(estimate >> 20), (unsigned long long)(budget >> 20),
         (unsigned long long)((estimate + (uint64_t(1) << 20) - 1) >> 20));
}

void build_aqp_dataset(const Mesh& input, const std::string& out_path, const AqpBuildOptions& o, AqpBuildReport* report_out) {
    const auto start = Clock::now();
    if (o.patch_level < -1 || o.patch_level == 0 || o.patch_level > kMaxPatchLevel)
        fail("patch level %d is out of range (1 to %d, or -1 to choose)", o.patch_level, kMaxPatchLevel);
    if (!(o.precision.model_units >= 0) || !(o.precision.mean_edges >= 0) || !std::isfinite(o.precision.model_units) ||
        !std::isfinite(o.precision.mean_edges) || (o.precision.model_units == 0 && o.precision.mean_edges == 0))
        fail("the precision must be a positive number of model units or mean edges");
    if (!(o.input_error >= 0) || !std::isfinite(o.input_error)) fail("the input's error must be a finite distance >= 0");
    check_output_file(out_path, "the output");
    std::unique_ptr<tbb::global_control> threads;
    if (o.threads) threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, o.threads);
    AqpBuildReport r;
    std::unique_ptr<Progress> progress;
    if (o.progress) progress = std::make_unique<Progress>("convert", "cleaning", input.triangle_count(), "tri");

    // 1. Clean.
    auto t = Clock::now();
    r.memory_estimate = aqp_memory_estimate(input.triangle_count());
    check_aqp_memory_budget(input.triangle_count(), o.memory_budget);
    CleanOptions clean_options;
    clean_options.min_component_area_fraction = o.min_component_area_fraction;
    CleanMesh clean = clean_to_manifold(input, clean_options, &r.clean);
    Mesh& surface = clean.mesh;
    if (!surface.has_normals()) surface.normals = compute_vertex_normals(surface);
    // Work about the origin: far from it (scans in projected coordinates, 1e7) the plane
    // quadrics' constant terms cancel catastrophically. Samples go back to world coordinates
    // before quantization; errors are measured here, where the rounding of the shift is covered
    // by `shift_slack`.
    const Vec3d centre = centre_of(surface.bounds());
    for (Vec3d& p : surface.positions)
        for (int a = 0; a < 3; ++a) p[a] -= centre[a];
    const double shift_slack =
        4 * std::nextafter(std::max({std::fabs(centre[0]), std::fabs(centre[1]), std::fabs(centre[2])}), INFINITY) -
        4 * std::max({std::fabs(centre[0]), std::fabs(centre[1]), std::fabs(centre[2])});
    r.mean_edge = mean_edge_length(surface);
    r.diagonal = input.bounds().diagonal();
    if (!(r.mean_edge > 0) || !std::isfinite(r.diagonal)) fail("the cleaned surface has no extent");
    if (progress) progress->add(input.triangle_count());
    r.seconds_clean = seconds_since(t);

    // 2. Base domain and parameterization.
    t = Clock::now();
    DomainOptions domain_options;
    domain_options.target_triangles = o.domain_triangles;
    domain_options.smoothing_sweeps = o.smoothing_sweeps;
    domain_options.retries = o.domain_triangles ? 0 : 3;  // a size the user chose is kept
    if (progress) progress->phase("base domain", surface.vertex_count(), "collapse");
    Parameterization param = build_parameterization(surface, domain_options, &r.domain, progress.get());
    for (const auto& [triangles, why] : r.domain.refused)
        r.warnings.push_back(strprintf("%zu base triangles were refused (%s); %zu gave a bijective map", triangles,
                                       why.c_str(), r.domain.target_triangles));
    r.seconds_parameterize = seconds_since(t);

    // 3-4. Patches and resampling.
    t = Clock::now();
    QuadLayout layout(param.domain);
    r.patches = layout.patch_count();
    r.patch_level = choose_patch_level(o, surface.vertex_count(), layout.patch_count());
    const int k = r.patch_level, n = 1 << k;
    if (double(layout.patch_count()) * (n - 1) * (n - 1) + 4.0 * double(layout.patch_count()) * n >= 4.0e9)
        fail("%zu patches at level %d are more samples than one dataset can number", layout.patch_count(), k);
    SampleNumbering numbering(layout, k);
    r.samples = numbering.sample_count();
    if (progress) progress->phase("resampling", r.samples, "sample");
    SurfaceMap map(surface, param);
    std::vector<SurfaceSample> samples = resample(layout, numbering, map, progress.get());
    r.location_misses = map.misses();
    for (SurfaceSample& sample : samples)
        for (int a = 0; a < 3; ++a) sample.position[a] += centre[a];
    if (r.location_misses)
        r.warnings.push_back(strprintf("%zu samples fell a hair outside every surface triangle and were put on the nearest",
                                       r.location_misses));

    // 5. Quantization.
    r.precision_asked = o.precision.model_units > 0 ? o.precision.model_units : o.precision.mean_edges * r.mean_edge;
    Bounds sample_bounds;
    for (const SurfaceSample& s : samples) sample_bounds.add(s.position);
    Quantization q = quantize(layout, numbering, samples, 2 * r.precision_asked / std::sqrt(3.0), sample_bounds);
    r.step = q.step;
    r.precision = q.step * std::sqrt(3.0) / 2;
    if (r.precision > r.precision_asked * (1 + 1e-9))
        r.warnings.push_back(strprintf("precision %.3g asked for, %.3g reached: a patch spans more than 65535 steps of "
                                       "the finer grid (ask for more domain triangles to reach it)",
                                       r.precision_asked, r.precision));
    r.collapsed_triangles = count_collapsed_triangles(layout, numbering, q);
    if (r.collapsed_triangles)
        r.warnings.push_back(strprintf("%zu of the finest level's %zu triangles have no area once quantized (parts thinner "
                                       "than the step %.3g draw as lines; a finer --precision keeps them)",
                                       r.collapsed_triangles, 2 * layout.patch_count() * size_t(n) * size_t(n), q.step));
    std::vector<uint16_t> normals(samples.size());
    tbb::parallel_for(size_t(0), samples.size(), [&](size_t s) {
        normals[s] = oct_encode_precise(samples[s].normal[0], samples[s].normal[1], samples[s].normal[2]);
    });
    r.seconds_resample = seconds_since(t);

    // 6. Errors.
    t = Clock::now();
    if (progress) progress->phase("measuring errors", layout.patch_count(), "patch");
    std::vector<Vec3d> exact(samples.size());
    for (size_t s = 0; s < samples.size(); ++s)
        for (int a = 0; a < 3; ++a) exact[s][a] = samples[s].position[a] - centre[a];
    std::vector<std::vector<double>> error = measure_patch_errors(
        surface, param, layout, map, numbering, exact,
        [&](uint32_t s) {
            Vec3d p = world_position(q, q.position[s]);
            for (int a = 0; a < 3; ++a) p[a] -= centre[a];
            return p;
        },
        progress.get());
    for (auto& levels : error)
        for (double& e : levels) e += shift_slack + o.input_error;
    r.seconds_errors = seconds_since(t);

    // 7. Nodes and the archive.
    t = Clock::now();
    if (progress) progress->phase("encoding", layout.patch_count() * size_t(k + 1), "node");
    const bool colors = input.has_colors();
    const std::vector<uint32_t> order = morton_patch_order(q);
    AqpMeta meta = make_meta(layout, q, samples, k, colors, input, r.mean_edge, order);
    meta.up_axis = o.up_axis;
    meta.tile_shift = tile_shifts(k, layout.patch_count(), o.tile_samples);
    ArchiveWriter writer(out_path, ArchiveKind::Aqp);
    r.levels.resize(size_t(k) + 1);
    // Dataset patch d's grid at level l (its samples every 2^(k - l) finest samples).
    auto make_grid = [&](uint32_t d, int l, PatchGrid& g) {
        const uint32_t p = order[d];
        g.patch = d;
        g.level = l;
        g.size = (1 << l) + 1;
        const int stride = 1 << (k - l);
        const size_t count = size_t(g.size) * g.size;
        g.position.resize(count);
        g.normal.resize(count);
        g.color.resize(colors ? count : 0);
        for (int j = 0; j < g.size; ++j)
            for (int i = 0; i < g.size; ++i) {
                const uint32_t s = numbering.id(p, i * stride, j * stride);
                const size_t at = g.index(i, j);
                for (int a = 0; a < 3; ++a) g.position[at][a] = uint16_t(q.position[s][a] - q.patch_origin[p][a]);
                g.normal[at] = normals[s];
                if (colors) g.color[at] = samples[s].color;
            }
    };
    for (int l = 0; l <= k; ++l) {
        std::vector<uint64_t> tile_bytes(meta.tile_count(l));
        tbb::parallel_for(uint32_t(0), meta.tile_count(l), [&](uint32_t tile) {
            const uint32_t first = meta.first_patch(tile, l), count = meta.tile_patches(tile, l);
            std::vector<PatchGrid> grids(count), coarser(l > 0 ? count : 0);
            std::vector<const PatchGrid*> grid_ptrs, coarser_ptrs;
            double tile_error = 0;
            for (uint32_t i = 0; i < count; ++i) {
                make_grid(first + i, l, grids[i]);
                grid_ptrs.push_back(&grids[i]);
                if (l > 0) {
                    make_grid(first + i, l - 1, coarser[i]);
                    coarser_ptrs.push_back(&coarser[i]);
                }
                tile_error = std::max(tile_error, error[order[first + i]][size_t(l)]);
            }
            const std::vector<uint8_t> node =
                encode_tile_node(grid_ptrs, coarser_ptrs, colors, o.png_compression, l == 0 ? meta.tile_patch_info(tile, 0) : TilePatches{});
            ArchiveEntry entry;
            entry.key = aqp_node_key(tile, l);
            entry.level = uint16_t(l);
            entry.count = uint32_t(count * grids[0].position.size());
            entry.error = float_at_least(tile_error);
            writer.add_node(entry, node.data(), node.size());
            tile_bytes[tile] = node.size();
            if (progress) progress->add(count);
        });
        AqpLevelStats& s = r.levels[size_t(l)];
        s.level = l;
        s.nodes = meta.tile_count(l);
        s.samples = layout.patch_count() * size_t((1 << l) + 1) * size_t((1 << l) + 1);
        for (uint64_t b : tile_bytes) s.bytes += b;
        for (size_t p = 0; p < layout.patch_count(); ++p) {
            s.max_error = std::max(s.max_error, error[p][size_t(l)]);
            s.mean_error += error[p][size_t(l)] / double(layout.patch_count());
        }
        r.payload_bytes += s.bytes;
    }
    if (progress) progress->phase("writing", 0, "");
    r.file_bytes = writer.finish(encode_aqp_meta(meta));
    r.seconds_encode = seconds_since(t);
    r.bits_per_sample = 8.0 * double(r.payload_bytes) / double(r.samples);
    if (progress) progress->finish();
    r.seconds = seconds_since(start);
    r.peak_rss = peak_rss_bytes();
    if (report_out) *report_out = std::move(r);
}

}  // namespace catpaq::aqp
