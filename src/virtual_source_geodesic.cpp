// Approximate geodesic distances from one vertex to all vertices by virtual source propagation, in the
// spirit of GSP (Trettner, Bommes, Kobbelt, "Geodesic Distance Computation via Virtual Source
// Propagation", CGF 40(5) 2021).
//
// Each face f carries one virtual source: a point S_f in the face's own plane (its frame: corner 0 at
// the origin, corner 1 on +x, corner 2 above) and a distance sigma_f, so that a point X of the face is
// at sigma_f + |S_f - X| from the source along a path that is straight in the unfolding. The source
// vertex's faces start with S = the source, sigma = 0. A face hands its source to the face g across
// each of its edges ab but the one it came through, unfolded into the edge's frame in g (the rotation
// about the shared edge: a at the origin, b on +x, g's third vertex c above, S below). Two rays from S
// decide, the one to c and the one to the probe point p = c + probe (m - c) (m: g's centroid; the
// default probe 1 is m itself):
//
//     c:  d(c) <- sigma + |S - c|                 where the ray to c crosses the segment ab,
//         d(c) <- sigma + |S - e| + |e - c|       else, e the endpoint of ab the ray passes;
//     g:  S_g = S, sigma_g = sigma                 where the ray to p crosses ab,
//         S_g = e, sigma_g = d(e)                  else (the path bends around e: a saddle, a
//                                                  boundary, or a vertex another strip passes straight).
//
// A source on c's side of ab (it lit f through another edge) bends at the endpoint nearer m. g keeps
// the candidate when it is nearer at m than g's source so far, and is queued to hand it on. On a plane
// every unfolding is exact and so are the distances. The probe decides most: the ray to c alone (probe
// 0) stalls at every face whose middle corner faces the source (0.9% mean error instead of 0.2%).
//
// Gates. Where g keeps S although the ray to c passes an endpoint e that is no vertex of a plane (its
// corner angles sum to more than 2 pi + `saddle`, or, with `convex`, less than 2 pi - FLAT), e becomes a
// gate of g's source on that side: later faces see S only on the near side of the ray from S to e, and
// a vertex beyond it gets sigma + |S - e| + |e - x|, the path around e. Without gates, a strip that wraps
// round a saddle keeps its source and its far vertices get straight paths through the saddle's excess
// angle that the surface does not have: shortcuts. Gates only where one vertex's excess passed 0.05 rad
// let strips through smooth saddle regions, whose excess is spread over many vertices (tori 0.6-1.9%
// short, bent tubes 4-6%); gates at every saddle vertex alone still let them through thin tubes at finer
// resolutions (a trefoil knot at 22k vertices 1.25% short, at 64k 1.65%), which gates at convex vertices
// too close.
//
// A face keeps one source where the exact solver keeps a window for each family of paths that crosses
// it: where two families meet, and behind every gate, its vertices come out a little long. The fields end
// with fast marching's triangle update over the faces (relax_across_faces), which takes most of that back.
// Measured on the shape zoo and classic meshes (docs/benchmarks.md, "The shape zoo"): 0.07-0.33% mean
// error, long rather than short.

// Faces wait in Dial's buckets of width `bucket` mean edge lengths, first in first out within a bucket
// (the default), or in a binary heap, by their source's distance at their centroid; a face improved
// while it waits is handed on once, with its newest source. An accepted candidate is nearer at m by a
// relative 1e-12, so the propagation ends. The order changes the fixed point little.
//
// Edges are paired by their two vertices: an edge with one face is a boundary (no face across it), one
// with three or more is refused, and so is a vertex whose faces form two or more fans (nothing hands a
// source through a vertex). Faces may be oriented against each other. Vertices of other connected parts
// stay at infinity. A triangle soup (a point cloud's local triangles) comes with its gluing instead, each
// half-edge's twin given; its fields end relaxed along its edges (relax_along_edges). Memory: 64 bytes a
// half-edge (its unfolding, one cache line), 144 a face and 24 a vertex, and per thread 85 a face and 17
// a vertex: ~0.9 kB a vertex in all.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "dial_queues.h"
#include "threads.h"
#include "unfolded_surface.h"

namespace nb = nanobind;

