// Each point's normal and local Delaunay triangles as potpourri3d's point-cloud heat method makes them
// (geometry-central's buildLocalTriangulations; gegnn/cloud_heat.py describes every step), one point at a
// time without the interpreter (Python threads run blocks of rows side by side, gegnn/threads.py):
//
//   normal     the third left singular vector of the 3 x k matrix of neighbour offsets, sign included, as
//              Eigen 3.3.9's JacobiSVD computes it in the library's x86-64 build (SSE2, no FMA): column-
//              pivoting Householder QR of the transpose with Eigen's reduction orders, two-sided Jacobi
//              sweeps on R^T, singular values sorted;
//   tangent    coordinates of the offsets in the frame x = unit(t x n), y = unit(n x x), t = e_x (e_y where
//              |n_x| > 0.9);
//   triangles  the neighbours sorted by angle (std::sort, as the library), sweeps dropping a neighbour where
//              the two triangles it closes with its angular neighbours fail the in-circle test (or, of two
//              collinear ones, the farther), then (point, a, b) for consecutive kept neighbours, a x b > 0.
//
// Every operation is the library's in its order, in IEEE double without contraction (-ffp-contract=off),
// so the normals and triangles are its own bit for bit (tests against potpourri3d).
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <utility>
#include <vector>

namespace nb = nanobind;

