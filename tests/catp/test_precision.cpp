// The precision the converter is asked for (`convert --precision`) holds: the finest level's
// measured distance to the input, both ways, is at most the precision, on meshes of several
// sizes, offsets and colourings, for every vertex layout; `verify` fails when it is exceeded.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "catp/builder.h"
#include "catp/dataset.h"
#include "catp/verify.h"
#include "mesh/generators.h"
#include "scratch_directory.h"

using namespace catpaq;
namespace fs = std::filesystem;

namespace {

std::string temp_path(const std::string& name) {
    static const catpaq::test::ScratchDirectory dir("catpaq_precision_");
    return (dir / (name + ".cpq")).string();
}

struct Converted {
    std::string path;
    CatpBuildReport report;
};

Converted convert(const Mesh& mesh, const std::string& name, Precision precision,
                  LayoutChoice layout = LayoutChoice::Auto, size_t leaf_triangles = 500) {
    Converted c;
    c.path = temp_path(name);
    CatpBuildSettings settings;
    settings.precision = precision;
    settings.layout = layout;
    settings.leaf_triangles = leaf_triangles;
    settings.progress = false;
    c.report = build_catp(mesh, c.path, settings);
    return c;
}

// The mean edge length of a mesh (model units), as the converter measures it.
double mean_edge(const Mesh& mesh) {
    double sum = 0;
    size_t n = 0;
    for (size_t t = 0; t < mesh.triangle_count(); ++t)
        for (int k = 0; k < 3; ++k) {
            const Vec3d& a = mesh.positions[mesh.indices[3 * t + size_t(k)]];
            const Vec3d& b = mesh.positions[mesh.indices[3 * t + size_t((k + 1) % 3)]];
            sum += std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
            ++n;
        }
    return sum / double(n);
}

Mesh shifted(Mesh mesh, double offset) {
    for (Vec3d& p : mesh.positions) p = {p[0] + offset, p[1] - 0.5 * offset, p[2] + 2 * offset};
    return mesh;
}

// Verifies with the original; returns the finest level's largest measured distance.
double expect_precision_holds(const Mesh& mesh, const Converted& c, double precision) {
    VerifySettings settings;
    settings.samples_per_level = 20000;
    VerifyReport r = verify_catp(c.path, &mesh, settings);
    EXPECT_TRUE(r.ok()) << (r.problems.empty() ? "" : r.problems[0]);
    EXPECT_FALSE(r.precision_exceeded);
    EXPECT_NEAR(r.precision, precision, precision * 1e-9) << "the dataset records the precision asked for";
    EXPECT_NEAR(c.report.precision, precision, precision * 1e-9);
    EXPECT_LE(c.report.leaf_step, precision) << "the leaves' quantization step is the guarantee";
    const VerifyLevel& finest = r.levels.back();
    const double measured = std::max(finest.distance_to_original_max, finest.distance_from_original_max);
    EXPECT_GE(measured, 0.0);
    EXPECT_LE(measured, precision);
    return measured;
}

}  // namespace

TEST(CatpPrecision, DefaultTenthOfTheMeanEdgeHoldsOnMeshesOfSeveralSizesAndOffsets) {
    struct Case {
        const char* name;
        Mesh mesh;
    };
    std::vector<Case> cases;
    cases.push_back({"sphere5k", make_sphere(5000, 1)});
    cases.push_back({"sphere60k", make_sphere(60000, 2)});
    cases.push_back({"scan40k", make_scan_like(40000, 3)});
    cases.push_back({"scan40k_at_1e6", shifted(make_scan_like(40000, 3), 1e6)});
    cases.push_back({"torus20k_at_-3e4", shifted(make_torus(20000, 4), -3e4)});
    for (const Case& c : cases) {
        SCOPED_TRACE(c.name);
        Converted out = convert(c.mesh, c.name, Precision{});
        const double edge = mean_edge(c.mesh);
        EXPECT_NEAR(out.report.mean_edge, edge, edge * 1e-6) << "the converter's mean edge";
        const double measured = expect_precision_holds(c.mesh, out, 0.1 * edge);
        std::printf("%-18s %s/%d leaf level %d: finest level within %.3g mean edges (asked 0.1)\n", c.name,
                    out.report.layout.name(), out.report.layout.grid, out.report.leaf_level, measured / edge);
    }
}