namespace {

using namespace vsp;
constexpr double SETTLED = 1e-12;  // relative: a smaller improvement does not queue a face again
constexpr double ON_EDGE = 1e-12;  // relative to the edge's length: a source on the edge's line
// A ray that meets the edge's line within SEEN edge lengths of an endpoint passes through the edge, and
// a source bent at a vertex counts BENT relatively farther: where the source, the vertex and the face are
// in line (a regular grid is full of such lines) the unbent source, which lights the faces beyond the
// same way, wins the tie (without these, a flat grid is 3% off beyond its diagonals).
constexpr double SEEN = 1e-9;
constexpr double BENT = 1e-10;
constexpr double CHORD_SLACK = 1e-3;
constexpr double FLAT = 1e-6;  // radians: a vertex of excess within it is a vertex of a plane

// The design choices the benchmark ablates (benchmarks/bench_field_solver.py --ablation).
struct Choices {
    std::string queue = "buckets";  // or "heap"
    double bucket = 0.5;            // the buckets' width in mean edge lengths
    double probe = 1.0;             // the probe point: 0 the far vertex, 1 the face's centroid
    double saddle = FLAT;           // the angle excess (radians) from which a saddle vertex is a gate
    bool convex = true;             // convex vertices are gates too
    bool relax = true;              // the fields end with relax_across_faces
};

struct Source {
    double x, y, sigma;  // in the face's frame
    double best;         // its distance at the face's centroid
    int entered;         // the edge it came through, which it is not handed back across (-1: none)
    int gated;           // whether it has gates (Workspace::gates)
    int detoured = 0;    // whether it was bent around a saddle gate on its way (its distances may come out long)
};

// Vertices (not a plane's) a source's rays passed on their left (l) and right (r), in the face's frame: a
// point is seen only right of the ray to l and left of the ray to r, else the path bends there (NaN: none).
struct Gates {
    double lx, ly, rx, ry;
    bool ls, rs;  // whether each is a saddle vertex (a path around a convex one is no geodesic: not detoured)
};

struct Workspace {
    std::vector<double> d;  // per vertex, in the solver's numbering
    std::vector<Source> faces;
    std::vector<Gates> gates;
    Buckets buckets;
    Heap heap;
    int64_t processed = 0;
    std::vector<int> queue, next;  // a glued soup's relaxation along its edges: this round's vertices, the next's
    std::vector<char> queued;
    std::vector<int> order;  // the faces in the order the queue first gave them out: relax_across_faces' sweeps
    std::vector<char> ordered;
    std::vector<char> detoured;  // per vertex: its distance came by a path bent around a saddle gate
    std::vector<double> before;  // per vertex: the distances before the last update of relax_across_faces
    std::array<double, 3> from;  // the source's position
    std::vector<char> short_of_chord;  // per vertex: a value nearer than the segment from the source was refused
};

// Each source's field over a surface's tables: the propagation, then the relaxation.
class VirtualSources : public UnfoldedSurface {
public:
    using UnfoldedSurface::UnfoldedSurface;

