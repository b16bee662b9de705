// The heat method's solves (gegnn/heat.py, HeatSolver), for many sources at once and without the
// interpreter, split over threads: for each source s,
//
//     (M + tL) u = e_s,    g = G u,    X_f = g_f / |g_f|  (0 where g_f = 0),    b = D X,
//     (L + shift I) phi = b,    d = phi - phi_s,
//
// G the per-face gradient (2F x N CSR: the x components of all faces, then the y components) and D the
// divergence (N x 2F CSR). Both systems are factored once by Eigen's SimplicialLLT (AMD ordering: the
// factorization libigl's min_quad_with_fixed made here before); each block of BLOCK sources is solved
// against the factor together (the factor read once a block, the sources' values of a vertex side by
// side), in the order of Eigen's own triangular solves, so every column is the one Eigen gives for it
// alone. The middle step takes every sum in SciPy's order (csr_matvec / csr_matvecs: from 0, over a row's
// entries as stored) and the normalization as NumPy's ((x x + y y), sqrt, 1 / norm, two products), with
// no fused multiply-add (-ffp-contract=off): it equals SciPy's products bit for bit. The result does not
// depend on the thread count.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <Eigen/OrderingMethods>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <utility>
#include <vector>

#include "threads.h"

namespace nb = nanobind;

namespace {

using Index = nb::ndarray<const int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Values = nb::ndarray<const double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Heat = nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using Out = nb::ndarray<nb::numpy, double, nb::ndim<2>>;

constexpr int BLOCK = 16;  // sources solved together: the factor is read once for them

// A sparse matrix in compressed rows (or columns), copied and checked once.
struct Csr {
    std::vector<int64_t> indptr, indices;
    std::vector<double> data;
    int64_t rows = 0, cols = 0;

    Csr(const Index& p, const Index& j, const Values& v, int64_t n_cols)
        : indptr(p.data(), p.data() + p.shape(0)), indices(j.data(), j.data() + j.shape(0)),
          data(v.data(), v.data() + v.shape(0)), rows(static_cast<int64_t>(p.shape(0)) - 1), cols(n_cols) {
        if (rows < 0 || indices.size() != data.size() || indptr[0] != 0 ||
            indptr.back() != static_cast<int64_t>(indices.size()))
            throw std::invalid_argument("heat_ops: inconsistent sparse arrays");
        for (int64_t i = 0; i < rows; ++i)
            if (indptr[i] > indptr[i + 1]) throw std::invalid_argument("heat_ops: decreasing row pointers");
        for (int64_t j : indices)
            if (j < 0 || j >= cols) throw std::out_of_range("heat_ops: column index out of range");
    }

    // y (rows x K) = A x (cols x K), in csr_matvec's / csr_matvecs' order: each sum from 0 over the row's
    // entries as stored.
    template <int K>
    void product(const double* __restrict x, double* __restrict y) const {
        const int64_t* p = indptr.data();
        const int64_t* j = indices.data();
        const double* v = data.data();
        for (int64_t i = 0; i < rows; ++i) {
            double sum[K] = {};
            for (int64_t e = p[i]; e < p[i + 1]; ++e) {
                const double* xj = x + j[e] * K;
                for (int c = 0; c < K; ++c) sum[c] += v[e] * xj[c];
            }
            for (int c = 0; c < K; ++c) y[i * K + c] = sum[c];
        }
    }
};

// P A P^T = L L^T of a symmetric positive definite matrix (its lower triangle read), Eigen's SimplicialLLT
// with AMD ordering; solves k right-hand sides stored side by side (row i: the k values of unknown i).
class Cholesky {
public:
    explicit Cholesky(const Csr& a) {
        const int n = static_cast<int>(a.rows);
        Eigen::SparseMatrix<double> m(n, n);  // a symmetric matrix: its CSR arrays are its CSC arrays
        m.resizeNonZeros(static_cast<Eigen::Index>(a.data.size()));
        std::copy(a.indptr.begin(), a.indptr.end(), m.outerIndexPtr());  // int64 to Eigen's int
        std::copy(a.indices.begin(), a.indices.end(), m.innerIndexPtr());
        std::copy(a.data.begin(), a.data.end(), m.valuePtr());
        Eigen::SimplicialLLT<Eigen::SparseMatrix<double>, Eigen::Lower, Eigen::AMDOrdering<int>> llt(m);
        if (llt.info() != Eigen::Success) throw std::runtime_error("not positive definite");
        const Eigen::SparseMatrix<double>& l = llt.matrixL().nestedExpression();
        n_ = n;
        colptr_.assign(l.outerIndexPtr(), l.outerIndexPtr() + n + 1);
        row_.assign(l.innerIndexPtr(), l.innerIndexPtr() + l.nonZeros());
        value_.assign(l.valuePtr(), l.valuePtr() + l.nonZeros());
        for (int j = 0; j < n; ++j)  // the diagonal entry of every column (Eigen stores it first)
            if (colptr_[j] == colptr_[j + 1] || row_[colptr_[j]] != j)
                throw std::runtime_error("factor without its diagonal");
        perm_.assign(llt.permutationP().indices().data(), llt.permutationP().indices().data() + n);
    }

