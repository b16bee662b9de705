// The neighbourhood term of GeoConv (gegnn/nn/geoconv.py) with max aggregation, for inference on a CPU:
//
//     y_i = s_i + max_{j -> i} ( h_j + W_g [v_i - v_j | |v_i - v_j|] ),    the max = 0 for a vertex without edges,
//
// h = W_1 f (the neighbour features, one row per vertex), W_g the geometric block (G x C, G = 3 relative
// coordinates and/or the edge length), s = W_0 f + b the vertex's own term. The torch version gathers h to every
// edge, adds the geometric term (an (E x G) x (G x C) matmul), scatters the maximum back and adds s: three
// passes over an (E x C) array. Here each vertex's incoming edges (contiguous: edges are sorted by receiver, as
// gegnn builds them) are reduced in one pass over h's rows, no (E x C) array, and y is the only new array
// (h and s are read in place: the two halves of one matmul's output); vertices are split between threads.
//
// The geometric term is summed in the order g = 0..G-1 and then added to h_j, as torch's addmm does, so
// results equal the torch version's to within float rounding (the matmul kernel may fuse differently).
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <vector>

#include "simd.h"
#include "threads.h"

namespace nb = nanobind;

namespace {

struct Edges {
    const float *h, *self, *pos, *w;
    const int64_t *receiver, *sender;
    int64_t h_stride, self_stride, channels, g;  // row strides in floats
    bool relative, length;
};

GEGNN_CLONES
void reduce_vertices(const Edges& E, const int64_t* first_edge, int64_t v0, int64_t v1, float* out) {
    const int64_t C = E.channels, full = C / LANES * LANES;
    for (int64_t v = v0; v < v1; ++v) {
        float* y = out + v * C;
        const float* own = E.self + v * E.self_stride;
        const int64_t lo = first_edge[v - v0], hi = first_edge[v - v0 + 1];
        if (lo == hi) {
            std::copy(own, own + C, y);
            continue;
        }
        std::fill(y, y + C, -INFINITY);
        const float* pi = E.pos + 3 * v;
        for (int64_t e = lo; e < hi; ++e) {
            const int64_t j = E.sender[e];
            const float* pj = E.pos + 3 * j;
            const float dx = pi[0] - pj[0], dy = pi[1] - pj[1], dz = pi[2] - pj[2];
            float geo[4];
            int g = 0;
            if (E.relative) {
                geo[g++] = dx;
                geo[g++] = dy;
                geo[g++] = dz;
            }
            if (E.length) geo[g++] = std::sqrt(dx * dx + dy * dy + dz * dz);
            const float* hj = E.h + j * E.h_stride;
            int64_t c = 0;
            for (; c < full; c += LANES) {
                V t = {}, w, hv, yv;
                for (int k = 0; k < g; ++k) {
                    std::memcpy(&w, E.w + k * C + c, sizeof(V));
                    t += geo[k] * w;
                }
                std::memcpy(&hv, hj + c, sizeof(V));
                std::memcpy(&yv, y + c, sizeof(V));
                const V m = hv + t;
                yv = yv > m ? yv : m;
                std::memcpy(y + c, &yv, sizeof(V));
            }
            for (; c < C; ++c) {
                float t = 0.0f;
                for (int k = 0; k < g; ++k) t += geo[k] * E.w[k * C + c];
                y[c] = std::max(y[c], hj[c] + t);
            }
        }
        for (int64_t c = 0; c < C; ++c) y[c] = own[c] + y[c];
    }
}

using Rows = nb::ndarray<const float, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using StridedRows = nb::ndarray<const float, nb::ndim<2>, nb::device::cpu>;  // rows of any stride, columns dense
using Index = nb::ndarray<const int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Out = nb::ndarray<float, nb::ndim<2>, nb::c_contig, nb::device::cpu>;

// Returns false (and writes nothing) when the edges are not sorted by receiver.
bool max_messages(StridedRows h, StridedRows self, Rows pos, Index receiver, Index sender, Rows w_geometry,
                  bool relative, bool length, Out out, int threads) {
    const int64_t n = static_cast<int64_t>(h.shape(0)), C = static_cast<int64_t>(h.shape(1));
    const int64_t E = static_cast<int64_t>(receiver.shape(0));
    const int64_t g = 3 * relative + length;
    if (h.stride(1) != 1 || self.stride(1) != 1)
        throw std::invalid_argument("max_messages: h and self need contiguous columns");
    if (static_cast<int64_t>(self.shape(0)) != n || static_cast<int64_t>(self.shape(1)) != C ||
        static_cast<int64_t>(pos.shape(0)) != n || pos.shape(1) != 3 || static_cast<int64_t>(sender.shape(0)) != E ||
        static_cast<int64_t>(w_geometry.shape(0)) != g || (g && static_cast<int64_t>(w_geometry.shape(1)) != C) ||
        static_cast<int64_t>(out.shape(0)) != n || static_cast<int64_t>(out.shape(1)) != C)
        throw std::invalid_argument("max_messages: shapes disagree");
    const int64_t* r = receiver.data();
    const int64_t* s = sender.data();
    for (int64_t e = 0; e < E; ++e) {
        if (r[e] < 0 || r[e] >= n || s[e] < 0 || s[e] >= n) throw std::out_of_range("vertex index out of range");
        if (e && r[e] < r[e - 1]) return false;
    }
    nb::gil_scoped_release release;
    // first[v] = the first edge of vertex v (CSR offsets from the sorted receivers).
    std::vector<int64_t> first(n + 1);
    for (int64_t v = 0, e = 0; v <= n; ++v) {
        while (e < E && r[e] < v) ++e;
        first[v] = e;
    }
    const Edges edges{h.data(), self.data(), pos.data(), g ? w_geometry.data() : nullptr, r, s,
                      static_cast<int64_t>(h.stride(0)), static_cast<int64_t>(self.stride(0)), C, g, relative, length};
    const int64_t parts = std::max<int64_t>(1, std::min<int64_t>(threads, E / 4096));
    run_parts(parts, [&](int64_t t) {
        const int64_t v0 = n * t / parts, v1 = n * (t + 1) / parts;
        reduce_vertices(edges, first.data() + v0, v0, v1, out.data());
    });
    return true;
}

}  // namespace

NB_MODULE(_geoconv, m) {
    m.doc() = "GeoConv's max over incoming edge messages without an (edges x channels) array (src/geoconv.cpp).";
    m.def("max_messages", &max_messages, nb::arg("h"), nb::arg("self"), nb::arg("pos"), nb::arg("receiver"),
          nb::arg("sender"), nb::arg("w_geometry"), nb::arg("relative"), nb::arg("length"), nb::arg("out"),
          nb::arg("threads") = 1,
          "out[i] = self[i] + max over edges j -> i of h[j] + w_geometry^T [pos_i - pos_j | |pos_i - pos_j|] (the max "
          "is 0 without edges); float32 / int64; h and self may be row-strided views, the rest C-contiguous; False "
          "(nothing written) when the edges are not sorted by receiver.");
}