    template <class Q>
    void distances(int64_t original, double* out, Workspace& w, Q& queue, const Choices& c) const {
        const int source = new_of_old_[original];
        w.from = {position_[3 * source], position_[3 * source + 1], position_[3 * source + 2]};
        w.d.assign(n_, INF);
        const bool relax = c.relax && edge_start_.empty();  // a glued soup ends relaxed along its edges instead
        w.order.clear();
        w.detoured.assign(n_, 0);
        w.short_of_chord.assign(n_, 0);
        if (relax) w.ordered.assign(m_, 0);
        double* d = w.d.data();
        w.faces.assign(m_, Source{0.0, 0.0, INF, INF, -1, 0});
        w.gates.resize(m_);
        queue.reset(c.bucket * mean_edge_, static_cast<size_t>(m_) + 1024);
        d[source] = 0.0;
        for (int i = vf_start_[source]; i < vf_start_[source + 1]; ++i) {
            const int f = vf_[i] / 3, k = vf_[i] % 3;
            const Point s = corner(f, k);
            for (int j = 0; j < 3; ++j) {
                const Point p = corner(f, j);
                d[F_[3 * f + j]] = std::min(d[F_[3 * f + j]], norm(p.x - s.x, p.y - s.y));
            }
            const Point m = centroid(f);
            w.faces[f] = {s.x, s.y, 0.0, norm(m.x - s.x, m.y - s.y), -1, 0};
            queue.push(w.faces[f].best, f);
        }
        for (double key; true;) {
            int f;
            if (!queue.pop(key, f)) break;
            if (key > w.faces[f].best) continue;  // a newer source of f is queued
            ++w.processed;
            if (relax && !w.ordered[f]) w.ordered[f] = 1, w.order.push_back(f);
            hand_on(f, d, w, queue, c);
        }
        for (int64_t v = 0; v < n_; ++v)  // reached only by paths shorter than the segment: the segment
            if (w.short_of_chord[v] && !(d[v] < INF)) d[v] = chord(w, static_cast<int>(v)) / (1.0 - CHORD_SLACK);
        if (!edge_start_.empty())
            relax_along_edges(d, w);
        else if (relax)
            relax_across_faces(d, w);
        for (int64_t i = 0; i < n_; ++i) out[old_of_new_[i]] = d[i];
    }

private:
    // d_v <= d_u + |uv| over a glued soup's edges (Bellman-Ford rounds from every vertex, then from those that
    // moved, until none does): edges left unglued can leave a vertex reached only the long way round, its
    // straight neighbours nearer.
    void relax_along_edges(double* d, Workspace& w) const {
        w.queue.resize(n_);
        for (int v = 0; v < n_; ++v) w.queue[v] = v;
        w.queued.assign(n_, 0);
        while (!w.queue.empty()) {
            w.next.clear();
            for (const int u : w.queue) {
                w.queued[u] = 0;
                if (!(d[u] < INF)) continue;
                for (int i = edge_start_[u]; i < edge_start_[u + 1]; ++i) {
                    const int v = edge_to_[i];
                    const double via = d[u] + edge_length_[i];
                    if (via < d[v]) {
                        d[v] = via;
                        if (!w.queued[v]) w.queued[v] = 1, w.next.push_back(v);
                    }
                }
            }
            std::swap(w.queue, w.next);
        }
    }
    // Gates at every vertex but a plane's leave no shortcut, but one source a face drops the other families of
    // paths that cross it: a vertex reached around a gate (detoured) comes out long where a family that
    // passed the gate's other side would have reached it straight, and where two families meet on a convex
    // surface a vertex is a little long too. Fast marching's triangle update (Kimmel and Sethian 1998) takes
    // the surplus back: the point S at d(a) from a and d(b) from b on the far side of the edge ab, and
    //     d(c) <- |S - c|    where the ray from S to c crosses the segment ab.
    // First one sweep over the faces with a corner detoured round a saddle gate (a path round a convex one is
    // no geodesic), in the order the queue first gave them out, a lowered corner counting as detoured for the
    // faces after it (it carries the family on); then one update of every face from the values the sweep left
    // (a lowered value is not used again in it). On
    // a surface without saddles the chained update comes out short: a sphere's fields 0.25% below exact
    // where they are 0.12% above; the single update there takes them to 0.08% above.
    void relax_across_faces(double* d, Workspace& w) const {
        for (const int f : w.order) {
            if (!(w.detoured[F_[3 * f]] || w.detoured[F_[3 * f + 1]] || w.detoured[F_[3 * f + 2]])) continue;
            for (int k = 0; k < 3; ++k) {
                const int c = F_[3 * f + k];
                if (upstream(f, k, d)) continue;
                const double to_c = across_face(f, k, d);
                if (to_c < d[c] * (1.0 - SETTLED) && to_c >= chord(w, c)) d[c] = to_c, w.detoured[c] = 1;
            }
        }
        w.before.assign(d, d + n_);
        const double* b = w.before.data();
        for (const int f : w.order)
            for (int k = 0; k < 3; ++k) {
                const int c = F_[3 * f + k];
                if (upstream(f, k, b)) continue;
                const double to_c = across_face(f, k, b);
                if (to_c < d[c] && to_c >= chord(w, c)) d[c] = to_c;
            }
    }

    // Whether face f's corner k is no farther than both others: a path to it does not cross the face, and
    // its update is not tried (a fifth of the relaxation's time; 1e-5 of the values move, by 1e-15 on
    // classic meshes and up to 0.5% on slivers).
    bool upstream(int f, int k, const double* d) const {
        return d[F_[3 * f + k]] <= std::min(d[F_[3 * f + (k + 1) % 3]], d[F_[3 * f + (k + 2) % 3]]);
    }