    // x = A^-1 b for K columns side by side: x = P^T L^-T L^-1 P b, as Eigen's solve takes each column.
    // work: N x K scratch.
    template <int K>
    void solve(const double* __restrict b, double* __restrict x, double* __restrict work) const {
        const int* perm = perm_.data();
        const int* cp = colptr_.data();
        const int* row = row_.data();
        const double* val = value_.data();
        for (int i = 0; i < n_; ++i)
            for (int c = 0; c < K; ++c) work[int64_t(perm[i]) * K + c] = b[int64_t(i) * K + c];
        for (int j = 0; j < n_; ++j) {  // L y = P b: column by column
            double yj[K];
            const double d = val[cp[j]];
            for (int c = 0; c < K; ++c) yj[c] = work[int64_t(j) * K + c] /= d;
            for (int e = cp[j] + 1; e < cp[j + 1]; ++e) {
                double* yi = work + int64_t(row[e]) * K;
                const double v = val[e];
                for (int c = 0; c < K; ++c) yi[c] -= v * yj[c];
            }
        }
        for (int j = n_ - 1; j >= 0; --j) {  // L^T z = y: row j of L^T is column j of L
            double zj[K];
            for (int c = 0; c < K; ++c) zj[c] = work[int64_t(j) * K + c];
            for (int e = cp[j] + 1; e < cp[j + 1]; ++e) {
                const double* zi = work + int64_t(row[e]) * K;
                const double v = val[e];
                for (int c = 0; c < K; ++c) zj[c] -= v * zi[c];
            }
            const double d = val[cp[j]];
            for (int c = 0; c < K; ++c) work[int64_t(j) * K + c] = zj[c] / d;
        }
        for (int i = 0; i < n_; ++i)
            for (int c = 0; c < K; ++c) x[int64_t(i) * K + c] = work[int64_t(perm[i]) * K + c];
    }

private:
    int n_ = 0;
    std::vector<int> colptr_, row_, perm_;
    std::vector<double> value_;
};

// One heat solver's operators: (M + tL) and (L + shift I) (symmetric CSR), G (2F x N) and D (N x 2F).
class HeatFields {
public:
    HeatFields(const Index& h_indptr, const Index& h_indices, const Values& h_data, const Index& p_indptr,
               const Index& p_indices, const Values& p_data, const Index& g_indptr, const Index& g_indices,
               const Values& g_data, const Index& d_indptr, const Index& d_indices, const Values& d_data, int64_t n)
        : grad_(g_indptr, g_indices, g_data, n), div_(d_indptr, d_indices, d_data, grad_.rows), n_(n) {
        if (grad_.rows % 2 != 0) throw std::invalid_argument("heat_ops: the gradient needs 2F rows");
        if (div_.rows != n) throw std::invalid_argument("heat_ops: the divergence needs N rows");
        const Csr heat(h_indptr, h_indices, h_data, n), poisson(p_indptr, p_indices, p_data, n);
        if (heat.rows != n || poisson.rows != n) throw std::invalid_argument("heat_ops: the systems need N rows");
        nb::gil_scoped_release released;
        heat_ = std::make_unique<Cholesky>(heat);
        poisson_ = std::make_unique<Cholesky>(poisson);
    }

    // D unit(G u) for u (N x k).
    Out divergence(const Heat& u) const {
        if (static_cast<int64_t>(u.shape(0)) != n_) throw std::invalid_argument("heat_ops: u needs one row a vertex");
        const int64_t k = static_cast<int64_t>(u.shape(1));
        double* out = allocate(n_ * k);
        {
            nb::gil_scoped_release released;
            std::vector<double> column(static_cast<size_t>(n_)), g(static_cast<size_t>(grad_.rows)), b(column.size());
            for (int64_t c = 0; c < k; ++c) {  // column by column: the same sums as for K side by side
                for (int64_t i = 0; i < n_; ++i) column[i] = u.data()[i * k + c];
                normalized_divergence<1>(column.data(), g.data(), b.data());
                for (int64_t i = 0; i < n_; ++i) out[i * k + c] = b[i];
            }
        }
        return wrap(out, n_, k);
    }

