// Quad patches over the base domain and the shared sample numbering (aqp/quad_layout.h).
#include "aqp/quad_layout.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <map>

namespace catpaq::aqp {

QuadLayout::QuadLayout(const BaseDomain& domain) : domain_(&domain) {
    const uint32_t nbv = uint32_t(domain.vertex_count()), nbt = uint32_t(domain.triangle_count());
    patch_of_edge_.assign(nbt, {kNone, kNone, kNone});
    for (uint32_t t = 0; t < nbt; ++t)
        for (uint8_t k = 0; k < 3; ++k) {
            const uint32_t other = domain.neighbour[t][k];
            if (other != kNone && other < t) continue;  // made from the other side
            QuadPatch p;
            p.triangle = {t, other};
            p.edge = {k, other == kNone ? uint8_t(0) : domain.neighbour_edge[t][k]};
            const uint32_t a = domain.triangles[t][k], b = domain.triangles[t][(k + 1) % 3];
            const uint32_t c2 = other == kNone ? nbv + nbt + uint32_t(border_edges_++) : nbv + other;
            p.corner = {nbv + t, a, c2, b};
            patch_of_edge_[t][k] = uint32_t(patches_.size());
            if (other != kNone) patch_of_edge_[other][p.edge[1]] = uint32_t(patches_.size());
            patches_.push_back(p);
        }
    // Spokes (barycentre of T, corner c) are edges of the patches of T's two edges at c.
    std::map<std::pair<uint32_t, uint32_t>, std::pair<uint32_t, uint8_t>> first_use;
    for (uint32_t p = 0; p < patches_.size(); ++p) {
        const QuadPatch& q = patches_[p];
        const std::pair<uint32_t, uint32_t> spokes[4] = {
            {q.triangle[0], q.edge[0]},
            {q.triangle[1], q.border() ? kNone : (q.edge[1] + 1u) % 3},
            {q.triangle[1], q.border() ? kNone : q.edge[1]},
            {q.triangle[0], (q.edge[0] + 1u) % 3}};
        for (uint8_t e = 0; e < 4; ++e) {
            if (spokes[e].second == kNone) continue;  // half of a border edge
            auto [it, inserted] = first_use.emplace(spokes[e], std::make_pair(p, e));
            if (inserted) continue;
            auto [other, other_edge] = it->second;
            // Both patches run the spoke between the same two quad vertices: reversed if their
            // edge starts differ.
            bool reversed = patches_[p].corner[e] != patches_[other].corner[other_edge];
            patches_[p].link[e] = {other, other_edge, reversed};
            patches_[other].link[other_edge] = {p, e, reversed};
        }
    }
}

DomainPoint QuadLayout::point(uint32_t p, double u, double v) const {
    const QuadPatch& q = patches_[p];
    DomainPoint x;
    const double third = 1.0 / 3.0;
    if (q.border()) {
        // Bilinear on (c1, a, m, b), all in T1: m = (a + b) / 2.
        const double wc = (1 - u) * (1 - v), wa = u * (1 - v) + 0.5 * u * v, wb = (1 - u) * v + 0.5 * u * v;
        x.triangle = q.triangle[0];
        x.bary = {wc * third, wc * third, wc * third};
        x.bary[q.edge[0]] += wa;
        x.bary[(q.edge[0] + 1) % 3] += wb;
        return x;
    }
    if (u + v <= 1) {
        const double wc = 1 - u - v;
        x.triangle = q.triangle[0];
        x.bary = {wc * third, wc * third, wc * third};
        x.bary[q.edge[0]] += u;              // a
        x.bary[(q.edge[0] + 1) % 3] += v;    // b
    } else {
        const double wc = u + v - 1;
        x.triangle = q.triangle[1];
        x.bary = {wc * third, wc * third, wc * third};
        x.bary[(q.edge[1] + 1) % 3] += 1 - v;  // a
        x.bary[q.edge[1]] += 1 - u;            // b
    }
    return x;
}

void QuadLayout::locate(const DomainPoint& x, uint32_t& patch, double& u, double& v) const {
    // The third of the triangle holding x is the one opposite its smallest coordinate.
    int m = 0;
    for (int i = 1; i < 3; ++i)
        if (x.bary[i] < x.bary[m]) m = i;
    const uint8_t k = uint8_t((m + 1) % 3);  // the base edge of that third
    patch = patch_of_edge_[x.triangle][k];
    const QuadPatch& q = patches_[patch];
    const double d = x.bary[m];
    if (q.triangle[0] == x.triangle && q.edge[0] == k) {
        const double along_a = x.bary[k] - d, along_b = x.bary[(k + 1) % 3] - d;
        if (!q.border()) {
            u = along_a;
            v = along_b;
        } else {
            // u (1 - v/2) = A and v (1 - u/2) = B: with D = A - B, u = v + D and
            // v^2 - (2 - D) v + 2B = 0, whose smaller root is the one in [0, 1].
            const double diff = along_a - along_b;
            const double discriminant = std::max(0.0, (2 - diff) * (2 - diff) - 8 * along_b);
            v = 0.5 * ((2 - diff) - std::sqrt(discriminant));
            u = v + diff;
        }
    } else {
        // T2 side: a is corner edge+1 of T2 and b corner edge.
        u = 1 - (x.bary[k] - d);
        v = 1 - (x.bary[(k + 1) % 3] - d);
    }
    u = std::clamp(u, 0.0, 1.0);
    v = std::clamp(v, 0.0, 1.0);
}

SampleNumbering::SampleNumbering(const QuadLayout& layout, int k) : layout_(&layout), k_(k), n_(1 << k) {
    const BaseDomain& d = layout.domain();
    const uint32_t run = uint32_t(n_ - 1);
    corners_ = layout.quad_vertex_count();
    const size_t spokes_first = corners_;
    const size_t halves_first = spokes_first + 3 * d.triangle_count() * run;
    const size_t interior_first = halves_first + 2 * layout.border_edges() * run;
    size_t border_index = 0;
    edge_runs_.resize(layout.patch_count());
    interior_first_.resize(layout.patch_count());
    for (uint32_t p = 0; p < layout.patch_count(); ++p) {
        const QuadPatch& q = layout.patches()[p];
        auto spoke = [&](uint32_t t, uint32_t c) { return uint32_t(spokes_first + (3 * size_t(t) + c) * run); };
        // Spokes run from the barycentre to the base vertex: edges 0 and 2 go that way, 1 and 3 back.
        edge_runs_[p][0] = {spoke(q.triangle[0], q.edge[0]), false};
        edge_runs_[p][3] = {spoke(q.triangle[0], (q.edge[0] + 1) % 3), true};
        if (q.border()) {
            edge_runs_[p][1] = {uint32_t(halves_first + (2 * border_index) * run), false};
            edge_runs_[p][2] = {uint32_t(halves_first + (2 * border_index + 1) * run), false};
            ++border_index;
        } else {
            edge_runs_[p][1] = {spoke(q.triangle[1], (q.edge[1] + 1) % 3), true};
            edge_runs_[p][2] = {spoke(q.triangle[1], q.edge[1]), false};
        }
        interior_first_[p] = uint32_t(interior_first + size_t(p) * run * run);
    }
    total_ = interior_first + layout.patch_count() * size_t(run) * run;
    assert(total_ < kNone);
}

uint32_t SampleNumbering::id(uint32_t p, int i, int j) const {
    const int n = n_;
    const QuadPatch& q = layout_->patches()[p];
    if ((i == 0 || i == n) && (j == 0 || j == n)) {
        int c = i == 0 ? (j == 0 ? 0 : 3) : (j == 0 ? 1 : 2);
        return q.corner[c];
    }
    int e = -1, s = 0;  // edge and position along it from its start
    if (j == 0) e = 0, s = i;
    else if (i == n) e = 1, s = j;
    else if (j == n) e = 2, s = n - i;
    else if (i == 0) e = 3, s = n - j;
    if (e >= 0) {
        const EdgeRun& r = edge_runs_[p][e];
        return r.first + uint32_t(r.reversed ? n - 1 - s : s - 1);
    }
    return interior_first_[p] + uint32_t((j - 1) * (n - 1) + (i - 1));
}

}  // namespace catpaq::aqp
