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
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include "dense.h"
#include "simd.h"
#include "threads.h"

namespace nb = nanobind;

namespace {

struct Layout {
    int64_t width, d, k;
    bool embedding, euclidean;
    int64_t n_in() const { return (embedding ? d : 0) + 5 + (euclidean ? 1 : 0) + 1; }
};

// row[c] = (a[c] - b[c])^2 for c < n: the embedding part of a decoder's features.
GEGNN_INLINE void squared_difference(const float* a, const float* b, int64_t n, float* row) {
    for (int64_t c = 0; c < n; ++c) {
        const float t = a[c] - b[c];
        row[c] = t * t;
    }
}

// One pair's row of landmark features (the layout above), and its bounds.
GEGNN_INLINE void landmark_row(const float* a, const float* b, const Layout& L, float* row, float& lower,
                               float& upper) {
    if (L.embedding) {
        squared_difference(a, b, L.d, row);
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
    if (std::isnan(total)) m = u = total;  // a NaN value: the max and min above may have skipped it, torch's do not
    lower = m;
    upper = u;
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

// Rows are gathered at random: fetch the rows of a pair a few pairs ahead of its use.
constexpr int64_t AHEAD = 4;

GEGNN_INLINE void prefetch_pair(const float* codes, const int64_t* ia, const int64_t* ib, int64_t p, int64_t end,
                                int64_t width) {
    if (p + AHEAD >= end) return;
    const char* na = reinterpret_cast<const char*>(codes + ia[p + AHEAD] * width);
    const char* nb = reinterpret_cast<const char*>(codes + ib[p + AHEAD] * width);
    for (int64_t byte = 0; byte < width * 4; byte += 64) {
        __builtin_prefetch(na + byte);
        __builtin_prefetch(nb + byte);
    }
}

GEGNN_CLONES
void pair_rows(const float* codes, const int64_t* ia, const int64_t* ib, int64_t begin, int64_t end, Layout L,
               float* x, float* lower, float* upper) {
    const int64_t n_in = L.n_in();
    for (int64_t p = begin; p < end; ++p) {
        prefetch_pair(codes, ia, ib, p, end, L.width);
        landmark_row(codes + ia[p] * L.width, codes + ib[p] * L.width, L, x + p * n_in, lower[p], upper[p]);
    }
}

// ---- The whole decode: features and MLP, a tile of pairs at a time ----

enum Mode { DIFFERENCE = 0, LANDMARK = 1 };  // DistanceDecoder: x = (e_a - e_b)^2; LandmarkDecoder: the row above

struct Decode {
    const float* codes;
    const int64_t *ia, *ib;
    Layout L;
    int mode;
    std::vector<const float*> w, b;  // the MLP's layers, w (n_in, n_out) row-major; the last has n_out = 1
    std::vector<int64_t> n_in, n_out;
    int64_t widest;  // of the hidden layers
    float *t, *lower, *upper;  // out: the last layer's value (P,); the landmark bounds (P,)
};

constexpr int64_t TILE = 64;  // pairs whose activations stay in cache: 64 x 256 floats = 64 KiB a layer

// Pairs [begin, end): a tile's features, then its hidden layers and the last, before the next tile.
template <class Vec, int R, int NV>
GEGNN_INLINE void decode_range(const Decode& job, int64_t begin, int64_t end) {
    const int64_t n0 = job.n_in[0], width = job.L.width, hidden = static_cast<int64_t>(job.w.size()) - 1;
    constexpr int64_t ROWS = (TILE + R - 1) / R * R;  // a tile's rows, padded to whole register blocks
    std::vector<float> x(ROWS * n0, 0.0f), h0(ROWS * job.widest), h1(ROWS * job.widest);
    for (int64_t p0 = begin; p0 < end; p0 += TILE) {
        const int64_t rows = std::min(TILE, end - p0), padded = (rows + R - 1) / R * R;
        for (int64_t r = 0; r < rows; ++r) {
            const int64_t p = p0 + r;
            prefetch_pair(job.codes, job.ia, job.ib, p, end, width);
            const float* a = job.codes + job.ia[p] * width;
            const float* b = job.codes + job.ib[p] * width;
            float* row = x.data() + r * n0;
            if (job.mode == LANDMARK)
                landmark_row(a, b, job.L, row, job.lower[p], job.upper[p]);
            else
                squared_difference(a, b, width, row);
        }
        const float* in = x.data();
        int64_t ld = n0;
        float* out = h0.data();
        for (int64_t l = 0; l < hidden; ++l) {
            dense_relu<Vec, R, NV>(in, ld, padded, job.w[l], job.b[l], job.n_in[l], job.n_out[l], out, job.widest);
            in = out;
            ld = job.widest;
            out = out == h0.data() ? h1.data() : h0.data();
        }
        dense_one<Vec>(in, ld, rows, job.w[hidden], job.b[hidden][0], job.n_in[hidden], job.t + p0);
    }
}

// Hidden layers' widths must be multiples of this (the widest kernel's column block), on every CPU alike.
constexpr int64_t COLUMNS = 32;

#if defined(__GNUC__) && defined(__x86_64__)
__attribute__((target("avx512f,avx512vl,avx2,fma"))) void decode_avx512(const Decode& j, int64_t b, int64_t e) {
    decode_range<V16, 4, 2>(j, b, e);
}
__attribute__((target("avx2,fma"))) void decode_avx2(const Decode& j, int64_t b, int64_t e) {
    decode_range<V8, 4, 2>(j, b, e);
}
#else
void decode_avx512(const Decode&, int64_t, int64_t) {}  // never called: parse_isa refuses both here
void decode_avx2(const Decode&, int64_t, int64_t) {}
#endif

using Codes = nb::ndarray<const float, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using Index = nb::ndarray<const int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Rows = nb::ndarray<float, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using Column = nb::ndarray<float, nb::ndim<1>, nb::c_contig, nb::device::cpu>;

using Weights = nb::ndarray<const float, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using Bias = nb::ndarray<const float, nb::ndim<1>, nb::c_contig, nb::device::cpu>;

// Indices are trusted no further than this check: a bad one would read outside the codes.
void check_pairs(const Index& ia, const Index& ib, int64_t rows) {
    const int64_t n = static_cast<int64_t>(ia.shape(0));
    if (static_cast<int64_t>(ib.shape(0)) != n) throw std::invalid_argument("i and j differ in length");
    for (int64_t p = 0; p < n; ++p)
        if (ia.data()[p] < 0 || ia.data()[p] >= rows || ib.data()[p] < 0 || ib.data()[p] >= rows)
            throw std::out_of_range("vertex index out of range");
}

Layout landmark_layout(const Codes& codes, int64_t d, int64_t k, bool embedding, bool euclidean) {
    const Layout L{static_cast<int64_t>(codes.shape(1)), d, k, embedding, euclidean};
    if (L.width != d + k + 4)
        throw std::invalid_argument("codes have " + std::to_string(L.width) + " columns, expected D + K + 4 = " +
                                    std::to_string(d + k + 4));
    return L;
}

// work(begin, end) on pairs [0, n) cut into one contiguous block per thread (at least 1024 pairs a block).
template <class Work>
void split(int64_t n, int threads, Work work) {
    const int64_t parts = std::max<int64_t>(1, std::min<int64_t>(threads, n / 1024));
    run_parts(parts, [&](int64_t t) { work(n * t / parts, n * (t + 1) / parts); });
}

void landmark_features(Codes codes, Index ia, Index ib, int64_t d, int64_t k, bool embedding, bool euclidean,
                       Rows x, Column lower, Column upper, int threads) {
    const Layout L = landmark_layout(codes, d, k, embedding, euclidean);
    const int64_t n = static_cast<int64_t>(ia.shape(0));
    if (static_cast<int64_t>(x.shape(0)) != n || static_cast<int64_t>(x.shape(1)) != L.n_in() ||
        static_cast<int64_t>(lower.shape(0)) != n || static_cast<int64_t>(upper.shape(0)) != n)
        throw std::invalid_argument("pair arrays disagree in length, or x is not (pairs, decoder inputs)");
    check_pairs(ia, ib, static_cast<int64_t>(codes.shape(0)));
    nb::gil_scoped_release release;
    split(n, threads, [&](int64_t begin, int64_t end) {
        pair_rows(codes.data(), ia.data(), ib.data(), begin, end, L, x.data(), lower.data(), upper.data());
    });
}

void decode_pairs(Codes codes, Index ia, Index ib, int mode, int64_t d, int64_t k, bool embedding, bool euclidean,
                  const std::vector<Weights>& weights, const std::vector<Bias>& biases, Column t, Column lower,
                  Column upper, int threads, const std::string& isa_name) {
    const Isa isa = parse_isa(isa_name);
    const int64_t n = static_cast<int64_t>(ia.shape(0));
    Decode job{codes.data(), ia.data(), ib.data(), {}, mode, {}, {}, {}, {}, 0, t.data(), lower.data(), upper.data()};
    int64_t n_in;
    if (mode == LANDMARK) {
        job.L = landmark_layout(codes, d, k, embedding, euclidean);
        n_in = job.L.n_in();
        if (static_cast<int64_t>(lower.shape(0)) != n || static_cast<int64_t>(upper.shape(0)) != n)
            throw std::invalid_argument("lower and upper must have one value per pair");
    } else if (mode == DIFFERENCE) {
        job.L = Layout{static_cast<int64_t>(codes.shape(1)), 0, 0, false, false};
        n_in = job.L.width;
    } else {
        throw std::invalid_argument("mode must be 0 (embedding difference) or 1 (landmark features)");
    }
    if (weights.size() < 2 || weights.size() != biases.size())
        throw std::invalid_argument("need one bias per weight, and at least one hidden layer and the last");
    for (size_t l = 0; l < weights.size(); ++l) {
        const int64_t rows = static_cast<int64_t>(weights[l].shape(0)), cols = static_cast<int64_t>(weights[l].shape(1));
        const bool last = l + 1 == weights.size();
        if (rows != n_in || static_cast<int64_t>(biases[l].shape(0)) != cols || (last ? cols != 1 : cols % COLUMNS))
            throw std::invalid_argument("layer " + std::to_string(l) + " is (" + std::to_string(rows) + ", " +
                                        std::to_string(cols) + "): needs " + std::to_string(n_in) +
                                        " inputs, a bias per output, and " +
                                        (last ? std::string("1 output") : "a multiple of 32 outputs"));
        job.w.push_back(weights[l].data());
        job.b.push_back(biases[l].data());
        job.n_in.push_back(rows);
        job.n_out.push_back(cols);
        if (!last) job.widest = std::max(job.widest, cols);
        n_in = cols;
    }
    if (static_cast<int64_t>(t.shape(0)) != n) throw std::invalid_argument("t must have one value per pair");
    check_pairs(ia, ib, static_cast<int64_t>(codes.shape(0)));
    nb::gil_scoped_release release;
    split(n, threads, [&](int64_t begin, int64_t end) {
        if (isa == Isa::avx512) return decode_avx512(job, begin, end);
        decode_avx2(job, begin, end);
    });
}

}  // namespace

NB_MODULE(_pair_features, m) {
    m.doc() = "The pair decoders on a CPU: fused features, and features + MLP (see src/pair_features.cpp).";
    m.def("landmark_features", &landmark_features, nb::arg("codes"), nb::arg("i"), nb::arg("j"), nb::arg("d"),
          nb::arg("k"), nb::arg("embedding"), nb::arg("euclidean"), nb::arg("x"), nb::arg("lower"),
          nb::arg("upper"), nb::arg("threads") = 1,
          "Fill x (P, decoder inputs), lower (P,) and upper (P,) for the pairs (i, j) of rows of codes (N, D + K + "
          "4), all float32 / int64 and C-contiguous, with up to `threads` threads.");
    m.def("decode_pairs", &decode_pairs, nb::arg("codes"), nb::arg("i"), nb::arg("j"), nb::arg("mode"), nb::arg("d"),
          nb::arg("k"), nb::arg("embedding"), nb::arg("euclidean"), nb::arg("weights"), nb::arg("biases"),
          nb::arg("t"), nb::arg("lower"), nb::arg("upper"), nb::arg("threads") = 1, nb::arg("isa") = "auto",
          "The MLP's last value t (P,) of the pairs (i, j) of rows of codes, from their features (mode 0: (e_i - "
          "e_j)^2 of the whole rows; mode 1: the landmark features, also filling lower and upper) through the "
          "layers weights[l] (n_in, n_out) (torch's Linear.weight transposed) and biases[l], ReLU after all but "
          "the last (1 output), in tiles of pairs held in cache. isa: 'auto', 'avx512' or 'avx2'.");
    m.def("cpu_isa", [] { return std::string(isa_name(cpu_isa())); },
          "The instruction set 'auto' picks on this CPU: 'avx512', 'avx2' (with FMA), or 'none' (no compiled "
          "decode: torch's path).");
}
