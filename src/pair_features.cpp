// The input features of the landmark decoder (gegnn.decoders.LandmarkDecoder.inputs) for a batch of vertex
// pairs, straight from the per-vertex codes and the pair indices: one pass over each pair's two code rows,
// no (pairs x K) intermediate. The torch version gathers both rows (2 x (D + K + 4) floats a pair), then
// makes five passes over (pairs x K) temporaries (|f_a - f_b|, f_a + f_b and the max, min, sum and
// sum of squares of them); here each landmark column is read once, in cache, and reduced in registers.
//
// A code is [e (D) | f (K) | n (1) | p (3)]. For the pair (a, b), with s_k = |f_ak - f_bk| and
// U = max(min_k (f_ak + f_bk), 1e-6), the row written is
//     [(e_a - e_b)^2 (D, if embedding) | max s / U, mean s / U, rms s / U, (n_a + n_b) / U, |n_a - n_b| / U,
//      (|p_a - p_b| / U, if euclidean) | log U]
// and lower = max s, upper = min_k (f_ak + f_bk) (the decoder's output needs them).
//
// Sums are accumulated in float in 8 independent lanes (the torch reductions also split their sums), so
// the features equal the torch version's to within float rounding (a few ulp), not bit for bit.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "simd.h"

namespace nb = nanobind;

namespace {

struct Layout {
    int64_t width, d, k;
    bool embedding, euclidean;
    int64_t n_in() const { return (embedding ? d : 0) + 5 + (euclidean ? 1 : 0) + 1; }
};

GEGNN_CLONES
void pair_rows(const float* codes, const int64_t* ia, const int64_t* ib, int64_t begin, int64_t end, Layout L,
               float* x, float* lower, float* upper) {
    const int64_t n_in = L.n_in();
    constexpr int64_t AHEAD = 4;  // rows are gathered at random: fetch a few pairs ahead of use
    for (int64_t p = begin; p < end; ++p) {
        if (p + AHEAD < end) {
            const char* na = reinterpret_cast<const char*>(codes + ia[p + AHEAD] * L.width);
            const char* nb = reinterpret_cast<const char*>(codes + ib[p + AHEAD] * L.width);
            for (int64_t byte = 0; byte < L.width * 4; byte += 64) {
                __builtin_prefetch(na + byte);
                __builtin_prefetch(nb + byte);
            }
        }
        const float* a = codes + ia[p] * L.width;
        const float* b = codes + ib[p] * L.width;
        float* row = x + p * n_in;
        if (L.embedding) {
            for (int64_t c = 0; c < L.d; ++c) {
                const float t = a[c] - b[c];
                row[c] = t * t;
            }
            row += L.d;
        }
        const float* fa = a + L.d;
        const float* fb = b + L.d;
        V mx = {}, sum = {}, sq = {}, mn = mx + INFINITY;
        int64_t c = 0;
        for (; c + LANES <= L.k; c += LANES) {
            V va, vb;
            std::memcpy(&va, fa + c, sizeof(V));
            std::memcpy(&vb, fb + c, sizeof(V));
            const V t = va - vb, s = t < 0 ? -t : t, both = va + vb;
            mx = mx > s ? mx : s;
            mn = mn < both ? mn : both;
            sum += s;
            sq += s * s;
        }
        float m = mx[0], u = mn[0], total = sum[0], squares = sq[0];
        for (int l = 1; l < LANES; ++l) {
            m = std::max(m, mx[l]);
            u = std::min(u, mn[l]);
            total += sum[l];
            squares += sq[l];
        }
        for (; c < L.k; ++c) {
            const float s = std::fabs(fa[c] - fb[c]);
            m = std::max(m, s);
            u = std::min(u, fa[c] + fb[c]);
            total += s;
            squares += s * s;
        }
        lower[p] = m;
        upper[p] = u;
        const float uc = std::max(u, 1e-6f), inv = 1.0f / uc;
        const float na = fa[L.k], nb = fb[L.k];
        row[0] = m * inv;
        row[1] = total / static_cast<float>(L.k) * inv;
        row[2] = std::sqrt(squares) / std::sqrt(static_cast<float>(L.k)) * inv;
        row[3] = (na + nb) * inv;
        row[4] = std::fabs(na - nb) * inv;
        int64_t o = 5;
        if (L.euclidean) {
            const float* pa = fa + L.k + 1;
            const float* pb = fb + L.k + 1;
            const float dx = pa[0] - pb[0], dy = pa[1] - pb[1], dz = pa[2] - pb[2];
            row[o++] = std::sqrt(dx * dx + dy * dy + dz * dz) * inv;
        }
        row[o] = std::log(uc);
    }
}

using Codes = nb::ndarray<const float, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using Index = nb::ndarray<const int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Rows = nb::ndarray<float, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using Column = nb::ndarray<float, nb::ndim<1>, nb::c_contig, nb::device::cpu>;

void landmark_features(Codes codes, Index ia, Index ib, int64_t d, int64_t k, bool embedding, bool euclidean,
                       Rows x, Column lower, Column upper, int threads) {
    const Layout L{static_cast<int64_t>(codes.shape(1)), d, k, embedding, euclidean};
    const int64_t n = static_cast<int64_t>(ia.shape(0)), rows = static_cast<int64_t>(codes.shape(0));
    if (L.width != d + k + 4)
        throw std::invalid_argument("codes have " + std::to_string(L.width) + " columns, expected D + K + 4 = " +
                                    std::to_string(d + k + 4));
    if (static_cast<int64_t>(ib.shape(0)) != n || static_cast<int64_t>(x.shape(0)) != n ||
        static_cast<int64_t>(x.shape(1)) != L.n_in() || static_cast<int64_t>(lower.shape(0)) != n ||
        static_cast<int64_t>(upper.shape(0)) != n)
        throw std::invalid_argument("pair arrays disagree in length, or x is not (pairs, decoder inputs)");
    // Indices are trusted no further than the check: a bad one would read outside the codes.
    for (int64_t p = 0; p < n; ++p)
        if (ia.data()[p] < 0 || ia.data()[p] >= rows || ib.data()[p] < 0 || ib.data()[p] >= rows)
            throw std::out_of_range("vertex index out of range");
    nb::gil_scoped_release release;
    const int64_t parts = std::max<int64_t>(1, std::min<int64_t>(threads, n / 1024));
    std::vector<std::thread> pool;
    for (int64_t t = 1; t < parts; ++t)
        pool.emplace_back(pair_rows, codes.data(), ia.data(), ib.data(), n * t / parts, n * (t + 1) / parts, L,
                          x.data(), lower.data(), upper.data());
    pair_rows(codes.data(), ia.data(), ib.data(), 0, n / parts, L, x.data(), lower.data(), upper.data());
    for (auto& th : pool) th.join();
}

}  // namespace

NB_MODULE(_pair_features, m) {
    m.doc() = "Fused pair features of the landmark decoder (see src/pair_features.cpp).";
    m.def("landmark_features", &landmark_features, nb::arg("codes"), nb::arg("i"), nb::arg("j"), nb::arg("d"),
          nb::arg("k"), nb::arg("embedding"), nb::arg("euclidean"), nb::arg("x"), nb::arg("lower"),
          nb::arg("upper"), nb::arg("threads") = 1,
          "Fill x (P, decoder inputs), lower (P,) and upper (P,) for the pairs (i, j) of rows of codes (N, D + K + "
          "4), all float32 / int64 and C-contiguous, with up to `threads` threads.");
}