TEST(CatpPrecision, ModelUnitsAndFinerPrecisionsHoldInEveryLayout) {
    const Mesh mesh = make_scan_like(30000, 5);  // with colours
    const double edge = mean_edge(mesh);
    for (LayoutChoice layout : {LayoutChoice::Rgb24, LayoutChoice::Rgb18, LayoutChoice::Position48, LayoutChoice::Auto})
        for (double fraction : {0.3, 0.05, 0.01}) {
            SCOPED_TRACE(std::to_string(int(layout)) + " " + std::to_string(fraction));
            // Half of them in model units, half in mean edges: the same distance either way.
            const Precision p = fraction == 0.05 ? Precision{fraction * edge, 0} : Precision{0, fraction};
            Converted out = convert(mesh, "scan_l" + std::to_string(int(layout)) + "_" + std::to_string(fraction), p, layout);
            expect_precision_holds(mesh, out, fraction * edge);
            const VertexLayoutKind kind = out.report.layout.kind;
            switch (layout) {
                case LayoutChoice::Rgb24: EXPECT_EQ(kind, VertexLayoutKind::Rgb24); break;
                case LayoutChoice::Rgb18: EXPECT_EQ(kind, VertexLayoutKind::Rgb18); break;
                case LayoutChoice::Position48: EXPECT_EQ(kind, VertexLayoutKind::Position48); break;
                case LayoutChoice::Auto: EXPECT_TRUE(out.report.layout.has_color()) << "a coloured input keeps colour"; break;
            }
            EXPECT_GE(out.report.leaf_level, out.report.density_leaf_level) << "never shallower than the density";
        }
}

TEST(CatpPrecision, LayoutFollowsTheInputsColoursAndThePrecision) {
    Mesh coloured = make_sphere(20000, 6);
    ASSERT_FALSE(coloured.colors.empty());
    Mesh plain = coloured;
    plain.colors.clear();
    // Without colours: the 48-bit positions, with no deeper leaves than the density's.
    Converted a = convert(plain, "plain", Precision{0, 0.01});
    EXPECT_EQ(a.report.layout.kind, VertexLayoutKind::Position48);
    EXPECT_EQ(a.report.leaf_level, a.report.density_leaf_level);
    // With colours and a loose precision: full colour, and the 24-bit grid at its finest (the
    // coarse levels need it whatever the leaves ask).
    Converted b = convert(coloured, "loose", Precision{0, 1.0});
    EXPECT_EQ(b.report.layout.kind, VertexLayoutKind::Rgb24);
    EXPECT_EQ(b.report.layout.grid, kBaryGrid);
    // With colours and a precision beyond the 24-bit grid at the density's leaves (the finest
    // ones: where the precision is loose the coarsest leaves may sit above them): 6-bit colour.
    CatpFile loose(b.path);
    const CatpMeta& meta = loose.index().meta();
    double finest_step = 0;
    for (const ArchiveEntry& e : loose.index().entries())
        if (e.level == meta.leaf_level) {
            const DiamondInfo info = diamond_info(DiamondId{e.key});
            for (int s = 0; s < info.ring_size; ++s)
                for (int i = 0; i < 4; ++i)
                    for (int j = i + 1; j < 4; ++j) {
                        const Tetrahedron t = diamond_tetrahedron(info, s);
                        double d2 = 0;
                        for (int a = 0; a < 3; ++a) d2 += double(t[i][a] - t[j][a]) * double(t[i][a] - t[j][a]);
                        finest_step = std::max(finest_step, std::sqrt(d2) * meta.cell / meta.layout.grid);
                    }
            break;
        }
    ASSERT_GT(finest_step, 0.0);
    Converted c = convert(coloured, "tight", Precision{0, 0.5 * finest_step / b.report.mean_edge});
    EXPECT_EQ(c.report.layout.kind, VertexLayoutKind::Rgb18);
    EXPECT_EQ(c.report.leaf_level, c.report.density_leaf_level);
    // The dataset records all of it.
    CatpFile file(c.path);
    EXPECT_EQ(file.index().meta().layout, c.report.layout);
    EXPECT_EQ(file.index().meta().up, UpAxis::PosY);
    EXPECT_NEAR(file.index().meta().mean_edge, c.report.mean_edge, 1e-12);
}