    // The triangle update of face f's corner k from the other two corners' values d (INF where it has none).
    double across_face(int f, int k, const double* d) const {
        const Opposite& o = opposite_[3 * f + k];
        const double da = d[F_[3 * f + (k + 1) % 3]], db = d[F_[3 * f + (k + 2) % 3]];
        if (!(da < INF && db < INF) || !(o.cy > 0.0)) return INF;
        const double x = (da * da - db * db + o.L * o.L) * o.half_inv_L, h2 = da * da - x * x;
        if (!(h2 > 0.0)) return INF;
        const double y = std::sqrt(h2), at = x + (o.cx - x) * y / (o.cy + y);
        if (at < 0.0 || at > o.L) return INF;
        return norm(o.cx - x, o.cy + y);
    }

    // Whether vertex v, passed by a kept source's ray, becomes a gate: a saddle (angle excess over `saddle`)
    // or, with `convex`, a convex vertex (a deficit over FLAT: not a vertex of a plane).
    bool gate(int v, const Choices& c) const {
        return excess_[v] > c.saddle || (c.convex && excess_[v] < -FLAT);
    }

    // The straight distance from the source to vertex v, less a relative CHORD_SLACK: no path is shorter,
    // and the fields' own error is allowed for (a straight line on a saddle patch comes out 0.04% short).
    double chord(const Workspace& w, int v) const {
        const double* p = &position_[3 * v];
        const double dx = p[0] - w.from[0], dy = p[1] - w.from[1], dz = p[2] - w.from[2];
        return std::sqrt(dx * dx + dy * dy + dz * dz) * (1.0 - CHORD_SLACK);
    }

