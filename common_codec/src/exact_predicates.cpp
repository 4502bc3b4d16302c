// The only translation unit of common_codec that includes CGAL.
#include "common_codec/exact_predicates.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

namespace catpaq {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;

int orient3d(const double a[3], const double b[3], const double c[3], const double d[3]) {
    Kernel::Point_3 pa(a[0], a[1], a[2]), pb(b[0], b[1], b[2]), pc(c[0], c[1], c[2]), pd(d[0], d[1], d[2]);
    return int(CGAL::orientation(pa, pb, pc, pd));
}

int orient2d(const double a[3], const double b[3], const double c[3], int i, int j) {
    Kernel::Point_2 pa(a[i], a[j]), pb(b[i], b[j]), pc(c[i], c[j]);
    return int(CGAL::orientation(pa, pb, pc));
}

}  // namespace catpaq
