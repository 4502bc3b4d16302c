// `verify` tells the truth both ways: it passes valid datasets (also of open and non-manifold
// inputs, whose borders may lie exactly in a tetrahedron face), and fails datasets with a crack,
// with missing geometry, or whose measured distance to the original exceeds the stored bound.
#include <gtest/gtest.h>

#include <filesystem>
#include <functional>

#include "catp/builder.h"
#include "catp/dataset.h"
#include "catp/verify.h"
#include "common_codec/barycentric.h"
#include "mesh/generators.h"
#include "scratch_directory.h"

using namespace catpaq;
namespace fs = std::filesystem;

namespace {

const fs::path& scratch_dir() {
    static const catpaq::test::ScratchDirectory dir("catpaq_verify_");
    return dir.path();
}

std::string build(const Mesh& mesh, const std::string& name, size_t leaf_triangles) {
    std::string path = (scratch_dir() / (name + ".cpq")).string();
    CatpBuildSettings settings;
    settings.leaf_triangles = leaf_triangles;
    settings.progress = false;
    build_catp(mesh, path, settings);
    return path;
}

VerifyReport verify(const std::string& path, const Mesh* original) {
    VerifySettings settings;
    settings.samples_per_level = 5000;
    return verify_catp(path, original, settings);
}

std::string problems(const VerifyReport& r) {
    std::string out;
    for (const std::string& p : r.problems) out += p + "\n";
    return out;
}

// A 40 x 40 grid in z = 0 over [0,1]^2, a fin standing on one of its border edges, a fin on its
// diagonal (in the plane x = y, a plane of the lattice's faces), and a bowtie (two triangles
// sharing one vertex) above it: open, with a non-manifold edge.
Mesh grid_with_fin_and_bowtie() {
    Mesh m;
    const int n = 40;
    auto at = [&](int i, int j) { return uint32_t(j * (n + 1) + i); };
    for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i) m.positions.push_back({double(i) / n, double(j) / n, 0.0});
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i)
            m.indices.insert(m.indices.end(), {at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    auto vertex = [&](double x, double y, double z) {
        m.positions.push_back({x, y, z});
        return uint32_t(m.positions.size() - 1);
    };
    m.indices.insert(m.indices.end(), {at(0, 0), at(1, 0), vertex(0.5 / n, 0, 0.3)});
    m.indices.insert(m.indices.end(), {at(n / 2, n / 2), at(n / 2 + 1, n / 2 + 1), vertex(0.5, 0.5, 0.3)});
    uint32_t b = vertex(0.2, 0.2, 0.2);
    vertex(0.3, 0.2, 0.2), vertex(0.25, 0.3, 0.2), vertex(0.35, 0.3, 0.2), vertex(0.3, 0.4, 0.2);
    m.indices.insert(m.indices.end(), {b, b + 1, b + 2, b + 2, b + 3, b + 4});
    return m;
}

// A closed sphere with extra triangles: a flap from the centre (an edge along the x axis, in
// the lattice's diagonal plane y = z), one floating outside, and one on a sphere edge (three
// triangles on that edge).
Mesh sphere_with_extra_triangles() {
    Mesh m = make_sphere(2000, 3);
    m.normals.clear();
    m.colors.clear();
    auto vertex = [&](double x, double y, double z) {
        m.positions.push_back({x, y, z});
        return uint32_t(m.positions.size() - 1);
    };
    m.indices.insert(m.indices.end(), {vertex(0, 0, 0), vertex(0.5, 0, 0), vertex(0, 0.5, 0)});
    m.indices.insert(m.indices.end(), {vertex(1.2, 0, 0), vertex(1.5, 0.1, 0), vertex(1.3, 0.3, 0.1)});
    uint32_t a = m.indices[300], b = m.indices[301];
    m.indices.insert(m.indices.end(), {a, b, vertex(0, 0, 0.2)});
    return m;
}

// Rewrites a dataset with every node passed through `edit` (which may change its fragments);
// the index counts and the meta's slot table follow the payload.
void rewrite(const std::string& from, const std::string& to,
             const std::function<void(const ArchiveEntry&, DiamondFragments&)>& edit) {
    CatpFile file(from);
    ArchiveWriter writer(to, ArchiveKind::Catp);
    CatpMeta meta = file.index().meta();
    meta.slot_bytes.clear();
    std::vector<ArchiveEntry> written;  // (the slot table's writer checks it against them)
    for (const ArchiveEntry& e : file.index().entries()) {  // in index order, as the slot table
        DiamondFragments node = file.decode(e);
        edit(e, node);
        ArchiveEntry entry = e;
        entry.count = 0;
        for (int s = 0; s < 8; ++s)
            if (node.slot_mask & (1 << s)) entry.count += uint32_t(node.slots[s].triangle_count());
        entry.flags = uint16_t((entry.flags & ~0xffu) | node.slot_mask);
        std::vector<uint32_t> slot_bytes;
        std::vector<uint8_t> bytes = encode_diamond_node(node, &slot_bytes);
        meta.slot_bytes.insert(meta.slot_bytes.end(), slot_bytes.begin(), slot_bytes.end());
        writer.add_node(entry, bytes.data(), bytes.size());
        entry.size = uint32_t(bytes.size());
        written.push_back(entry);
    }
    writer.finish(encode_catp_meta(meta, written));
}

// The first leaf-level fragment vertex with exactly one zero weight (on one face of its
// tetrahedron, not on an edge of it): its slot and index, or false.
bool find_face_vertex(const DiamondFragments& node, int& slot, size_t& vertex) {
    for (int s = 0; s < 8; ++s) {
        if (!(node.slot_mask & (1 << s))) continue;
        for (size_t v = 0; v < node.slots[s].vertices.size(); ++v) {
            BaryWeights w;
            vertex_weights(node.slots[s].vertices[v], node.slots[s].layout, w);
            int zeros = (w[0] == 0) + (w[1] == 0) + (w[2] == 0) + (w[3] == 0);
            if (zeros == 1) {
                slot = s;
                vertex = v;
                return true;
            }
        }
    }
    return false;
}

}  // namespace