TEST(CatpPrecision, VerifyFailsWhenTheFinestLevelIsFartherThanThePrecision) {
    const Mesh mesh = make_sphere(20000, 7);
    Converted out = convert(mesh, "sphere_verify", Precision{});
    // Against the original it holds; against the original moved by three precisions it cannot.
    VerifySettings settings;
    settings.samples_per_level = 5000;
    VerifyReport good = verify_catp(out.path, &mesh, settings);
    EXPECT_TRUE(good.ok());
    Mesh moved = mesh;
    for (Vec3d& p : moved.positions) p[0] += 3 * out.report.precision;
    VerifyReport bad = verify_catp(out.path, &moved, settings);
    EXPECT_TRUE(bad.precision_exceeded);
    EXPECT_FALSE(bad.ok());
    bool named = false;
    for (const std::string& p : bad.problems) named |= p.find("more than the precision") != std::string::npos;
    EXPECT_TRUE(named) << "the problem says what was exceeded";
}

TEST(CatpPrecision, AForcedLeafLevelThatCannotReachThePrecisionSaysSo) {
    const Mesh mesh = make_scan_like(20000, 8);
    CatpBuildSettings settings;
    settings.leaf_level = 3;  // far too coarse for a hundredth of an edge in 24-bit colour
    settings.layout = LayoutChoice::Rgb24;
    settings.precision = Precision{0, 0.01};
    settings.progress = false;
    const std::string path = temp_path("forced");
    CatpBuildReport r = build_catp(mesh, path, settings);
    ASSERT_EQ(r.warnings.size(), 1u);
    EXPECT_NE(r.warnings[0].find("cannot be reached"), std::string::npos) << r.warnings[0];
    EXPECT_EQ(r.leaf_level, 3);
    EXPECT_GT(r.leaf_step, 0.01 * r.mean_edge);
    // The dataset records what it does guarantee, and verify holds it to that.
    EXPECT_NEAR(r.precision, r.leaf_step, r.leaf_step * 1e-9);
    VerifySettings vs;
    vs.samples_per_level = 5000;
    EXPECT_TRUE(verify_catp(path, &mesh, vs).ok());
}

TEST(CatpPrecision, PrecisionAndLayoutOptionsParse) {
    Precision p;
    ASSERT_TRUE(parse_precision("0.25", p));
    EXPECT_EQ(p.model_units, 0.25);
    ASSERT_TRUE(parse_precision("0.1e", p));
    EXPECT_EQ(p.model_units, 0.0);
    EXPECT_EQ(p.mean_edges, 0.1);
    ASSERT_TRUE(parse_precision("2E", p));
    EXPECT_EQ(p.mean_edges, 2.0);
    for (const char* bad : {"", "e", "-1", "0", "0e", "abc", "1x", "nan", "inf"})
        EXPECT_FALSE(parse_precision(bad, p)) << bad;
    LayoutChoice l;
    EXPECT_TRUE(parse_layout_choice("position48", l));
    EXPECT_EQ(l, LayoutChoice::Position48);
    EXPECT_FALSE(parse_layout_choice("rgb32", l));
    UpAxis up;
    EXPECT_TRUE(parse_up_axis("-z", up));
    EXPECT_EQ(up, UpAxis::NegZ);
    EXPECT_TRUE(parse_up_axis("+y", up));
    EXPECT_EQ(up, UpAxis::PosY);
    EXPECT_FALSE(parse_up_axis("w", up));
}
