// Dense layers on a tile of rows held in cache, for the compiled decoders (src/pair_features.cpp): a small
// MLP (a few inputs to 64-256 hidden units) applied to a few dozen rows at a time, so its activations never
// leave L1/L2, where torch would run each layer over a whole chunk of pairs, out to memory and back.
//
// The kernels are templates on the vector type, instantiated per instruction set by the decoder's
// per-ISA entry points (target attributes, chosen at run time by cpu_isa): 16-float vectors on AVX512, 8 on
// AVX2 + FMA. A hidden unit's sum runs over the layer's inputs in order, one fused multiply-add at a time,
// on both; the last layer's dot product is split over the vector's lanes. So results agree between
// instruction sets, and with torch's matrix products, to within float rounding, not bit for bit.
#pragma once

#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>

#if defined(__GNUC__)
#define GEGNN_INLINE inline __attribute__((always_inline))
#else
#define GEGNN_INLINE inline
#endif

typedef float V8 __attribute__((vector_size(8 * sizeof(float))));
typedef float V16 __attribute__((vector_size(16 * sizeof(float))));

enum class Isa { none, avx2, avx512 };

// The widest kernel this CPU runs: AVX512, AVX2 with FMA, or none (the callers then keep torch's path:
// without FMA, the same kernels on SSE2 took 0.9 s for 1M landmark queries against torch's 0.49 s).
inline Isa cpu_isa() {
#if defined(__GNUC__) && defined(__x86_64__)
    __builtin_cpu_init();
    if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl")) return Isa::avx512;
    if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return Isa::avx2;
#endif
    return Isa::none;
}

inline const char* isa_name(Isa isa) { return isa == Isa::avx512 ? "avx512" : isa == Isa::avx2 ? "avx2" : "none"; }

// The kernel for a name ("auto": cpu_isa()); one the CPU lacks is refused, never run.
inline Isa parse_isa(const std::string& name) {
    const Isa best = cpu_isa();
    const Isa isa = name == "auto" ? best : name == "avx512" ? Isa::avx512 : name == "avx2" ? Isa::avx2 : Isa::none;
    if (isa == Isa::none || static_cast<int>(isa) > static_cast<int>(best))
        throw std::invalid_argument("instruction set '" + name + "' is not one this CPU runs (it has " +
                                    isa_name(best) + " of auto, avx2, avx512)");
    return isa;
}

// y[r][c] = max(0, b[c] + sum_k x[r][k] w[k][c]) for rows r < rows (a multiple of R) and columns c < n_out
// (a multiple of NV vectors); w is (n_in, n_out) row-major (the transpose of torch's Linear.weight).
// A block of R rows x NV vectors is accumulated in registers over all n_in inputs: each weight vector is
// loaded once per R rows, each input broadcast once per NV vectors.
template <class Vec, int R, int NV>
GEGNN_INLINE void dense_relu(const float* x, int64_t ldx, int64_t rows, const float* w, const float* b, int64_t n_in,
                             int64_t n_out, float* y, int64_t ldy) {
    constexpr int L = sizeof(Vec) / sizeof(float);
    for (int64_t r0 = 0; r0 < rows; r0 += R) {
        const float* xr = x + r0 * ldx;
        for (int64_t c0 = 0; c0 < n_out; c0 += L * NV) {
            Vec acc[R][NV];
            for (int v = 0; v < NV; ++v) {
                Vec bias;
                std::memcpy(&bias, b + c0 + v * L, sizeof(Vec));
                for (int r = 0; r < R; ++r) acc[r][v] = bias;
            }
            const float* wc = w + c0;
            for (int64_t k = 0; k < n_in; ++k, wc += n_out) {
                Vec wv[NV];
                for (int v = 0; v < NV; ++v) std::memcpy(&wv[v], wc + v * L, sizeof(Vec));
                for (int r = 0; r < R; ++r) {
                    const Vec xb = xr[r * ldx + k] - Vec{};  // a broadcast (x - 0 is x, unlike 0 + x for -0)
                    for (int v = 0; v < NV; ++v) acc[r][v] += xb * wv[v];
                }
            }
            for (int r = 0; r < R; ++r)
                for (int v = 0; v < NV; ++v) {
                    const Vec t = acc[r][v] < 0 ? Vec{} : acc[r][v];  // NaN stays NaN, as torch's relu
                    std::memcpy(y + (r0 + r) * ldy + c0 + v * L, &t, sizeof(Vec));
                }
        }
    }
}

// out[r] = b + sum_k x[r][k] w[k] (a layer of one output, n_in a multiple of the vector width).
template <class Vec>
GEGNN_INLINE void dense_one(const float* x, int64_t ldx, int64_t rows, const float* w, float b, int64_t n_in,
                            float* out) {
    constexpr int L = sizeof(Vec) / sizeof(float);
    for (int64_t r = 0; r < rows; ++r) {
        const float* xr = x + r * ldx;
        Vec acc = {};
        for (int64_t k = 0; k < n_in; k += L) {
            Vec xv, wv;
            std::memcpy(&xv, xr + k, sizeof(Vec));
            std::memcpy(&wv, w + k, sizeof(Vec));
            acc += xv * wv;
        }
        float s = 0;
        for (int l = 0; l < L; ++l) s += acc[l];
        out[r] = b + s;
    }
}
