// Row-wise fits of a point cloud's neighbourhoods (gegnn/pointcloud.py), one point at a time and without
// the interpreter (Python threads run blocks of rows side by side, gegnn/threads.py):
//
//   plane_normals   the least-variance direction of a point with its neighbours (PCA about their mean);
//   mls_project     the point moved onto the quadric z = c0 + c1 u + c2 v + c3 u^2 + c4 uv + c5 v^2 fitted
//                   by weighted least squares (weights exp(-(2 d / d_k)^2)) in the frame of the weighted
//                   covariance, p' = p + c0 n, kept where |c0| > d_k / 2;
//   cone_neighbors  the k nearest candidates q within a cone about the tangent plane,
//                   |n . (q - p)| < sin(cone) |q - p| (and n_q . n_p > 0 with given normals), n fitted twice
//                   where not given: to the point and its `fit` nearest, then to the point and its `fit`
//                   nearest within that first cone; a row is settled where it had k candidates within
//                   the cone (and `fit` within the first), so that more candidates would not change it.
//
// Eigen's SelfAdjointEigenSolver (eigenvalues ascending) and LDLT stand for LAPACK's eigh and solve: the same
// fits to rounding.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <vector>

namespace nb = nanobind;

namespace {

using Points = nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using Index = nb::ndarray<const int64_t, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using Rows = nb::ndarray<const int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Table = nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
template <typename T>
using Out = nb::ndarray<nb::numpy, T>;

template <typename T>
Out<T> owned(T* data, std::initializer_list<size_t> shape) {
    nb::capsule owner(data, [](void* p) noexcept { delete[] static_cast<T*>(p); });
    return Out<T>(data, shape, owner);
}

// The points, the rows (the points fitted) and their neighbours' indices, checked against the point count.
void check(const Points& points, const Rows& rows, const Index& nbrs) {
    const int64_t n = static_cast<int64_t>(points.shape(0));
    if (points.shape(1) != 3) throw std::invalid_argument("cloud_ops: need points (N, 3)");
    if (rows.shape(0) != nbrs.shape(0)) throw std::invalid_argument("cloud_ops: need a row of neighbours per point");
    const int64_t* i = rows.data();
    for (size_t e = 0; e < rows.size(); ++e)
        if (i[e] < 0 || i[e] >= n) throw std::out_of_range("cloud_ops: point index out of range");
    const int64_t* j = nbrs.data();
    for (size_t e = 0; e < nbrs.size(); ++e)
        if (j[e] < 0 || j[e] >= n) throw std::out_of_range("cloud_ops: neighbour index out of range");
}

Eigen::Vector3d point(const double* x, int64_t i) { return {x[3 * i], x[3 * i + 1], x[3 * i + 2]}; }

// Unit least-variance direction of the point `center` with the points `near[0..m)`.
Eigen::Vector3d plane_normal(const double* x, int64_t center, const int64_t* near, int64_t m) {
    Eigen::Vector3d mean = point(x, center);
    for (int64_t j = 0; j < m; ++j) mean += point(x, near[j]);
    mean /= static_cast<double>(m + 1);
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    const Eigen::Vector3d c = point(x, center) - mean;
    cov.selfadjointView<Eigen::Lower>().rankUpdate(c);
    for (int64_t j = 0; j < m; ++j) cov.selfadjointView<Eigen::Lower>().rankUpdate(point(x, near[j]) - mean);
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov, Eigen::ComputeEigenvectors);
    return eig.eigenvectors().col(0);
}

Out<double> plane_normals(const Points& points, const Rows& centers, const Index& nbrs) {
    check(points, centers, nbrs);
    const int64_t rows = static_cast<int64_t>(nbrs.shape(0)), m = static_cast<int64_t>(nbrs.shape(1));
    auto* out = new double[static_cast<size_t>(3 * rows)];
    {
        nb::gil_scoped_release released;
        for (int64_t r = 0; r < rows; ++r) {
            const Eigen::Vector3d n = plane_normal(points.data(), centers.data()[r], nbrs.data() + r * m, m);
            for (int d = 0; d < 3; ++d) out[3 * r + d] = n[d];
        }
    }
    return owned(out, {static_cast<size_t>(rows), 3});
}

