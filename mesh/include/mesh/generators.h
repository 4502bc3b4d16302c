#pragma once
// Deterministic procedural meshes for tests and benchmarks. The same arguments give the same
// bytes on every machine: randomness comes from our own splitmix64, angles from our own sin/cos
// polynomials, and positions use only + - * / and sqrt (exactly rounded by IEEE 754), with FMA
// contraction off project-wide. Nothing reads the clock or std:: distributions.
#include <cstddef>
#include <cstdint>

#include "mesh/mesh.h"

namespace catpaq {

// A closed, consistently outward-oriented unit sphere (centre 0, radius 1; a "cube sphere":
// a subdivided box projected onto the sphere) with unit normals and a smooth colour field
// chosen by `seed`. Triangle count within 1 of max(target_triangles, 12). Positions are
// float-representable, so a float PLY round trip is exact. Every edge is used by exactly two
// triangles.
Mesh make_sphere(size_t target_triangles, uint64_t seed = 1);

// A closed torus of genus 1 (major radius 1, minor radius 0.35, around the z axis) with unit
// normals and colours. Triangle count within 1 of max(target_triangles, 18).
Mesh make_torus(size_t target_triangles, uint64_t seed = 1);

// A dense "scanned statue": a closed star-shaped blob (a cube sphere displaced along its radius
// by multi-octave value noise, the finest octave a few triangles wide), scaled by
// (0.8, 1.3, 0.7) so it lies within [-1.04,1.04] x [-1.69,1.69] x [-0.91,0.91], with stone-like
// colours and area-weighted normals. `seed` changes the shape. Triangle count within 1 of
// max(target_triangles, 12). Memory and time are proportional to the output (20M triangles: about
// 6 s of CPU, spread over the available cores).
Mesh make_scan_like(size_t target_triangles, uint64_t seed = 1);

// Density that varies about a hundredfold, as in a scan with one finely detailed region: a
// scan-like blob (make_scan_like) with an eighth of the triangles, and inside it, apart from
// it, a sphere of radius 0.15 about the origin with the rest. Two closed surfaces. Triangle
// count within 2 of max(target_triangles, 96).
Mesh make_uneven_density(size_t target_triangles, uint64_t seed = 1);

// Small meshes that stress numerical robustness. Unless stated otherwise a case's bounding box
// is exactly [0,1]^3: the converter then uses the root cube [-0.5,1.5]^3, whose bisection planes
// are x, y, z in {0.5, 0, 1, 0.25, 0.75, ...} and whose diagonal planes (x=y, x+y=1, ...) pass
// through the centre. All cases have unit normals and colours; `seed` only permutes vertex and
// triangle order, rotates triangle corners (keeping orientation) and recolours, so geometry and
// topology do not depend on it.
enum class HardCase {
    // A closed box-like surface on a 1/16 lattice whose faces are pushed in as step pyramids
    // (depths k/64): thousands of vertices and whole edges lie exactly in the planes x, y or z =
    // k/16 (0.5, 0.25, ...), and face diagonals run along x=y, x+y=1 and their kin. 3072 triangles.
    OnBisectionPlanes,
    // Closed components (they may intersect one another): an octahedron spanning the box, plus
    // tetrahedra with a vertex exactly at the centre (0.5,0.5,0.5), vertices at (0.5,0.5,0.25) and
    // on the line x=y=z, a face containing the centre in its interior, and edges passing through
    // the centre (along x=y=z) and through (0.5,0.5,0.75).
    OnLatticeEdgesAndCorners,
    // Three closed needle bicones (aspect ratio above 1000) crossing the whole box, one from corner
    // (0,0,0) to corner (1,1,1).
    Slivers,
    // A closed box surface plus zero-area triangles (a repeated index, all three indices equal,
    // and a collinear triple of distinct vertices in both orientations) and exact duplicates (same
    // indices, and the same indices reversed). count_border_edges is 0.
    DegenerateAndDuplicateTriangles,
    // Three sheets sharing one edge, plus two closed boxes sharing one edge (same vertices):
    // 2 non-manifold edges and 9 border edges.
    NonManifoldEdges,
    // A sphere with four rectangular holes: an open surface with 36 border edges.
    Holes,
    // A 32 x 32 planar grid of zero thickness: bounding box [0,1] x [0,1] x {0.5}, 128 border edges.
    Flat,
    // The same grid in the tilted plane z = (x + y) / 2 (bounding box [0,1]^3), 128 border edges.
    FlatTilted,
    // OnBisectionPlanes offset by (1e6, 2e6, -1e6): bounding box [1e6, 1e6+1] x [2e6, 2e6+1] x
    // [-1e6, -1e6+1], every coordinate exactly representable in double (not in float).
    FarFromOrigin,
    // The same offset by (1e7, 2e7, -1e7): the spacing of doubles there is 2^-28 to 2^-27 (about
    // 4e-9 to 7e-9), still exact for the 1/64 steps of the model.
    FarFromOrigin1e7,
    // A closed sphere with bounding box [0, 1e-4]^3.
    Tiny,
    // A closed box surface on an 8^3 grid where about 60 triangles are split around slivers of
    // relative area 1e-12 to 1e-6 (a vertex at that height above an edge, in the plane or off
    // it): near-degenerate, never exactly degenerate; closed and consistently oriented.
    NearDegenerateTriangles,
};

inline constexpr HardCase kAllHardCases[] = {
    HardCase::OnBisectionPlanes, HardCase::OnLatticeEdgesAndCorners,
    HardCase::Slivers,           HardCase::DegenerateAndDuplicateTriangles,
    HardCase::NonManifoldEdges,  HardCase::Holes,
    HardCase::Flat,              HardCase::FlatTilted,
    HardCase::FarFromOrigin,     HardCase::FarFromOrigin1e7,
    HardCase::Tiny,              HardCase::NearDegenerateTriangles,
};

const char* hard_case_name(HardCase c);  // the enumerator's name, e.g. "OnBisectionPlanes"
Mesh make_hard_case(HardCase c, uint64_t seed = 1);
size_t hard_case_border_edges(HardCase c);  // as documented above; 0 for closed cases
Bounds hard_case_bounds(HardCase c);        // the exact bounding box documented above

}  // namespace catpaq
