// Normals by PCA over the k nearest neighbours, oriented consistently within a leaf, and radii
// that cover the sampled surface: the distance to a small k-th neighbour (estimate.h).
//
// Orientation: the sign of a PCA normal is arbitrary. Within a leaf, signs are propagated along
// the neighbour graph in Prim's order of the strongest agreement |n_i . n_j| first (Hoppe et
// al. 1992's minimum spanning tree, restricted to the leaf: it stays local, parallel and needs
// no global graph; agreements are ordered to a third of a degree, StepQueue), which crosses
// smooth regions before creases. Each connected piece then
// gets one global sign by majority vote against a reference direction (outward from the centre,
// or +z), which a few points of a concave region cannot overturn. Pieces are at most a leaf, so
// two leaves on either side of a fold may disagree; splats are lit two-sided by the client, so
// this only matters for back-face culling.
#include "estimate.h"
#include "grid_knn.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include <Eigen/Eigenvalues>

namespace catpaq::points_detail {
namespace {

constexpr size_t kOrientationLinks = 8;
// Points per occupied cell of the neighbour search's grid (grid_knn.h), for k = 16: on the 1M
// scan 4 took the least CPU (perf samples of the estimate: 2 -> 4824, 3 -> 4012, 4 -> 3410,
// 5 -> 3549, 8 -> 4927; smaller cells send more queries past their 3x3x3 block).
constexpr double kPointsPerCell = 4;

using DirectEigen = Eigen::internal::direct_selfadjoint_eigenvalues<Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>, 3, false>;

}  // namespace

// Eigen's computeDirect (Eigen/src/Eigenvalues/SelfAdjointEigenSolver.h, the 3x3 case) up to
// the smallest eigenvalue's vector, calling its own root and kernel functions on the same
// values, so the bits are the same; what is skipped is only what the other two vectors need
// (a second kernel, always, and a cross product). The solver was 5.1% of the 1M scan's
// conversion time.
void smallest_eigenvector(const double cov[6], double vector[3], double values[3]) {
    Eigen::Matrix3d m;
    m << cov[0], cov[1], cov[2], cov[1], cov[3], cov[4], cov[2], cov[4], cov[5];
    const double shift = m.trace() / 3.0;
    Eigen::Matrix3d scaled = m;
    scaled.diagonal().array() -= shift;
    const double scale = scaled.cwiseAbs().maxCoeff();
    if (scale > 0) scaled /= scale;
    Eigen::Vector3d roots;
    DirectEigen::computeRoots(scaled, roots);
    Eigen::Vector3d n;
    if ((roots(2) - roots(0)) <= Eigen::NumTraits<double>::epsilon()) {
        n = Eigen::Vector3d(1, 0, 0);  // all three the same: Eigen's identity
    } else {
        double d0 = roots(2) - roots(1), d1 = roots(1) - roots(0);
        Eigen::Matrix3d tmp = scaled;
        if (!(d0 > d1)) {  // Eigen's k = 0: the smallest's vector comes first, from its kernel
            tmp.diagonal().array() -= roots(0);
            Eigen::Vector3d representative;
            DirectEigen::extract_kernel(tmp, n, representative);
        } else {  // k = 2, l = 0
            d0 = d1;
            if (d0 <= 2 * Eigen::NumTraits<double>::epsilon() * d1) {
                // Eigen orthonormalizes the representative of the largest's kernel (as it does)
                Eigen::Vector3d largest;
                tmp.diagonal().array() -= roots(2);
                DirectEigen::extract_kernel(tmp, largest, n);
                n -= largest.dot(n) * n;
                n.normalize();
            } else {
                tmp.diagonal().array() -= roots(0);
                Eigen::Vector3d dummy;
                DirectEigen::extract_kernel(tmp, n, dummy);
            }
        }
    }
    roots *= scale;
    roots.array() += shift;
    for (int a = 0; a < 3; ++a) {
        vector[a] = n[a];
        values[a] = roots[a];
    }
}

// (Eigen's closed form takes an atan2, a sine and a cosine per call: with the rest of it, 6% of
// the 1M scan's conversion; on a plane's neighbourhood this takes three or four Newton steps.)
bool plane_eigenvector(const double cov[6], double vector[3], double values[3]) {
    const double xx = cov[0], xy = cov[1], xz = cov[2], yy = cov[3], yz = cov[4], zz = cov[5];
    // det(lambda I - C) = lambda^3 - c2 lambda^2 + c1 lambda - c0
    const double c2 = xx + yy + zz;
    const double c1 = xx * yy - xy * xy + xx * zz - xz * xz + yy * zz - yz * yz;
    const double c0 = xx * (yy * zz - yz * yz) - xy * (xy * zz - yz * xz) + xz * (xy * yz - yy * xz);
    if (!(c2 > 0) || !std::isfinite(c0 + c1 + c2)) return false;
    double lambda = 0;
    if (c0 > 0) {  // else the smallest eigenvalue is 0 (or below it by rounding): C's kernel
        bool settled = false;
        for (int step = 0; step < 8 && !settled; ++step) {
            const double p = ((lambda - c2) * lambda + c1) * lambda - c0;
            const double slope = (3 * lambda - 2 * c2) * lambda + c1;
            if (!(slope > 0)) return false;
            const double next = lambda - p / slope;
            settled = !(next - lambda > 1e-15 * c2);
            lambda = std::max(lambda, next);  // from below: a step back is rounding
        }
        if (!settled) return false;
    }
    // The other two: their sum and product from the coefficients; the larger from the sum, the
    // smaller from the product (no cancellation when it is small).
    const double sum = c2 - lambda, product = c1 - lambda * sum;
    const double larger = 0.5 * sum + std::sqrt(std::max(0.25 * sum * sum - product, 0.0));
    const double middle = larger > 0 ? product / larger : 0;
    if (!(middle - lambda > 1e-3 * larger)) return false;
    // The kernel of C - lambda I (Eigen's extract_kernel): the largest diagonal entry's column
    // crossed with each of the other two, the longer product normalized.
    const double m[3][3] = {{xx - lambda, xy, xz}, {xy, yy - lambda, yz}, {xz, yz, zz - lambda}};
    int i0 = 0;
    for (int i = 1; i < 3; ++i)
        if (std::fabs(m[i][i]) > std::fabs(m[i0][i0])) i0 = i;
    const double* r = m[i0];
    auto cross = [](const double* a, const double* b, double out[3]) {
        out[0] = a[1] * b[2] - a[2] * b[1];
        out[1] = a[2] * b[0] - a[0] * b[2];
        out[2] = a[0] * b[1] - a[1] * b[0];
        return out[0] * out[0] + out[1] * out[1] + out[2] * out[2];
    };
    double v0[3], v1[3];
    const double n0 = cross(r, m[(i0 + 1) % 3], v0), n1 = cross(r, m[(i0 + 2) % 3], v1);
    const double* v = n0 > n1 ? v0 : v1;
    const double length = std::sqrt(std::max(n0, n1));
    if (!(length > 0)) return false;
    for (int a = 0; a < 3; ++a) vector[a] = v[a] / length;
    values[0] = lambda;
    values[1] = middle;
    values[2] = larger;
    return true;
}

namespace {

// The unit normal of the points' best-fitting plane: the eigenvector of their covariance with
// the smallest eigenvalue; +z when the points do not span a plane (fewer than 3, or a line:
// then any direction across the line is as good, and +z unless the line is vertical).
Vec3f pca_normal(const Vec3d* positions, const uint32_t* index, size_t count) {
    if (count < 3) return {0, 0, 1};
    // The neighbours gathered once; the covariance's six distinct entries summed in the order
    // Eigen's d * d^T would (the same bits, a third of the instructions).
    double p[GridKnn::kMaxK][3];
    double c[3] = {0, 0, 0};
    for (size_t i = 0; i < count; ++i)
        for (int a = 0; a < 3; ++a) {
            p[i][a] = positions[index[i]][a];
            c[a] += p[i][a];
        }
    for (double& v : c) v /= double(count);
    double xx = 0, xy = 0, xz = 0, yy = 0, yz = 0, zz = 0;
    for (size_t i = 0; i < count; ++i) {
        const double dx = p[i][0] - c[0], dy = p[i][1] - c[1], dz = p[i][2] - c[2];
        xx += dx * dx;
        xy += dx * dy;
        xz += dx * dz;
        yy += dy * dy;
        yz += dy * dz;
        zz += dz * dz;
    }
    const double six[6] = {xx, xy, xz, yy, yz, zz};
    double vector[3], values[3];
    if (!plane_eigenvector(six, vector, values)) smallest_eigenvector(six, vector, values);
    Eigen::Vector3d n(vector[0], vector[1], vector[2]);
    // A line (or a point): the two smallest eigenvalues are both ~0 and the plane is undefined.
    if (!(values[1] > 1e-12 * values[2]) || !std::isfinite(n[0] + n[1] + n[2])) {
        Eigen::Matrix3d cov;  // (rare: the whole solver for the line's direction)
        cov << xx, xy, xz, xy, yy, yz, xz, yz, zz;
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
        solver.computeDirect(cov);
        Eigen::Vector3d along = solver.eigenvectors().col(2);
        n = along.cross(std::fabs(along[2]) < 0.9 ? Eigen::Vector3d(0, 0, 1) : Eigen::Vector3d(1, 0, 0)).normalized();
        if (!std::isfinite(n[0] + n[1] + n[2])) return {0, 0, 1};
    }
    return {float(n[0]), float(n[1]), float(n[2])};
}

// The distance to the radius_k-th neighbour (distance2[0] is the point itself), or to the farthest
// found when the cloud has fewer points. Why it covers: on a uniformly random sample of a plane,
// discs reaching each point's 6th neighbour leave 2.2e-4 of the plane uncovered (7th: 8e-5, 8th:
// 1.5e-5; 5th: 9e-4, 4th: 4e-3) with a mean radius of 1.36 spacings (1/sqrt(density)), and the
// radius follows the local density.
float coverage_radius(const float* distance2, size_t found, size_t radius_k) {
    if (found < 2) return 0.0f;
    return std::sqrt(distance2[std::min(radius_k, found - 1)]);
}

float dot(const Vec3f& a, const Vec3f& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

// The orientation's queue of steps, strongest agreement first: a bucket queue over the angle
// between the two normals rather than a binary heap. Agreements are |n_i . n_j| in [0, 1]; a
// step's bucket is sqrt(1 - agreement) in kAngleBuckets equal parts, which is nearly linear in
// the angle between the lines of the two normals (sqrt(1 - cos t) = sqrt(2) sin(t / 2)), so
// steps within about a third of a degree of each other share a bucket and pop last in, first
// out. Prim's order only has to cross smooth regions before creases, which are tens of degrees
// apart; the binary heap that ordered steps exactly was 10% of the 1M scan's conversion time
// (its sift-down's loads missed), pushes and pops here are a few instructions each.
// A step is the point it reaches, with the flip its normal needs if the step settles it: known
// when the step is queued (the sign of the dot product; neither normal changes while it waits).
class StepQueue {
public:
    static constexpr int kAngleBuckets = 256;

    static int bucket_of(float agreement) {
        const float gap = std::sqrt(std::max(1.0f - agreement, 0.0f));
        return std::min(int(gap * float(kAngleBuckets)), kAngleBuckets - 1);
    }
    void clear() {
        for (std::vector<uint32_t>& b : buckets_) b.clear();
        first_ = kAngleBuckets;
    }
    bool empty() {
        while (first_ < kAngleBuckets && buckets_[size_t(first_)].empty()) ++first_;
        return first_ == kAngleBuckets;
    }
    void push(int bucket, uint32_t to_flip) {
        buckets_[size_t(bucket)].push_back(to_flip);
        first_ = std::min(first_, bucket);
    }
    // The newest step of the strongest bucket; call after empty() said false.
    uint32_t pop() {
        std::vector<uint32_t>& b = buckets_[size_t(first_)];
        const uint32_t step = b.back();
        b.pop_back();
        return step;
    }

private:
    std::vector<uint32_t> buckets_[kAngleBuckets];
    int first_ = kAngleBuckets;  // no bucket before it holds a step
};

// Makes the orientation of normals[begin, end) consistent along the neighbour graph and votes
// each connected piece's sign (see the file comment).
void orient_leaf(const EstimateInput& in, size_t begin, size_t end, const std::vector<uint32_t>& neighbours,
                 size_t k, Vec3f* normals) {
    const size_t n = end - begin;
    // Kept per thread (as LeafScratch): the buckets no longer regrow from empty for each leaf.
    static thread_local std::vector<uint8_t> done;
    static thread_local std::vector<int> best;  // the strongest bucket queued to each point
    static thread_local std::vector<uint32_t> piece;
    static thread_local StepQueue queue;
    done.assign(n, 0);
    best.assign(n, StepQueue::kAngleBuckets);
    queue.clear();
    for (size_t seed = 0; seed < n; ++seed) {
        if (done[seed]) continue;
        piece.clear();
        queue.push(0, uint32_t(seed) << 1);
        while (!queue.empty()) {
            const uint32_t step = queue.pop();
            const uint32_t to = step >> 1;
            if (done[to]) continue;
            done[to] = 1;
            best[to] = -1;  // no step to it is queued any more (below)
            piece.push_back(to);
            Vec3f& normal = normals[begin + to];
            if (step & 1)
                for (float& v : normal) v = -v;
            for (size_t j = 0; j < k; ++j) {
                uint32_t other = neighbours[to * k + j];
                if (other == UINT32_MAX) continue;
                // A step no stronger than one already queued to the same point would pop after
                // it, when that point is done: it is not queued. A point done has the strongest
                // possible best: one test skips it too.
                const float product = dot(normal, normals[begin + other]);
                const int bucket = StepQueue::bucket_of(std::fabs(product));
                if (bucket >= best[other]) continue;
                best[other] = bucket;
                queue.push(bucket, other << 1 | uint32_t(product < 0));
            }
        }
        double vote = 0;
        for (uint32_t i : piece) {
            const Vec3f& normal = normals[begin + i];
            if (in.orient_up) {
                vote += normal[2];
            } else {
                const Vec3d& p = in.positions[begin + i];
                double length = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
                if (length > 0) vote += (normal[0] * p[0] + normal[1] * p[1] + normal[2] * p[2]) / length;
            }
        }
        if (vote < 0)
            for (uint32_t i : piece)
                for (float& v : normals[begin + i]) v = -v;
    }
}

// A first halo margin: 1.5 times the k-th neighbour distance on a surface sampled as densely as
// the leaf (its two largest sides taken as its area). Points whose neighbours reach farther get
// a wider halo in a second round, so the guess only trades halo size against rounds.
float first_margin(const float lo[3], const float hi[3], size_t n, size_t k) {
    float e[3] = {hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]};
    std::sort(e, e + 3, [](float a, float b) { return a > b; });
    const double area = e[1] > 0 ? double(e[0]) * e[1] : double(e[0]) * e[0];
    const double spacing = std::sqrt(area / double(std::max<size_t>(n, 1)));
    return float(1.5 * std::sqrt(double(k) / M_PI) * spacing);
}

// Per thread, kept from leaf to leaf: no allocations per leaf once warm.
struct LeafScratch {
    std::vector<uint32_t> ids;
    std::vector<float> xyz;
    std::vector<uint32_t> pending, next;  // the points still without neighbours
    std::vector<uint8_t> wanted;           // by leaf position: still without neighbours
    LocalKnn knn;
};

}  // namespace

void estimate_leaf(const EstimateInput& in, size_t begin, size_t end, Vec3f* normals, float* radii) {
    // The query finds the point itself first, then its neighbours: k + 1 for the k-th neighbour.
    const size_t radius_k = std::min<size_t>(std::max<size_t>(in.radius_neighbour, 1), GridKnn::kMaxK - 1);
    const size_t normal_k = std::min<size_t>(std::max<size_t>(in.neighbours, 3), GridKnn::kMaxK);
    const size_t k = std::max(normals ? normal_k : 0, radii ? radius_k + 1 : 0);
    if (k == 0 || end <= begin) return;
    const size_t n = end - begin;
    // Orientation follows the nearest few only: they are the most alike.
    const size_t links = std::min<size_t>(k, kOrientationLinks);
    static thread_local std::vector<uint32_t> local_neighbours;
    local_neighbours.assign(normals ? n * links : 0, UINT32_MAX);
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t i = begin; i < end; ++i)
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], in.xyz[3 * i + a]);
            hi[a] = std::max(hi[a], in.xyz[3 * i + a]);
        }
    static thread_local LeafScratch scratch;
    LeafScratch& s = scratch;
    // What a point's exact neighbours give it.
    auto settle = [&](uint32_t i, size_t found, const uint32_t* index, const float* distance2) {
        if (radii) radii[i] = coverage_radius(distance2, found, radius_k);
        if (normals) {
            const size_t used = std::min(found, normal_k);
            normals[i] = pca_normal(in.positions, index, used);
            for (size_t j = 0; j < std::min(used, links); ++j)
                if (index[j] >= begin && index[j] < end && index[j] != i)
                    local_neighbours[(i - begin) * links + j] = uint32_t(index[j] - begin);
        }
    };
    s.pending.resize(n);
    for (size_t i = 0; i < n; ++i) s.pending[i] = uint32_t(begin + i);
    s.wanted.assign(n, 1);
    float margin = first_margin(lo, hi, n, k);
    if (!(margin > 0)) margin = std::max(in.cloud_extent * 1e-6f, 1e-30f);
    // Rounds over the whole leaf while many points are left (a first margin guessed too small
    // doubles); the few left after that search the whole cloud.
    for (bool first = true; !s.pending.empty() && (first || s.pending.size() > std::max<size_t>(n / 16, 8)); first = false) {
        // A margin as wide as the cloud takes in every point: the neighbours found are exact.
        const bool everything = !(margin < in.cloud_extent);
        s.ids.resize(n);
        for (size_t i = 0; i < n; ++i) s.ids[i] = uint32_t(begin + i);
        float box_lo[3], box_hi[3];
        for (int a = 0; a < 3; ++a) {
            box_lo[a] = everything ? -INFINITY : lo[a] - margin;
            box_hi[a] = everything ? INFINITY : hi[a] + margin;
        }
        in.halo(box_lo, box_hi, begin, end, s.ids);
        s.xyz.resize(3 * s.ids.size());
        for (size_t i = 0; i < s.ids.size(); ++i)
            for (int a = 0; a < 3; ++a) s.xyz[3 * i + a] = in.xyz[3 * size_t(s.ids[i]) + a];
        s.knn.build(s.xyz.data(), s.ids.data(), s.ids.size(), kPointsPerCell);
        s.next.clear();
        auto wanted = [&](uint32_t id) { return id >= begin && id < end && s.wanted[id - begin]; };
        s.knn.all_nearest(k, wanted, [&](uint32_t i, const float* q, size_t found, const uint32_t* index, const float* distance2) {
            // A point outside the halo's box is farther from q than the margin plus q's distance
            // to the leaf box's nearest face: nearer neighbours than that are certain.
            float face = INFINITY;
            for (int a = 0; a < 3; ++a) face = std::min({face, q[a] - lo[a], hi[a] - q[a]});
            if (!everything) {
                const float reach = found == k ? std::sqrt(distance2[k - 1]) : INFINITY;
                if (!(reach <= margin + face)) {
                    s.next.push_back(i);
                    return;
                }
            }
            s.wanted[i - begin] = 0;
            settle(i, found, index, distance2);
        });
        s.pending.swap(s.next);
        margin *= 2;
    }
    // The few left search the whole cloud: a halo wide enough for an outlier's far neighbours
    // around the whole leaf would gather a big part of the cloud for every leaf holding one.
    uint32_t index[GridKnn::kMaxK];
    float distance2[GridKnn::kMaxK];
    for (const uint32_t i : s.pending) settle(i, in.nearest(&in.xyz[3 * size_t(i)], k, index, distance2), index, distance2);
    if (normals) orient_leaf(in, begin, end, local_neighbours, links, normals);
}

}  // namespace catpaq::points_detail