namespace {

using Points = nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using Rows = nb::ndarray<const int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Index = nb::ndarray<const int64_t, nb::ndim<2>, nb::c_contig, nb::device::cpu>;

constexpr double TINY = std::numeric_limits<double>::min();
constexpr double EPS = std::numeric_limits<double>::epsilon();
constexpr double DEGENERATE = 1e-7;  // relative to the neighbourhood radius
constexpr double PI = 3.141592653589793;

// Sum of squares of x[0..size) in the order of Eigen 3.3's SSE2 reduction: two 2-lane accumulators over
// blocks of four, merged, one more pair, the lanes added, then the odd last element.
double eigen_sum_squares(const double* x, int64_t size) {
    if (size < 2) return size ? x[0] * x[0] : 0.0;
    const int64_t end2 = size / 4 * 4, end = size / 2 * 2;
    double p0[2] = {x[0] * x[0], x[1] * x[1]};
    if (end > 2) {
        double p1[2] = {x[2] * x[2], x[3] * x[3]};
        for (int64_t i = 4; i < end2; i += 4) {
            p0[0] += x[i] * x[i];
            p0[1] += x[i + 1] * x[i + 1];
            p1[0] += x[i + 2] * x[i + 2];
            p1[1] += x[i + 3] * x[i + 3];
        }
        p0[0] += p1[0];
        p0[1] += p1[1];
        if (end > end2) {
            p0[0] += x[end2] * x[end2];
            p0[1] += x[end2 + 1] * x[end2 + 1];
        }
    }
    double out = p0[0] + p0[1];
    if (end < size) out = out + x[end] * x[end];
    return out;
}

// Dot product of x and y over [0, depth) as Eigen 3.3's row-major GEMV kernel sums a row (SSE2): the elements
// before the first aligned one (`start`) one by one, two lanes over the aligned pairs, their sum, the rest.
double eigen_dot(const double* x, const double* y, int64_t depth, int64_t start) {
    double out = 0.0;
    for (int64_t i = 0; i < std::min(start, depth); ++i) out = out + x[i] * y[i];
    const int64_t end = start + (depth - start) / 2 * 2;
    if (end > start) {
        double lanes[2] = {x[start] * y[start], x[start + 1] * y[start + 1]};
        for (int64_t i = start + 2; i < end; i += 2) {
            lanes[0] += x[i] * y[i];
            lanes[1] += x[i + 1] * y[i + 1];
        }
        out = out + (lanes[0] + lanes[1]);
    }
    for (int64_t i = std::max(end, start); i < depth; ++i) out = out + x[i] * y[i];
    return out;
}

// One point's working arrays, made once a call and reused point after point: the k offsets (k x 3), the
// QR's columns and Householder vector, the tangent coordinates (pushed out where degenerate), their
// angles and angular order, the sorted coordinates and the ring of kept neighbours.
struct Scratch {
    explicit Scratch(int64_t k)
        : offsets(static_cast<size_t>(3 * k)), a(offsets.size()), essential(static_cast<size_t>(k)), px(essential),
          py(essential), angle(essential), x(essential), y(essential), len(essential), sq(essential),
          order(static_cast<size_t>(k)), prv(order), nxt(order), valid(static_cast<size_t>(k)) {}
    std::vector<double> offsets, a, essential, px, py, angle, x, y, len, sq;
    std::vector<int64_t> order, prv, nxt;
    std::vector<char> valid;
};

// The unit normal of one point from its k offsets (s.offsets, k x 3, row-major): Eigen's
// JacobiSVD(M, ComputeThinU) of the 3 x k matrix M = offsets^T, last column of U.
std::array<double, 3> svd_normal(int64_t k, Scratch& s) {
    const double* offsets = s.offsets.data();
    std::vector<double>& a = s.a;
    std::vector<double>& essential = s.essential;
    double scale = 0.0;
    for (int64_t e = 0; e < 3 * k; ++e) scale = std::max(scale, std::abs(offsets[e]));
    if (scale == 0.0) scale = 1.0;
    // a[c * k + r]: column c of the k x 3 matrix offsets / scale (the QR's input, M^T)
    for (int64_t r = 0; r < k; ++r)
        for (int c = 0; c < 3; ++c) a[c * k + r] = offsets[3 * r + c] / scale;
    double direct[3], updated[3];
    int perm[3] = {0, 1, 2};
    for (int c = 0; c < 3; ++c) direct[c] = updated[c] = std::sqrt(eigen_sum_squares(&a[c * k], k));
    const double downdate_floor = std::sqrt(EPS);
    for (int col = 0; col < 3; ++col) {
        int big = col;
        for (int c = col + 1; c < 3; ++c)
            if (updated[c] > updated[big]) big = c;
        if (big != col) {
            std::swap_ranges(&a[col * k], &a[col * k] + k, &a[big * k]);
            std::swap(updated[col], updated[big]);
            std::swap(direct[col], direct[big]);
            std::swap(perm[col], perm[big]);
        }
        double* v = &a[col * k];
        const double c0 = v[col];
        const double* tail = v + col + 1;
        const int64_t n_tail = k - col - 1;
        const double tail_sq = eigen_sum_squares(tail, n_tail);
        double beta, tau;
        if (tail_sq <= TINY) {
            beta = c0;
            tau = 0.0;
            std::fill(essential.begin(), essential.begin() + n_tail, 0.0);
        } else {
            beta = std::sqrt(c0 * c0 + tail_sq);
            if (c0 >= 0) beta = -beta;
            for (int64_t r = 0; r < n_tail; ++r) essential[r] = tail[r] / (c0 - beta);
            tau = (beta - c0) / beta;
        }
        v[col] = beta;
        for (int j = col + 1; j < 3; ++j) {
            double* w = &a[j * k] + col;  // column j from row col
            // applyHouseholderOnTheLeft; the essential part starts at element col * k + col + 1 of the
            // 16-byte aligned column-major storage
            const double tmp = eigen_dot(essential.data(), w + 1, n_tail, (col * k + col + 1) % 2) + w[0];
            if (tau != 0) {
                w[0] = w[0] - tau * tmp;
                for (int64_t r = 0; r < n_tail; ++r) w[1 + r] = w[1 + r] - tmp * (tau * essential[r]);
            }
            const double u = updated[j];
            if (u != 0) {
                double t = std::abs(w[0]) / u;
                t = (1 + t) * (1 - t);
                if (t < 0) t = 0.0;
                const double ratio = u / direct[j];
                const double t2 = t * (ratio * ratio);
                if (t2 <= downdate_floor) {
                    direct[j] = updated[j] = std::sqrt(eigen_sum_squares(w + 1, n_tail));
                } else {
                    updated[j] = u * std::sqrt(t);
                }
            }
        }
    }
    // W = R^T (lower triangular): row i of W is column i of R
    double W[3][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j <= i; ++j) W[i][j] = a[i * k + j];
    double U[3][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
    for (int c = 0; c < 3; ++c) U[perm[c]][c] = 1.0;
    double max_diag = std::max(std::max(std::abs(W[0][0]), std::abs(W[1][1])), std::abs(W[2][2]));
    constexpr int PAIRS[3][2] = {{1, 0}, {2, 0}, {2, 1}};
    bool rotated = true;
    while (rotated) {
        rotated = false;
        for (const auto& pq : PAIRS) {
            const int p = pq[0], q = pq[1];
            const double threshold = std::max(TINY, 2 * EPS * max_diag);
            if (!(std::abs(W[p][q]) > threshold || std::abs(W[q][p]) > threshold)) continue;
            rotated = true;
            const double m00 = W[p][p], m01 = W[p][q], m10 = W[q][p], m11 = W[q][q];
            // real_2x2_jacobi_svd: a rotation making the block symmetric, then its Jacobi rotation
            const double t = m00 + m11, d = m10 - m01;
            double c1 = 1.0, s1 = 0.0;
            if (!(std::abs(d) < TINY)) {
                const double ratio = t / d;
                const double root = std::sqrt(1 + ratio * ratio);
                s1 = 1 / root;
                c1 = ratio / root;
            }
            const double a00 = c1 * m00 + s1 * m10, a01 = c1 * m01 + s1 * m11, a11 = -s1 * m01 + c1 * m11;
            const double deno = 2 * std::abs(a01);
            double cr = 1.0, sr = 0.0;
            if (!(deno < TINY)) {
                const double tau = (a00 - a11) / deno;
                const double wv = std::sqrt(tau * tau + 1);
                const double tt = tau > 0 ? 1 / (tau + wv) : 1 / (tau - wv);
                const double nn = 1 / std::sqrt(tt * tt + 1);
                sr = -(tt > 0 ? 1.0 : -1.0) * (a01 / std::abs(a01)) * std::abs(tt) * nn;
                cr = nn;
            }
            const double cl = c1 * cr + s1 * sr, sl = -c1 * sr + s1 * cr;  // j_left = rot1 * j_right^T
            for (int j = 0; j < 3; ++j) {  // rows p, q of W by j_left
                const double wp = W[p][j], wq = W[q][j];
                W[p][j] = cl * wp + sl * wq;
                W[q][j] = -sl * wp + cl * wq;
            }
            for (int i = 0; i < 3; ++i) {  // columns p, q of U by j_left
                const double up = U[i][p], uq = U[i][q];
                U[i][p] = cl * up + sl * uq;
                U[i][q] = -sl * up + cl * uq;
            }
            for (int i = 0; i < 3; ++i) {  // columns p, q of W by j_right
                const double wp = W[i][p], wq = W[i][q];
                W[i][p] = cr * wp - sr * wq;
                W[i][q] = sr * wp + cr * wq;
            }
            max_diag = std::max(max_diag, std::max(std::abs(W[p][p]), std::abs(W[q][q])));
        }
    }
    double sv[3];
    for (int j = 0; j < 3; ++j) {
        sv[j] = std::abs(W[j][j]);
        if (W[j][j] < 0)
            for (int i = 0; i < 3; ++i) U[i][j] = -U[i][j];
    }
    for (int i = 0; i < 3; ++i) {  // sort descending, the first maximum wins
        int pos = i;
        for (int j = i + 1; j < 3; ++j)
            if (sv[j] > sv[pos]) pos = j;
        if (pos != i && sv[pos] != 0) {
            std::swap(sv[i], sv[pos]);
            for (int r = 0; r < 3; ++r) std::swap(U[r][i], U[r][pos]);
        }
    }
    const double inv = 1 / std::sqrt(U[0][2] * U[0][2] + U[1][2] * U[1][2] + U[2][2] * U[2][2]);
    return {U[0][2] * inv, U[1][2] * inv, U[2][2] * inv};
}

using V3 = std::array<double, 3>;
V3 cross(const V3& a, const V3& b) {
    return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double dot(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
V3 unit(const V3& v) {
    const double inv = 1 / std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    return {v[0] * inv, v[1] * inv, v[2] * inv};
}

// The point's triangles (point, a, b) appended to `faces` from its neighbours' tangent coordinates
// (s.px, s.py).
void local_triangles(int64_t point, const int64_t* neighbors, int64_t k, Scratch& s, std::vector<int64_t>& faces) {
    std::vector<double> &px = s.px, &py = s.py, &angle = s.angle, &x = s.x, &y = s.y, &len = s.len, &sq = s.sq;
    std::vector<int64_t> &order = s.order, &prv = s.prv, &nxt = s.nxt;
    std::vector<char>& valid = s.valid;
    double radius2 = 0.0;
    for (int64_t j = 0; j < k; ++j) {
        if (!(std::isfinite(px[j]) && std::isfinite(py[j]))) return;  // no usable neighbourhood
        radius2 = std::max(radius2, px[j] * px[j] + py[j] * py[j]);
    }
    const double radius = std::sqrt(radius2);
    if (!(std::isfinite(radius) && radius > 0)) return;
    // neighbours that (nearly) coincide with the point pushed out along their direction (or a fixed one)
    for (int64_t j = 0; j < k; ++j) {
        const double dist = std::sqrt(px[j] * px[j] + py[j] * py[j]);
        if (!(dist < radius * DEGENERATE)) continue;
        double dx = px[j] * (1 / dist), dy = py[j] * (1 / dist);
        if (!(std::isfinite(dx) && std::isfinite(dy))) {
            const double theta = (2.0 * PI * static_cast<double>(j)) / static_cast<double>(k);
            dx = std::cos(theta);
            dy = std::sin(theta);
        }
        const double length = (1.0 + static_cast<double>(j) / static_cast<double>(k)) * radius * DEGENERATE * 10;
        px[j] = length * dx;
        py[j] = length * dy;
    }
    for (int64_t j = 0; j < k; ++j) {
        const double inv = 1 / std::sqrt(px[j] * px[j] + py[j] * py[j]);
        angle[j] = std::atan2(py[j] * inv, px[j] * inv);
    }
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(), [&](int64_t a, int64_t b) { return angle[a] < angle[b]; });
    // only neighbourhoods with two directions closer than 1e-5 rad can meet the collinearity test
    double gap = angle[order[0]] + 2 * PI - angle[order[k - 1]];
    for (int64_t j = 1; j < k; ++j) gap = std::min(gap, angle[order[j]] - angle[order[j - 1]]);
    const bool near = !(gap > 1e-5);
    for (int64_t j = 0; j < k; ++j) {
        x[j] = px[order[j]];
        y[j] = py[order[j]];
        sq[j] = x[j] * x[j] + y[j] * y[j];
        len[j] = std::sqrt(sq[j]);
    }
    for (int64_t j = 0; j < k; ++j) {
        valid[j] = 1;
        prv[j] = (j + k - 1) % k;
        nxt[j] = (j + 1) % k;
    }
    bool changed = true;
    while (changed) {
        changed = false;
        for (int64_t m = 0; m < k; ++m) {
            if (!valid[m]) continue;
            const int64_t a = prv[m], b = nxt[m];
            const double cross_ca = x[m] * y[a] - y[m] * x[a], cross_cb = x[m] * y[b] - y[m] * x[b];
            const double cross_ab = x[a] * y[b] - x[b] * y[a];
            // Eigen's 4x4 determinant of rows (0, 0, 0, 1), prev, next, cur
            const double det = cross_cb * sq[a] - (cross_ab * sq[m] + cross_ca * sq[b]);
            bool drop = cross_ca < 0 && cross_cb > 0 && !(det > 0);  // both triangles there, not Delaunay
            if (near) {  // of collinear neighbours keep the closest
                drop = drop || (std::abs(cross_ca) < (len[a] * len[m]) * DEGENERATE && x[m] * x[a] + y[m] * y[a] > 0 &&
                                len[m] > len[a]);
                drop = drop || (std::abs(cross_cb) < (len[b] * len[m]) * DEGENERATE && x[m] * x[b] + y[m] * y[b] > 0 &&
                                len[m] > len[b]);
            }
            if (drop && a != m && a != b) {  // three distinct kept neighbours
                valid[m] = 0;
                nxt[a] = b;
                prv[b] = a;
                changed = true;
            }
        }
    }
    for (int64_t i = 0; i < k; ++i) {
        if (!valid[i]) continue;
        const int64_t j = nxt[i];
        if (j != i && x[i] * y[j] - y[i] * x[j] > 0) {  // not a gap of pi or more
            faces.push_back(point);
            faces.push_back(neighbors[order[i]]);
            faces.push_back(neighbors[order[j]]);
        }
    }
}

nb::tuple local_triangulations(const Points& points, const Rows& centers, const Index& neighbors) {
    const int64_t n = static_cast<int64_t>(points.shape(0)), rows = static_cast<int64_t>(neighbors.shape(0));
    const int64_t k = static_cast<int64_t>(neighbors.shape(1));
    if (points.shape(1) != 3 || centers.shape(0) != neighbors.shape(0) || k < 3)
        throw std::invalid_argument("local_triangulations: need points (N, 3) and a row of k >= 3 neighbours a center");
    for (size_t e = 0; e < centers.size(); ++e)
        if (centers.data()[e] < 0 || centers.data()[e] >= n) throw std::out_of_range("local_triangulations: center");
    for (size_t e = 0; e < neighbors.size(); ++e)
        if (neighbors.data()[e] < 0 || neighbors.data()[e] >= n) throw std::out_of_range("local_triangulations: neighbour");
    const double* p = points.data();
    auto* normals = new double[static_cast<size_t>(3 * rows)];
    auto* faces = new std::vector<int64_t>();
    {
        nb::gil_scoped_release released;
        Scratch s(k);
        std::vector<double>& offsets = s.offsets;
        for (int64_t r = 0; r < rows; ++r) {
            const int64_t i = centers.data()[r];
            const int64_t* nb_row = neighbors.data() + r * k;
            for (int64_t j = 0; j < k; ++j)
                for (int c = 0; c < 3; ++c) offsets[3 * j + c] = p[3 * nb_row[j] + c] - p[3 * i + c];
            const V3 normal = svd_normal(k, s);
            for (int c = 0; c < 3; ++c) normals[3 * r + c] = normal[c];
            // the tangent frame of the normal (Vector3::buildTangentBasis) and the offsets in it
            const V3 u = unit(normal);
            const V3 test = std::abs(u[0]) > 0.9 ? V3{0.0, 1.0, 0.0} : V3{1.0, 0.0, 0.0};
            const V3 bx = unit(cross(test, u)), by = unit(cross(u, bx));
            for (int64_t j = 0; j < k; ++j) {
                const V3 o = {offsets[3 * j], offsets[3 * j + 1], offsets[3 * j + 2]};
                const double along = dot(normal, o);
                const V3 flat = {o[0] - normal[0] * along, o[1] - normal[1] * along, o[2] - normal[2] * along};
                s.px[j] = dot(bx, flat);
                s.py[j] = dot(by, flat);
            }
            local_triangles(i, nb_row, k, s, *faces);
        }
    }
    nb::capsule normals_owner(normals, [](void* q) noexcept { delete[] static_cast<double*>(q); });
    nb::capsule faces_owner(faces, [](void* q) noexcept { delete static_cast<std::vector<int64_t>*>(q); });
    return nb::make_tuple(
        nb::ndarray<nb::numpy, double>(normals, {static_cast<size_t>(rows), 3}, normals_owner),
        nb::ndarray<nb::numpy, int64_t>(faces->data(), {faces->size() / 3, 3}, faces_owner));
}

}  // namespace

NB_MODULE(_local_triangulation, m) {
    m.doc() = "potpourri3d's point-cloud normals and local Delaunay triangles (see src/local_triangulation.cpp).";
    m.def("local_triangulations", &local_triangulations, nb::arg("points"), nb::arg("centers"), nb::arg("neighbors"),
          "(R, 3) normals of points[centers] from their neighbours (R, k), and (F, 3) their local triangles "
          "(center, a, b), center by center.");
}