    // Face f hands its source to the faces across its three edges (in each edge's frame in the face g
    // across it: A = (0, 0), B = (L, 0), C = (cx, cy) above).
    template <class Q>
    void hand_on(int f, double* d, Workspace& w, Q& queue, const Choices& c) const {
        const Source from = w.faces[f];
        for (int k = 0; k < 3; ++k) {
            const Across& u = across_[3 * f + k];
            if (u.packed < 0 || k == from.entered) continue;
            const int g = u.g();
            auto vertex = [&](bool at_b) { return F_[3 * g + (u.kg() + at_b) % 3]; };  // at A or B: when needed
            const double L = u.L, cx = u.cx, cy = u.cy, mx = (L + cx) / 3.0, my = cy / 3.0;
            const Point C = {cx, cy};
            Point t = u.map({from.x, from.y});
            double sigma = from.sigma;
            // the gates, left and right of the rays in this frame (a reflection swaps the sides)
            Point gl = {NAN, NAN}, gr = {NAN, NAN};
            bool ls = false, rs = false;
            if (from.gated) {
                const Gates& gates = w.gates[f];
                if (!std::isnan(gates.lx)) gl = u.map({gates.lx, gates.ly}), ls = gates.ls;
                if (!std::isnan(gates.rx)) gr = u.map({gates.rx, gates.ry}), rs = gates.rs;
                if (u.reflects()) std::swap(gl, gr), std::swap(ls, rs);
            }
            // where the rays from the source to C and to the probe point meet the edge's line; a source
            // on C's side sees nothing through the edge: bend at the endpoint nearer g's centroid
            double c_x, p_x;
            bool straight = false;
            Point p = C;
            if (t.y > ON_EDGE * L) {
                const bool at_a = d[vertex(false)] + norm(mx, my) <= d[vertex(true)] + norm(mx - L, my);
                c_x = p_x = at_a ? -1.0 : 2.0 * L + 1.0;
                t = {at_a ? 0.0 : L, 0.0};
                sigma = d[vertex(!at_a)];
            } else if (t.y >= -ON_EDGE * L) {
                c_x = p_x = t.x;
            } else {
                p = {cx + c.probe * (mx - cx), cy + c.probe * (my - cy)};
                c_x = t.x - (cx - t.x) * t.y / (cy - t.y);
                p_x = t.x - (p.x - t.x) * t.y / (p.y - t.y);
                straight = true;
            }
            // a point X is seen past the gates unless it is left of the ray to gl or right of the ray to gr
            auto blocked_by = [&](Point X) -> int {  // 0: seen, 1: left gate, 2: right gate
                if (!straight || !from.gated) return 0;
                if (!std::isnan(gl.x) && cross(t, gl, X) > 0.0) return 1;
                if (!std::isnan(gr.x) && cross(t, gr, X) < 0.0) return 2;
                return 0;
            };
            // C: straight where seen through the edge and past the gates, else around what it passes
            const double lo = -SEEN * L, hi = L * (1.0 + SEEN);
            double to_c;
            const int c_gate = blocked_by(C);
            if (c_gate) {
                const Point e = c_gate == 1 ? gl : gr;
                to_c = sigma + norm(e.x - t.x, e.y - t.y) + norm(cx - e.x, cy - e.y);
            } else if (c_x >= lo && c_x <= hi) {
                to_c = sigma + norm(cx - t.x, cy - t.y);
            } else {
                const double ex = c_x > L ? L : 0.0;
                to_c = sigma + norm(ex - t.x, t.y) + norm(cx - ex, cy);
            }
            // no path is shorter than the segment from the source: an unfolding that says so has left the
            // surface (a strip grazing a strongly convex source's fan gave 22% short values 2-7 edges from it)
            if (to_c < d[u.vc] && to_c >= chord(w, u.vc))
                d[u.vc] = to_c, w.detoured[u.vc] = (c_gate == 1 ? ls : c_gate == 2 && rs) || from.detoured;
            else if (to_c < d[u.vc])
                w.short_of_chord[u.vc] = 1;
            // g's source: S past the gates, with a new gate where the ray to C passes an endpoint (gate());
            // else what the ray to the probe point passes, a gate or an endpoint
            double tie = 1.0;
            const int p_gate = blocked_by(p);
            if (p_gate) {
                const Point e = p_gate == 1 ? gl : gr;
                sigma += norm(e.x - t.x, e.y - t.y);
                t = e;
                gl = gr = {NAN, NAN};
                tie = 1.0 + BENT;
            } else if (!(p_x >= lo && p_x <= hi)) {
                const bool at_b = p_x > L;
                t = {at_b ? L : 0.0, 0.0};
                sigma = d[vertex(at_b)];
                if (!(sigma < INF)) continue;
                gl = gr = {NAN, NAN};
                tie = 1.0 + BENT;
            } else if (straight && !c_gate && c_x < lo && gate(vertex(false), c)) {
                gl = {0.0, 0.0}, ls = excess_[vertex(false)] > FLAT;
            } else if (straight && !c_gate && c_x > hi && gate(vertex(true), c)) {
                gr = {L, 0.0}, rs = excess_[vertex(true)] > FLAT;
            }
            if (!straight && !p_gate) gl = gr = {NAN, NAN};
            const double at_m = (sigma + norm(mx - t.x, my - t.y)) * tie;
            Source& to = w.faces[g];
            if (at_m < to.best * (1.0 - SETTLED)) {  // into g's frame
                const Point a = corner(g, u.kg()), b = corner(g, (u.kg() + 1) % 3);
                const double inv = 1.0 / L, ex = (b.x - a.x) * inv, ey = (b.y - a.y) * inv;
                auto face = [&](Point q) { return Point{a.x + q.x * ex - q.y * ey, a.y + q.x * ey + q.y * ex}; };
                const Point s = face(t);
                const bool gated = !std::isnan(gl.x) || !std::isnan(gr.x);
                to = {s.x, s.y, sigma, at_m, u.kg(), gated, (p_gate == 1 ? ls : p_gate == 2 && rs) || from.detoured};
                if (gated) {
                    const Point l = face(gl), r = face(gr);
                    w.gates[g] = {l.x, l.y, r.x, r.y, ls, rs};
                }
                queue.push(at_m, g);
            }
        }
    }

};

using Vertices = nb::ndarray<const double, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu>;
using Faces = nb::ndarray<const int64_t, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu>;
using Sources = nb::ndarray<const int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Twins = nb::ndarray<const int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Excess = nb::ndarray<const double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Out = nb::ndarray<nb::numpy, double, nb::ndim<2>>;


// The fields of all sources (one row each), over `threads` threads taking sources in turn; each
// source's field depends on nothing but the source, so the result does not depend on the thread count.
Out solve(const VirtualSources& surface, const Sources& sources, int64_t threads, const Choices& c,
          int64_t* processed_total) {
    const size_t k = sources.shape(0), n = static_cast<size_t>(surface.n_vertices());
    const int64_t* src = sources.data();
    for (size_t i = 0; i < k; ++i)
        if (src[i] < 0 || src[i] >= surface.n_vertices()) throw std::invalid_argument("source vertex out of range");
    if (c.queue != "buckets" && c.queue != "heap") throw std::invalid_argument("queue: 'buckets' or 'heap'");
    if (!(c.bucket > 0.0)) throw std::invalid_argument("bucket width must be positive");
    if (!(c.probe >= 0.0 && c.probe <= 1.0)) throw std::invalid_argument("probe must be in [0, 1]");
    double* out = new double[std::max<size_t>(k * n, 1)];
    nb::capsule owner(out, [](void* p) noexcept { delete[] static_cast<double*>(p); });
    std::atomic<int64_t> processed{0};
    {
        nb::gil_scoped_release release;
        std::atomic<size_t> next{0};
        auto work = [&]() {
            Workspace w;
            for (size_t i; (i = next++) < k;) {
                if (c.queue == "heap")
                    surface.distances(src[i], out + i * n, w, w.heap, c);
                else
                    surface.distances(src[i], out + i * n, w, w.buckets, c);
            }
            processed += w.processed;
        };
        const int64_t team = std::max<int64_t>(1, std::min<int64_t>(threads, static_cast<int64_t>(k)));
        run_parts(team, [&](int64_t) { work(); });  // each takes sources until none is left
    }
    if (processed_total) *processed_total = processed;
    return Out(out, {k, n}, owner);
}

}  // namespace