    // (N x S): column j the distance field of sources[j] alone, phi - phi[source]; the sources in blocks
    // of BLOCK (the last one's remainder in blocks of 8, 4, 2, 1) spread over `threads` threads.
    Out distances(const Index& sources, int64_t threads) const {
        const int64_t s = static_cast<int64_t>(sources.shape(0));
        const int64_t* src = sources.data();
        for (int64_t j = 0; j < s; ++j)
            if (src[j] < 0 || src[j] >= n_) throw std::out_of_range("heat_ops: source out of range");
        double* out = allocate(n_ * s);
        {
            nb::gil_scoped_release released;
            std::vector<std::pair<int64_t, int>> blocks;  // (first source, width)
            int64_t first = 0;
            for (int width = BLOCK; width >= 1; width /= 2)
                for (; s - first >= width; first += width) blocks.emplace_back(first, width);
            std::atomic<size_t> next{0};
            auto work = [&]() {
                const size_t width = static_cast<size_t>(std::min<int64_t>(BLOCK, s));
                std::vector<double> a(n_ * width), b(a.size()), scratch(a.size()), g(grad_.rows * width);
                Buffers buf{a.data(), b.data(), scratch.data(), g.data()};
                for (size_t i; (i = next++) < blocks.size();) {
                    const auto [begin, k] = blocks[i];
                    switch (k) {
                        case 16: fields<16>(src + begin, buf, out + begin, s); break;
                        case 8: fields<8>(src + begin, buf, out + begin, s); break;
                        case 4: fields<4>(src + begin, buf, out + begin, s); break;
                        case 2: fields<2>(src + begin, buf, out + begin, s); break;
                        default: fields<1>(src + begin, buf, out + begin, s); break;
                    }
                }
            };
            const int64_t team = std::max<int64_t>(1, std::min<int64_t>(threads, static_cast<int64_t>(blocks.size())));
            run_parts(team, [&](int64_t) { work(); });  // each takes blocks until none is left
        }
        return wrap(out, n_, s);
    }

private:
    struct Buffers {
        double *a, *b, *scratch, *g;
    };

    // The fields of the K sources src, written to columns 0..K-1 of out (row stride `stride`).
    template <int K>
    void fields(const int64_t* src, const Buffers& buf, double* out, int64_t stride) const {
        std::fill(buf.a, buf.a + n_ * K, 0.0);
        for (int c = 0; c < K; ++c) buf.a[src[c] * K + c] = 1.0;
        heat_->solve<K>(buf.a, buf.b, buf.scratch);        // u
        normalized_divergence<K>(buf.b, buf.g, buf.a);      // D X
        poisson_->solve<K>(buf.a, buf.b, buf.scratch);     // phi
        for (int64_t i = 0; i < n_; ++i)
            for (int c = 0; c < K; ++c) out[i * stride + c] = buf.b[i * K + c] - buf.b[src[c] * K + c];
    }

    template <int K>
    void normalized_divergence(const double* u, double* g, double* out) const {
        const int64_t faces = grad_.rows / 2;
        grad_.product<K>(u, g);
        for (int64_t i = 0; i < faces * K; ++i) {  // (x, y) of one face and column: rows f and F + f
            double& x = g[i];
            double& y = g[faces * K + i];
            double norm = x * x;
            norm += y * y;
            norm = std::sqrt(norm);
            if (norm <= 0) norm = 1.0;               // a zero gradient stays zero
            norm = 1.0 / norm;
            x *= norm;
            y *= norm;
        }
        div_.product<K>(g, out);
    }

    static double* allocate(int64_t size) { return new double[static_cast<size_t>(std::max<int64_t>(size, 1))]; }

    static Out wrap(double* data, int64_t rows, int64_t cols) {
        nb::capsule owner(data, [](void* p) noexcept { delete[] static_cast<double*>(p); });
        return Out(data, {static_cast<size_t>(rows), static_cast<size_t>(cols)}, owner);
    }

    Csr grad_, div_;
    int64_t n_;
    std::unique_ptr<Cholesky> heat_, poisson_;
};

}  // namespace

NB_MODULE(_heat_ops, m) {
    nb::class_<HeatFields>(m, "HeatFields")
        .def(nb::init<const Index&, const Index&, const Values&, const Index&, const Index&, const Values&,
                      const Index&, const Index&, const Values&, const Index&, const Index&, const Values&, int64_t>())
        .def("divergence", &HeatFields::divergence, nb::arg("u"))
        .def("distances", &HeatFields::distances, nb::arg("sources"), nb::arg("threads"));
}