// Before, verify only printed the distances: the wrong original (4 diagonals away) still gave
// "verify: OK".
TEST(Verify, FailsWhenTheMeasuredDistanceExceedsTheStoredBound) {
    Mesh sphere = make_sphere(3000, 4);
    std::string path = build(sphere, "sphere", 300);
    VerifyReport good = verify(path, &sphere);
    EXPECT_TRUE(good.ok()) << problems(good);
    EXPECT_EQ(good.bound_violations, 0u);

    Mesh elsewhere = sphere;
    double shift = 4 * sphere.bounds().diagonal();
    for (Vec3d& p : elsewhere.positions) p[0] += shift;
    VerifyReport bad = verify(path, &elsewhere);
    EXPECT_FALSE(bad.ok());
    EXPECT_GT(bad.bound_violations, 0u);
    ASSERT_FALSE(bad.problems.empty());
    EXPECT_NE(problems(bad).find("exceeds the stored bound"), std::string::npos) << problems(bad);
    EXPECT_NE(problems(bad).find(" by "), std::string::npos) << problems(bad);
}

// Before, both datasets failed the shared-face check: their inputs end (or branch) exactly in
// planes of the lattice's faces, which the check took for cracks. face_border_edges counts the
// edges it used to fail on.
TEST(Verify, PassesDatasetsOfOpenAndNonManifoldInputs) {
    for (auto [name, mesh] : {std::pair{"grid_fin_bowtie", grid_with_fin_and_bowtie()},
                              std::pair{"sphere_extra", sphere_with_extra_triangles()}}) {
        SCOPED_TRACE(name);
        std::string path = build(mesh, name, 200);
        VerifyReport alone = verify(path, nullptr);
        EXPECT_TRUE(alone.ok()) << problems(alone);
        EXPECT_GT(alone.face_border_edges, 0u) << "the case this test is about does not occur";
        VerifyReport with_original = verify(path, &mesh);
        EXPECT_TRUE(with_original.ok()) << problems(with_original);
        EXPECT_EQ(with_original.border_cracks, 0u);
    }
}