NB_MODULE(_virtual_source_geodesic, m) {
    m.doc() = "Approximate geodesic distances by virtual source propagation (see src/virtual_source_geodesic.cpp).";
    nb::class_<VirtualSources>(m, "VirtualSources")
        .def(
            "__init__",
            [](VirtualSources* self, Vertices V, Faces F, std::optional<Twins> twins, std::optional<Excess> excess) {
                if (twins && twins->shape(0) != 3 * F.shape(0)) throw std::invalid_argument("twins: 3 M half-edges");
                if (excess && excess->shape(0) != V.shape(0)) throw std::invalid_argument("excess: one a vertex");
                new (self) VirtualSources(V.data(), V.shape(0), F.data(), F.shape(0), twins ? twins->data() : nullptr,
                                          excess ? excess->data() : nullptr);
            },
            nb::arg("vertices"), nb::arg("faces"), nb::arg("twins") = nb::none(), nb::arg("excess") = nb::none(),
            "Precompute a mesh: vertices (N, 3) float64 and faces (M, 3) int64, both C-contiguous; twins\n"
            "(3 M,) int64: the half-edge 3 g + j glued to each half-edge 3 f + k (-1: none), where edges are not\n"
            "paired by their vertices (a point cloud's soup; pinched vertices are then taken, and each field ends\n"
            "relaxed along the edges); excess (N,) float64:\n"
            "each vertex's angle excess for the gates, where the corners' angle sums do not give it.")
        .def("n_vertices", &VirtualSources::n_vertices)
        .def(
            "distances",
            [](const VirtualSources& self, Sources sources, int64_t threads, const std::string& queue, double bucket,
               double probe, double saddle, bool convex, bool relax) {
                return solve(self, sources, threads, Choices{queue, bucket, probe, saddle, convex, relax}, nullptr);
            },
            nb::arg("sources"), nb::arg("threads") = 1, nb::arg("queue") = "buckets", nb::arg("bucket") = 0.5,
            nb::arg("probe") = 1.0, nb::arg("saddle") = FLAT, nb::arg("convex") = true, nb::arg("relax") = true,
            "Distances (len(sources), N) float64 from each source vertex to every vertex; inf where unreached.\n"
            "queue ('buckets' or 'heap'), bucket (width in mean edge lengths), probe (the test point: 0 the far\n"
            "vertex, 1 the face's centroid), saddle (the angle excess from which a saddle vertex is a gate,\n"
            "radians), convex (convex vertices are gates too), relax (the fields end relaxed across the faces; a\n"
            "glued soup's along its edges whatever it says): the design choices.")
        .def(
            "processed",
            [](const VirtualSources& self, Sources sources) {
                int64_t total = 0;
                solve(self, sources, 1, Choices{}, &total);
                return total;
            },
            nb::arg("sources"), "How many faces the queue gave out (handed on) over all sources.");
}
