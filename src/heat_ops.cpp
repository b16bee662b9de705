// The heat method's middle step (gegnn/heat.py, HeatSolver): from the heat u (N values, or N x k for k
// sources) to the Poisson equation's right-hand side,
//
//     g = G u,    X_f = g_f / |g_f|  (0 where g_f = 0),    b = D X,
//
// G the per-face gradient (2F x N CSR: the x components of all faces, then the y components) and D the
// divergence (N x 2F CSR). SciPy does it in three passes (two sparse products, NumPy's normalization)
// holding the interpreter between them; here in two loops without it, so that the network's thread runs
// meanwhile. Every sum is taken in SciPy's order (csr_matvec / csr_matvecs: from 0, over a row's entries
// as stored) and the normalization is NumPy's ((x x + y y), sqrt, 1 / norm, two products), with no fused
// multiply-add (-ffp-contract=off): the result equals SciPy's bit for bit.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <vector>

namespace nb = nanobind;

namespace {

using Index = nb::ndarray<const int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Values = nb::ndarray<const double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Heat = nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;

// A CSR matrix of `cols` columns, copied and checked once.
struct Csr {
    std::vector<int64_t> indptr, indices;
    std::vector<double> data;
    int64_t rows = 0, cols = 0;

    Csr(const Index& p, const Index& j, const Values& v, int64_t n_cols)
        : indptr(p.data(), p.data() + p.shape(0)), indices(j.data(), j.data() + j.shape(0)),
          data(v.data(), v.data() + v.shape(0)), rows(static_cast<int64_t>(p.shape(0)) - 1), cols(n_cols) {
        if (rows < 0 || indices.size() != data.size() || indptr[0] != 0 ||
            indptr.back() != static_cast<int64_t>(indices.size()))
            throw std::invalid_argument("heat_ops: inconsistent CSR arrays");
        for (int64_t i = 0; i < rows; ++i)
            if (indptr[i] > indptr[i + 1]) throw std::invalid_argument("heat_ops: decreasing CSR row pointers");
        for (int64_t j : indices)
            if (j < 0 || j >= cols) throw std::out_of_range("heat_ops: CSR column index out of range");
    }

    // y (rows x k) = A x (cols x k), in csr_matvec's / csr_matvecs' order: each sum from 0 over the row's
    // entries as stored.
    void product(const double* __restrict x, int64_t k, double* __restrict y) const {
        const int64_t* p = indptr.data();
        const int64_t* j = indices.data();
        const double* v = data.data();
        if (k == 1) {
            for (int64_t i = 0; i < rows; ++i) {
                double sum = 0.0;
                for (int64_t e = p[i]; e < p[i + 1]; ++e) sum += v[e] * x[j[e]];
                y[i] = sum;
            }
            return;
        }
        for (int64_t i = 0; i < rows; ++i) {
            double* yi = y + i * k;
            for (int64_t c = 0; c < k; ++c) yi[c] = 0.0;
            for (int64_t e = p[i]; e < p[i + 1]; ++e) {
                const double* xj = x + j[e] * k;
                for (int64_t c = 0; c < k; ++c) yi[c] += v[e] * xj[c];
            }
        }
    }
};

// G (2F x N) and D (N x 2F) of one heat solver; called with u (N x k), gives D unit(G u) (N x k).
class GradientDivergence {
public:
    GradientDivergence(const Index& g_indptr, const Index& g_indices, const Values& g_data, const Index& d_indptr,
                       const Index& d_indices, const Values& d_data, int64_t n)
        : grad_(g_indptr, g_indices, g_data, n), div_(d_indptr, d_indices, d_data, grad_.rows) {
        if (grad_.rows % 2 != 0) throw std::invalid_argument("heat_ops: the gradient needs 2F rows");
        if (div_.rows != n) throw std::invalid_argument("heat_ops: the divergence needs N rows");
    }

    nb::ndarray<nb::numpy, double, nb::ndim<2>> operator()(const Heat& u) const {
        if (static_cast<int64_t>(u.shape(0)) != grad_.cols)
            throw std::invalid_argument("heat_ops: u needs one row a vertex");
        const int64_t k = static_cast<int64_t>(u.shape(1)), faces = grad_.rows / 2;
        auto* out = new double[static_cast<size_t>(div_.rows * k)];
        nb::capsule owner(out, [](void* p) noexcept { delete[] static_cast<double*>(p); });
        {
            nb::gil_scoped_release released;
            std::vector<double> g(static_cast<size_t>(grad_.rows * k));
            grad_.product(u.data(), k, g.data());
            for (int64_t i = 0; i < faces * k; ++i) {  // (x, y) of one face and column: rows f and F + f
                double& x = g[i];
                double& y = g[faces * k + i];
                double norm = x * x;
                norm += y * y;
                norm = std::sqrt(norm);
                if (norm <= 0) norm = 1.0;               // a zero gradient stays zero
                norm = 1.0 / norm;
                x *= norm;
                y *= norm;
            }
            div_.product(g.data(), k, out);
        }
        return nb::ndarray<nb::numpy, double, nb::ndim<2>>(
            out, {static_cast<size_t>(div_.rows), static_cast<size_t>(k)}, owner);
    }

private:
    Csr grad_, div_;
};

}  // namespace

NB_MODULE(_heat_ops, m) {
    nb::class_<GradientDivergence>(m, "GradientDivergence")
        .def(nb::init<const Index&, const Index&, const Values&, const Index&, const Index&, const Values&, int64_t>(),
             nb::arg("g_indptr"), nb::arg("g_indices"), nb::arg("g_data"), nb::arg("d_indptr"),
             nb::arg("d_indices"), nb::arg("d_data"), nb::arg("n"))
        .def("__call__", &GradientDivergence::operator(), nb::arg("u"));
}