// A vertex on a shared face moved along the face (one grid step): the two sides of the face end
// at different edges, a crack, caught without the original.
TEST(Verify, FailsACrackWhereTheTwoSidesOfAFaceDisagree) {
    Mesh sphere = make_sphere(4000, 5);
    std::string path = build(sphere, "crack_source", 300);
    ASSERT_TRUE(verify(path, nullptr).ok());
    std::string cracked = (scratch_dir() / "cracked.cpq").string();
    bool moved = false;
    rewrite(path, cracked, [&](const ArchiveEntry& e, DiamondFragments& node) {
        int slot;
        size_t v;
        if (moved || !(e.flags & kCatpLeafFlag) || !find_face_vertex(node, slot, v)) return;
        PackedVertex& p = node.slots[slot].vertices[v];
        const VertexLayout layout = node.slots[slot].layout;
        BaryWeights w;
        vertex_weights(p, layout, w);
        int from = -1, to = -1;  // two non-zero corners: the vertex stays in the face
        for (int k = 0; k < 4; ++k)
            if (w[k] != 0) (from < 0 && w[k] > 1 ? from : to) = k;
        ASSERT_GE(from, 0);
        ASSERT_GE(to, 0);
        w[from]--;
        w[to]++;
        const uint8_t rgb[3] = {0, 0, 0};
        const uint64_t colour = p.payload() & ~((uint64_t(1) << layout.color_shift()) - 1);
        p = PackedVertex::from_payload(pack_vertex(layout, w, 0, rgb).payload() | colour, p.normal());
        moved = true;
    });
    ASSERT_TRUE(moved);
    VerifyReport r = verify(cracked, nullptr);
    EXPECT_FALSE(r.ok());
    EXPECT_GT(r.face_mismatches, 0u);
    EXPECT_NE(problems(r).find("crack"), std::string::npos) << problems(r);
    // With the original too (a closed sphere: no edge of it is the input's border).
    VerifyReport with_original = verify(cracked, &sphere);
    EXPECT_FALSE(with_original.ok());
    EXPECT_GT(with_original.face_mismatches, 0u);
}

// A triangle touching a shared face removed: only one side ends there, which the face alone
// cannot tell from an input border; with the original, the border check fails it.
TEST(Verify, FailsMissingGeometryWithTheOriginal) {
    Mesh sphere = make_sphere(4000, 6);
    std::string path = build(sphere, "hole_source", 300);
    std::string holed = (scratch_dir() / "holed.cpq").string();
    bool removed = false;
    rewrite(path, holed, [&](const ArchiveEntry& e, DiamondFragments& node) {
        int slot;
        size_t v;
        if (removed || !(e.flags & kCatpLeafFlag) || !find_face_vertex(node, slot, v)) return;
        std::vector<uint32_t>& indices = node.slots[slot].indices;
        for (size_t t = 0; t + 2 < indices.size(); t += 3)
            if (indices[t] == v || indices[t + 1] == v || indices[t + 2] == v) {
                indices.erase(indices.begin() + long(t), indices.begin() + long(t) + 3);
                removed = true;
                return;
            }
    });
    ASSERT_TRUE(removed);
    VerifyReport with_original = verify(holed, &sphere);
    EXPECT_FALSE(with_original.ok());
    EXPECT_GT(with_original.border_cracks, 0u) << problems(with_original);
    EXPECT_NE(problems(with_original).find("not on the original's border"), std::string::npos) << problems(with_original);
}
