// What the compiled inference kernels (src/pair_features.cpp, src/geoconv.cpp) share: 8-float vectors
// (GCC/Clang vector extension) and per-CPU clones of the hot functions.
#pragma once

constexpr int LANES = 8;
typedef float V __attribute__((vector_size(LANES * sizeof(float))));

#if defined(__GNUC__) && defined(__x86_64__) && !defined(__clang__)
// AVX2 where the CPU has it, SSE2 elsewhere: one build runs on every x86-64 node of a cluster.
#define GEGNN_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define GEGNN_CLONES
#endif
