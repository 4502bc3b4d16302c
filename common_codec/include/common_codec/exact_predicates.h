#pragma once
// Exact geometric predicates on double coordinates (CGAL's filtered exact kernel, confined to
// this one translation unit to keep builds lean). "Exact" means the sign is the sign of the
// determinant computed with unlimited precision from the given doubles: no tolerance.
namespace catpaq {

// Sign of the orientation of (a, b, c, d): +1 if d is on the positive side of the plane through
// a, b, c (a, b, c, d positively oriented: det[b-a, c-a, d-a] > 0), -1 on the negative side,
// 0 if coplanar.
int orient3d(const double a[3], const double b[3], const double c[3], const double d[3]);

// Sign of det[b-a, c-a] in the plane spanned by two coordinate axes (i, j).
int orient2d(const double a[3], const double b[3], const double c[3], int i, int j);

}  // namespace catpaq