Out<double> mls_project(const Points& points, const Rows& centers, const Index& nbrs, const Table& dist) {
    check(points, centers, nbrs);
    const int64_t rows = static_cast<int64_t>(nbrs.shape(0)), m = static_cast<int64_t>(nbrs.shape(1));
    if (dist.shape(0) != nbrs.shape(0) || dist.shape(1) != nbrs.shape(1))
        throw std::invalid_argument("mls_project: dist must have the neighbours' shape");
    const double* x = points.data();
    auto* out = new double[static_cast<size_t>(3 * rows)];
    {
        nb::gil_scoped_release released;
        std::vector<double> w(static_cast<size_t>(m));
        for (int64_t r = 0; r < rows; ++r) {
            const int64_t* near = nbrs.data() + r * m;
            const double* d = dist.data() + r * m;
            const double radius = std::max(d[m - 1], 1e-300);
            double total = 0.0;
            Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
            for (int64_t j = 0; j < m; ++j) {
                const double s = 2.0 * d[j] / radius;
                w[j] = std::exp(-s * s);
                total += w[j];
                centroid += w[j] * point(x, near[j]);
            }
            centroid /= total;
            Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
            for (int64_t j = 0; j < m; ++j)
                cov.selfadjointView<Eigen::Lower>().rankUpdate(point(x, near[j]) - centroid, w[j]);
            Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov, Eigen::ComputeEigenvectors);
            const Eigen::Matrix3d& frame = eig.eigenvectors();  // columns: normal, then the tangents
            const Eigen::Vector3d p = point(x, centers.data()[r]);
            Eigen::Matrix<double, 6, 6> normal_eq = 1e-10 * Eigen::Matrix<double, 6, 6>::Identity();
            Eigen::Matrix<double, 6, 1> rhs = Eigen::Matrix<double, 6, 1>::Zero();
            for (int64_t j = 0; j < m; ++j) {
                const Eigen::Vector3d local = frame.transpose() * (point(x, near[j]) - p);
                const double sw = std::sqrt(w[j]), u = local[2] / radius, v = local[1] / radius;
                Eigen::Matrix<double, 6, 1> a;  // columns of comparable size: the normal equations stay well
                a << 1.0, u, v, u * u, u * v, v * v;  // conditioned
                a *= sw;
                normal_eq.selfadjointView<Eigen::Lower>().rankUpdate(a);
                rhs += a * (local[0] * sw);
            }
            const double c0 = normal_eq.selfadjointView<Eigen::Lower>().ldlt().solve(rhs)[0];
            const Eigen::Vector3d moved = std::abs(c0) <= 0.5 * radius ? Eigen::Vector3d(p + c0 * frame.col(0)) : p;
            for (int k = 0; k < 3; ++k) out[3 * r + k] = moved[k];
        }
    }
    return owned(out, {static_cast<size_t>(rows), 3});
}

nb::tuple cone_neighbors(const Points& points, const Rows& centers, const Index& nbrs, int64_t k, double sin_cone,
                         int64_t fit, const Points& normals) {
    check(points, centers, nbrs);
    const int64_t rows = static_cast<int64_t>(nbrs.shape(0)), m = static_cast<int64_t>(nbrs.shape(1));
    const bool given = normals.shape(0) > 0;
    if (given && (normals.shape(0) != points.shape(0) || normals.shape(1) != 3))
        throw std::invalid_argument("cone_neighbors: normals must have the points' shape");
    if (k < 1 || k > m || fit < 1 || fit > m)
        throw std::invalid_argument("cone_neighbors: need 1 <= k, fit <= candidates");
    const double* x = points.data();
    auto* out = new int64_t[static_cast<size_t>(rows * k)];
    auto* settled = new bool[static_cast<size_t>(rows)];
    {
        nb::gil_scoped_release released;
        std::vector<int64_t> order(static_cast<size_t>(m));
        std::vector<char> inside(static_cast<size_t>(m));
        std::vector<int64_t> first(static_cast<size_t>(fit));  // the second fit's points
        for (int64_t r = 0; r < rows; ++r) {
            const int64_t i = centers.data()[r];
            const int64_t* near = nbrs.data() + r * m;
            const Eigen::Vector3d p = point(x, i);
            // The candidates within the cone of normal n first, each group nearest first; how many within.
            auto cone = [&](const Eigen::Vector3d& n) {
                int64_t in = 0;
                for (int64_t j = 0; j < m; ++j) {
                    const Eigen::Vector3d o = point(x, near[j]) - p;
                    bool ok = std::abs(o.dot(n)) < sin_cone * o.norm();
                    if (given) ok = ok && point(normals.data(), near[j]).dot(point(normals.data(), i)) > 0;
                    inside[j] = ok;
                    in += ok;
                }
                int64_t a = 0, b = in;
                for (int64_t j = 0; j < m; ++j) order[inside[j] ? a++ : b++] = near[j];
                return in;
            };
            bool done;
            if (given) {
                done = cone(point(normals.data(), i)) >= k;
            } else {
                const bool fitted = cone(plane_normal(x, i, near, fit)) >= fit;
                std::copy(order.begin(), order.begin() + fit, first.begin());
                const bool enough = cone(plane_normal(x, i, first.data(), fit)) >= k;
                done = fitted && enough;
            }
            std::copy(order.begin(), order.begin() + k, out + r * k);
            settled[r] = done;
        }
    }
    return nb::make_tuple(owned(out, {static_cast<size_t>(rows), static_cast<size_t>(k)}),
                          owned(settled, {static_cast<size_t>(rows)}));
}

}  // namespace

NB_MODULE(_cloud_ops, m) {
    m.doc() = "Row-wise fits of point-cloud neighbourhoods (see src/cloud_ops.cpp).";
    m.def("plane_normals", &plane_normals, nb::arg("points"), nb::arg("centers"), nb::arg("nbrs"),
          "(R, 3) unit least-variance directions of points[centers[r]] with points[nbrs[r]].");
    m.def("mls_project", &mls_project, nb::arg("points"), nb::arg("centers"), nb::arg("nbrs"), nb::arg("dist"),
          "(R, 3): points[centers[r]] moved onto the quadric fitted to points[nbrs[r]] (itself first) at dist[r].");
    m.def("cone_neighbors", &cone_neighbors, nb::arg("points"), nb::arg("centers"), nb::arg("nbrs"), nb::arg("k"),
          nb::arg("sin_cone"), nb::arg("fit"), nb::arg("normals"),
          "(R, k) neighbours of points[centers[r]] within the cone among the candidates nbrs[r] (nearest first), "
          "and (R,) whether each is settled; normals: the points' own (N, 3), or (0, 3) to fit them.");
}
