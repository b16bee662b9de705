// Each point's normal and local Delaunay triangles as potpourri3d's point-cloud heat method makes them
// (geometry-central's buildLocalTriangulations; gegnn/cloud_heat.py describes every step), one point at a
// time without the interpreter (Python threads run blocks of rows side by side, gegnn/threads.py):
//
//   normal     the third left singular vector of the 3 x k matrix of neighbour offsets, by Eigen's
//              JacobiSVD (the library's own algorithm, here Eigen 3.4 where potpourri3d 1.4 has 3.3.9:
//              the same normals to rounding, signs included on the clouds tested);
//   tangent    coordinates of the offsets in the frame x = unit(t x n), y = unit(n x x), t = e_x (e_y where
//              |n_x| > 0.9);
//   triangles  the neighbours sorted by angle (std::sort, as the library), sweeps dropping a neighbour where
//              the two triangles it closes with its angular neighbours fail the in-circle test (or, of two
//              collinear ones, the farther), then (point, a, b) for consecutive kept neighbours, a x b > 0.
//
// In IEEE double without contraction (-ffp-contract=off); tests compare the normals and triangles with
// potpourri3d's.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <Eigen/SVD>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <stdexcept>
#include <utility>
#include <vector>

namespace nb = nanobind;

namespace {

using Points = nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using Rows = nb::ndarray<const int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Index = nb::ndarray<const int64_t, nb::ndim<2>, nb::c_contig, nb::device::cpu>;

constexpr double DEGENERATE = 1e-7;  // relative to the neighbourhood radius
constexpr double PI = 3.141592653589793;

using Offsets = Eigen::Matrix<double, 3, Eigen::Dynamic>;

// One point's working arrays, made once a call and reused point after point: the k offsets (3 x k) and
// the SVD's workspace, the tangent coordinates (pushed out where degenerate), their angles and angular
// order, the sorted coordinates and the ring of kept neighbours.
struct Scratch {
    explicit Scratch(int64_t k)
        : offsets(3, k), svd(3, k, Eigen::ComputeThinU), px(static_cast<size_t>(k)), py(px), angle(px), x(px), y(px),
          len(px), sq(px), order(static_cast<size_t>(k)), prv(order), nxt(order), valid(static_cast<size_t>(k)) {}
    Offsets offsets;
    Eigen::JacobiSVD<Offsets> svd;
    std::vector<double> px, py, angle, x, y, len, sq;
    std::vector<int64_t> order, prv, nxt;
    std::vector<char> valid;
};

using V3 = std::array<double, 3>;

// The unit normal of one point from its offsets (s.offsets): the last left singular vector of the 3 x k
// matrix, by Eigen's JacobiSVD (in the scratch's workspace), sign as it leaves it.
V3 svd_normal(Scratch& s) {
    const Eigen::Vector3d n = s.svd.compute(s.offsets, Eigen::ComputeThinU).matrixU().col(2).normalized();
    return {n[0], n[1], n[2]};
}

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
        if (neighbors.data()[e] < 0 || neighbors.data()[e] >= n)
            throw std::out_of_range("local_triangulations: neighbour");
    const double* p = points.data();
    auto* normals = new double[static_cast<size_t>(3 * rows)];
    auto* faces = new std::vector<int64_t>();
    {
        nb::gil_scoped_release released;
        Scratch s(k);
        Offsets& offsets = s.offsets;
        for (int64_t r = 0; r < rows; ++r) {
            const int64_t i = centers.data()[r];
            const int64_t* nb_row = neighbors.data() + r * k;
            for (int64_t j = 0; j < k; ++j)
                for (int c = 0; c < 3; ++c) offsets(c, j) = p[3 * nb_row[j] + c] - p[3 * i + c];
            const V3 normal = svd_normal(s);
            for (int c = 0; c < 3; ++c) normals[3 * r + c] = normal[c];
            // the tangent frame of the normal (Vector3::buildTangentBasis) and the offsets in it
            const V3 u = unit(normal);
            const V3 test = std::abs(u[0]) > 0.9 ? V3{0.0, 1.0, 0.0} : V3{1.0, 0.0, 0.0};
            const V3 bx = unit(cross(test, u)), by = unit(cross(u, bx));
            for (int64_t j = 0; j < k; ++j) {
                const V3 o = {offsets(0, j), offsets(1, j), offsets(2, j)};
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
