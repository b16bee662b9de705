// Exact polyhedral geodesic distances from one vertex to all vertices by window propagation.
//
// A window is an interval [b0, b1] of a half-edge h together with the unfolded position S of the
// (pseudo-)source that lights it and that source's distance sigma: every point X of the interval is at
// distance sigma + |S - X| along a straight path in the unfolding (Mitchell-Mount-Papadimitriou;
// Surazhsky et al. 2005). Windows are kept in the half-edge's frame: its start vertex at the origin, its
// end vertex on +x, the face it lights (face h / 3) on +y and S on y <= 0.
//
// Only the wavefront is kept (VTP, Qin et al. 2016): a window waits on its half-edge until the
// half-edge's turn comes, then all windows waiting there cross the face together and are dropped, their
// children waiting on the face's other two half-edges. Memory grows with the wavefront, not with all
// windows ever made (~N^1.5 on smooth meshes: 313 MiB of windows at 40k vertices before, 3 MiB now), and
// distances are the same to 1e-14. As in Chen-Han / ICH (Xin and Wang 2009), windows are not merged into
// one partition of each edge (MMP's costly step). Instead a window is cut or dropped wherever a real
// path is shorter by a relative margin (1e-12), so rounding never removes a shortest path:
//   1. vertex filter: a window on edge AB is useless when d(A) + |A X| < sigma + |S X| at its far end
//      from A (|S X| - |A X| only decreases away from A), or the same from B; checked when it is made
//      and again when it crosses, with the vertices' distances of then.
//   2. one angle, two sides: of all windows that crossed h so far (the current batch included), the one
//      with the shortest straight path to the opposite vertex C crosses h at sp*. A window whose planar
//      distance to C is longer cannot reach the far side of the segment sp*-C first: its rays through
//      x < sp* never continue onto edge BC, nor rays through x > sp* onto edge AC (exchange argument at
//      the crossing point). Two numbers a half-edge keep it across batches.
//   3. windows on one half-edge: between two crossings of their distance functions (roots of a
//      quadratic) one window is shorter throughout; each loses the ends of its interval where the other
//      is shorter. A middle part is kept, never split. A batch is sorted by start and each window is
//      compared with the survivors before it that overlap it (trimming leaves the starts only nearly
//      sorted: a comparison missed only prunes less). Windows that crossed earlier are gone and no
//      longer compared: on smooth meshes of 10k-160k vertices that made 0.2% more windows.
//   4. relay: a window within a hair of a vertex V (its whole interval closer to V than 1e-11 of its
//      distance) is replaced by V, which lights its edges for this source as a pseudo-source does. Every
//      path through the window reaches a point Y beyond it no shorter than d(V) + d(V, Y) - 2 hairs,
//      and V's own windows give d(V) + d(V, Y): distances change by 3e-11 relative at most. Without
//      it, windows that pass a vertex within rounding pile up on its edges by the thousand (on
//      openDoor.obj, around a needle tip of total angle 0.005 rad they spiral round).
// With a tolerance t > 0, rules 1-3 prune a window already where a real path is within a factor 1 - t of it
// (not only where one is shorter), and a vertex whose path pruned a window by rule 1 only thanks to t
// relays it (rule 4's step), so the paths it stands for go on from there. Every value is still a real
// path's length (pruning only drops candidates), never below exact; the error is measured, not bounded:
// benchmarks/bench_field_frontier.py.
// Half-edges wait in buckets of their earliest window's smallest distance and leave each bucket first
// in, first out (the fast wavefront of Xu et al. 2015); a half-edge whose windows all crossed is queued
// again by the next window that reaches it. Since every rule prunes against real paths (rule 4 up to its
// 3 hairs), the order only costs time, never exactness; a saddle or boundary vertex lights the edges
// opposite it again whenever its distance improves after it did so.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <new>
#include <stdexcept>
#include <type_traits>
#include <utility>
#include <vector>

#include "exact_windows.h"
#include "threads.h"
#include "vertex_corners.h"

namespace nb = nanobind;

namespace {

using namespace windows;

constexpr double INF = std::numeric_limits<double>::infinity();
constexpr double MARGIN = 1e-12;      // relative: prune only what is worse than a real path by more
constexpr double HAIR = 1e-11;   // relative to a window's distance: closer to a vertex, it relays (rule 4)
constexpr double BUCKET = 0.05;  // bucket width / mean edge length (0.02-0.3: within 5% at 160k vertices)

// The mesh, read-only once built: the half-edge tables every source's propagation reads.
class Surface {
public:
    Surface(const double* V, int64_t n, const int32_t* F, int64_t m) : n_(n), m_(m), F_(F, F + 3 * m) {
        for (int64_t i = 0; i < 3 * m; ++i)
            if (F_[i] < 0 || F_[i] >= n) throw std::invalid_argument("face index out of range");
        build_twins();
        build_frames(V);
        vertex_corners(F_, n_, vf_start_, vf_);
        double total = 0.0;
        for (double l : len_) total += l;
        width_ = BUCKET * total / std::max<size_t>(len_.size(), 1);
    }

    int64_t n_vertices() const { return n_; }

    int64_t n_, m_;
    std::vector<int32_t> F_;
    std::vector<int> twin_;             // per half-edge h = 3 f + k (F[h] -> F[next(h)]): its twin or -1
    std::vector<double> len_, cx_, cy_;  // per half-edge: length, opposite vertex in its frame (cy >= 0)
    std::vector<char> pseudo_;          // per vertex: saddle (angle sum > 2 pi) or on the boundary
    std::vector<int> vf_start_, vf_;    // faces around each vertex (CSR), as half-edges leaving it
    double width_ = 1.0;                // bucket width

private:
    static int next(int h) { return h % 3 == 2 ? h - 2 : h + 1; }
    static int prev(int h) { return h % 3 == 0 ? h + 2 : h - 1; }

    void build_twins() {
        std::vector<std::pair<std::pair<int, int>, int>> keys(3 * m_);
        for (int h = 0; h < 3 * m_; ++h) {
            const int a = F_[h], b = F_[next(h)];
            keys[h] = {{std::min(a, b), std::max(a, b)}, h};
        }
        std::sort(keys.begin(), keys.end());
        twin_.assign(3 * m_, -1);
        for (size_t i = 0; i + 1 < keys.size(); ++i) {
            if (keys[i].first != keys[i + 1].first) continue;
            const bool lone = (i + 2 >= keys.size() || keys[i + 2].first != keys[i].first) &&
                              (i == 0 || keys[i - 1].first != keys[i].first);
            if (lone) {  // exactly two half-edges: a manifold edge (more: left as boundary, never paired)
                twin_[keys[i].second] = keys[i + 1].second;
                twin_[keys[i + 1].second] = keys[i].second;
            }
        }
    }

    void build_frames(const double* V) {  // the positions are needed only here
        len_.resize(3 * m_);
        cx_.resize(3 * m_);
        cy_.resize(3 * m_);
        std::vector<double> angle_sum(n_, 0.0);
        pseudo_.assign(n_, 0);
        for (int h = 0; h < 3 * m_; ++h) {
            const double* a = &V[3 * F_[h]];
            const double* b = &V[3 * F_[next(h)]];
            const double* c = &V[3 * F_[prev(h)]];
            double u[3], w[3];
            for (int i = 0; i < 3; ++i) u[i] = b[i] - a[i], w[i] = c[i] - a[i];
            const double L = hypot2(hypot2(u[0], u[1]), u[2]);
            const double x = L > 0.0 ? (u[0] * w[0] + u[1] * w[1] + u[2] * w[2]) / L : 0.0;
            const double cw = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
            len_[h] = L;
            cx_[h] = x;
            cy_[h] = std::sqrt(std::max(cw - x * x, 0.0));
            angle_sum[F_[h]] += std::atan2(cy_[h], x);  // the corner angle at the start vertex
            if (twin_[h] < 0) pseudo_[F_[h]] = pseudo_[F_[next(h)]] = 1;
        }
        for (int64_t v = 0; v < n_; ++v)
            if (angle_sum[v] > 2.0 * M_PI * (1.0 + 1e-9)) pseudo_[v] = 1;  // a geodesic passes a flat vertex straight
    }
};

// One source's propagation on a Surface: the wavefront and the distances, reused source after source (one a
// thread: sources are independent, so the fields do not depend on how many threads share them).
class Front {
public:
    explicit Front(const Surface& s)
        : n_(s.n_), F_(s.F_), twin_(s.twin_), len_(s.len_), cx_(s.cx_), cy_(s.cy_), pseudo_(s.pseudo_),
          vf_start_(s.vf_start_), vf_(s.vf_), width_(s.width_) {
        d_.resize(n_);
        emitted_.resize(n_);
        best_d_.resize(3 * s.m_);
        best_sp_.resize(3 * s.m_);
        head_.resize(3 * s.m_);
        due_.resize(3 * s.m_);
    }

    void distances(int64_t source, double* out, double tolerance) {
        keep_ = tolerance > 0.0 ? 1.0 - tolerance : 1.0 + MARGIN;
        std::fill(d_.begin(), d_.end(), INF);
        std::fill(emitted_.begin(), emitted_.end(), INF);
        emits_ = pseudo_;
        emits_[source] = 1;
        std::fill(best_d_.begin(), best_d_.end(), INF);
        std::fill(head_.begin(), head_.end(), -1);
        std::fill(due_.begin(), due_.end(), -1);
        chunks_.clear();
        queue_.reset(width_);
        source_ = static_cast<int>(source);
        improve(source_, 0.0);
        size_t b;
        for (int id; queue_.pop(id, b);) {
            if (id < 0)
                settle(-id - 1);
            else if (due_[id] == static_cast<int64_t>(b))
                sweep(id);
        }
        std::copy(d_.begin(), d_.end(), out);
    }

private:
    const int64_t n_;
    const std::vector<int32_t>& F_;
    const std::vector<int>& twin_;
    const std::vector<double>&len_, &cx_, &cy_;
    const std::vector<char>& pseudo_;
    const std::vector<int>&vf_start_, &vf_;
    const double width_;
    // per source
    std::vector<char> emits_;  // per vertex: lights its edges (pseudo-source, source or relay)
    std::vector<double> d_, best_d_, best_sp_;
    std::vector<double> emitted_;  // per vertex: the distance at which it last lit its edges
    ChunkStore chunks_;
    std::vector<int> head_;      // per half-edge: the windows waiting on it (-1: none)
    std::vector<int64_t> due_;  // per half-edge: the bucket it is queued in (-1: none; older entries are stale)
    std::vector<Window> batch_;  // the windows of the half-edge that sweeps
    struct Paths {
        double to0, to1, sp, planar;  // distances at b0 and b1; where the path to C crosses, its length
    };
    std::vector<Paths> paths_;
    BucketQueue queue_;
    int source_ = 0;
    double keep_ = 1.0 + MARGIN;  // a window survives a real path only if shorter than it times this

    static int next(int h) { return h % 3 == 2 ? h - 2 : h + 1; }
    static int prev(int h) { return h % 3 == 0 ? h + 2 : h - 1; }

    // A vertex that lights its edges from now on, for this source, like a pseudo-source (rule 4).
    void relay(int v) {
        if (emits_[v]) return;
        emits_[v] = 1;
        if (d_[v] < INF) queue_.push(d_[v], -v - 1);
    }

    void improve(int v, double dist) {
        if (dist < d_[v]) {
            d_[v] = dist;
            if (emits_[v]) queue_.push(dist, -v - 1);
        }
    }

    // A vertex's distance is final: a source, pseudo-source or relay lights the edges opposite it.
    void settle(int v) {
        if (d_[v] >= emitted_[v]) return;
        emitted_[v] = d_[v];
        for (int i = vf_start_[v]; i < vf_start_[v + 1]; ++i) {
            const int h = vf_[i];  // leaves v in its face; the edge opposite v is next(h)
            improve(F_[next(h)], d_[v] + len_[h]);  // both neighbours, for boundary vertices
            improve(F_[prev(h)], d_[v] + len_[prev(h)]);
            const int e = next(h);
            // v in e's frame is its opposite vertex (cx, cy); the window lights the face across e
            emit_child(e, 0.0, 0.0, len_[e], 0.0, cx_[e], cy_[e], cx_[e], cy_[e], 0.0, 0.0, len_[e], 0.0, d_[v]);
        }
    }

    // The window that continues across half-edge e of the current face, given in the current frame:
    // e runs from P to Q, T is the face's third vertex, S the source, X0 and X1 the ends of the lit part.
    void emit_child(int e, double px, double py, double qx, double qy, double tx, double ty, double sx,
                    double sy, double x0x, double x0y, double x1x, double x1y, double sigma) {
        const int t = twin_[e];
        if (t < 0) return;
        // t's frame: origin at t's start vertex, +x along t, the current face on -y
        const bool start_at_q = F_[t] == F_[next(e)];
        const double ox = start_at_q ? qx : px, oy = start_at_q ? qy : py;
        const double ex = start_at_q ? px : qx, ey = start_at_q ? py : qy;
        const double L = len_[t];
        if (!(L > 0.0)) return;
        const double ux = (ex - ox) / L, uy = (ey - oy) / L;
        // -y is toward the current face's third vertex (S lies on that side too, or on the line)
        double nx = -uy, ny = ux;
        if (cross(ux, uy, tx - ox, ty - oy) > 0.0) nx = uy, ny = -ux;
        auto fx = [&](double x, double y) { return (x - ox) * ux + (y - oy) * uy; };
        auto fy = [&](double x, double y) { return (x - ox) * nx + (y - oy) * ny; };
        double s0 = fx(x0x, x0y), s1 = fx(x1x, x1y);
        if (s0 > s1) std::swap(s0, s1);
        s0 = std::max(s0, 0.0);
        s1 = std::min(s1, L);
        if (s1 <= s0) return;
        add_window({s0, s1, fx(sx, sy), std::min(fy(sx, sy), 0.0), sigma, t});
    }

    // Cut the start or end of [b0, b1] where the other window is shorter by more than the margin (a
    // dominated middle part stays). Returns false when nothing is left.
    static bool cut_dominated(Window& w, const double* cut, const bool* worse, int k) {
        double keep0 = w.b0, keep1 = w.b1;
        for (int i = 0; i < k && worse[i] && cut[i] <= keep0; ++i) keep0 = cut[i + 1];
        for (int i = k - 1; i >= 0 && worse[i] && cut[i + 1] >= keep1; --i) keep1 = cut[i];
        if (keep1 <= keep0) return false;
        w.b0 = keep0;
        w.b1 = keep1;
        return true;
    }

    // Two windows on one half-edge: between two crossings of their distance functions one is shorter
    // throughout (tested in the middle); each loses the ends where the other is shorter. Returns false
    // when nothing of w is left; o is emptied (b1 = -inf) when nothing of it is left. Windows that overlap
    // by less than 1% of the longer are left as they are: 60% of the contests, most of which cut nothing
    // (5-15% faster from 5k to 160k vertices, distances unchanged; a cut left out only prunes less).
    bool contest(Window& w, Window& o) const {
        const double lo = std::max(w.b0, o.b0), hi = std::min(w.b1, o.b1);
        if (hi - lo <= 1e-9 * hi || hi - lo < 0.01 * std::max(w.b1 - w.b0, o.b1 - o.b0)) return true;
        double cut[4] = {lo, 0.0, 0.0, 0.0}, roots[2];
        int k = 1;
        for (int i = 0, n = crossings(w, o, roots); i < n; ++i)
            if (roots[i] > lo && roots[i] < hi) cut[k++] = roots[i];
        std::sort(cut + 1, cut + k);
        cut[k] = hi;
        bool w_worse[3], o_worse[3];
        for (int i = 0; i < k; ++i) {
            const double mid = 0.5 * (cut[i] + cut[i + 1]), dw = at(w, mid), dout = at(o, mid);
            w_worse[i] = dw > dout * keep_;
            o_worse[i] = !w_worse[i] && dout > dw * (1.0 + MARGIN);
        }
        if (!cut_dominated(o, cut, o_worse, k)) o.b1 = -INF;  // dominated
        return cut_dominated(w, cut, w_worse, k);
    }

    // Rule 1: longer at its far end from A than the path through A, or the same for B.
    // to0, to1: the window's distances at b0 and b1.
    bool useless(const Window& w, double to0, double to1) {
        const int a = F_[w.h], b = F_[next(w.h)];
        const double via_a = d_[a] + w.b1, via_b = d_[b] + len_[w.h] - w.b0;
        if (to1 > via_a * keep_) {
            if (to1 <= via_a * (1.0 + MARGIN)) relay(a);  // pruned only by the tolerance: a carries its paths on
            return true;
        }
        if (to0 > via_b * keep_) {
            if (to0 <= via_b * (1.0 + MARGIN)) relay(b);
            return true;
        }
        return false;
    }

    // The edge's vertices take the paths through the window's ends (to0, to1: its distances there).
    void reach_ends(const Window& w, double to0, double to1) {
        improve(F_[w.h], to0 + w.b0);
        improve(F_[next(w.h)], to1 + len_[w.h] - w.b1);
    }

    // Vertex filter and relay (a window within a hair of a vertex); then the window waits on its
    // half-edge, which is queued by its earliest window, and the edge's vertices take the paths
    // through its ends.
    void add_window(Window w) {
        const double to0 = at(w, w.b0), to1 = at(w, w.b1);
        if (useless(w, to0, to1)) return;
        reach_ends(w, to0, to1);
        const bool at_start = w.b1 <= HAIR * to0;
        if (at_start || w.b0 >= len_[w.h] - HAIR * to1) {
            relay(at_start ? F_[w.h] : F_[next(w.h)]);
            return;
        }
        const int h = w.h;
        if (head_[h] < 0 || chunks_[head_[h]].n == CHUNK) head_[h] = chunks_.take(head_[h]);
        Chunk& c = chunks_[head_[h]];
        c.w[c.n++] = w;
        schedule(h, w.sx < w.b0 ? to0 : (w.sx > w.b1 ? to1 : w.sigma - w.sy));  // its least distance
    }

    void schedule(int h, double key) {
        const int64_t b = static_cast<int64_t>(queue_.bucket(key));
        if (due_[h] < 0 || b < due_[h]) {
            due_[h] = b;
            queue_.push_at(b, h);
        }
    }

    // The windows waiting on half-edge h, all at once (VTP's triangle-oriented step): sorted by start,
    // each is trimmed against the kept ones before it that overlap it (rule 3); the shortest straight
    // path to the opposite vertex among the survivors is found (rule 2); then all cross the face.
    void sweep(int h) {
        due_[h] = -1;
        batch_.clear();
        for (int i = head_[h]; i >= 0;) {
            const Chunk& c = chunks_[i];
            batch_.insert(batch_.end(), c.w, c.w + c.n);
            const int after = c.next;
            chunks_.release(i);
            i = after;
        }
        head_[h] = -1;
        std::sort(batch_.begin(), batch_.end(), [](const Window& a, const Window& b) { return a.b0 < b.b0; });
        size_t kept = 0;  // batch_[0, kept): the survivors so far, by start
        for (size_t i = 0; i < batch_.size(); ++i) {
            Window w = batch_[i];
            // rule 1 again: the vertices may have improved since it came
            if (useless(w, at(w, w.b0), at(w, w.b1))) continue;
            bool alive = true, emptied = false;
            // back from the last survivor; past the last two, stop at the first that ends before w starts
            // (trimming leaves the starts only nearly sorted: a comparison missed only prunes less)
            for (size_t j = kept; j-- > 0;) {
                Window& o = batch_[j];
                if (o.b1 <= w.b0 && j + 2 < kept) break;
                alive = contest(w, o);
                emptied |= o.b1 < o.b0;
                if (!alive) break;
            }
            if (emptied) kept = std::remove_if(batch_.begin(), batch_.begin() + kept,
                                               [](const Window& o) { return o.b1 < o.b0; }) - batch_.begin();
            if (alive) batch_[kept++] = w;
        }
        const double cx = cx_[h], cy = cy_[h];
        if (cy <= 0.0) return;  // a degenerate face lights nothing
        const int c = F_[prev(h)];
        paths_.resize(kept);
        for (size_t i = 0; i < kept; ++i) {  // rule 2's best path over the whole batch before any crosses
            const Window& w = batch_[i];
            Paths& x = paths_[i];
            x.to0 = at(w, w.b0), x.to1 = at(w, w.b1);
            // where the ray from S to C crosses the edge, and the distance to C through the window
            x.sp = w.sx - w.sy * (cx - w.sx) / (cy - w.sy);
            x.planar = w.sigma + hypot2(cx - w.sx, cy - w.sy);
            if (x.sp < w.b0)
                improve(c, x.to0 + hypot2(cx - w.b0, cy));
            else if (x.sp > w.b1)
                improve(c, x.to1 + hypot2(cx - w.b1, cy));
            else {
                improve(c, x.planar);
                if (x.planar < best_d_[h]) best_d_[h] = x.planar, best_sp_[h] = x.sp;
            }
        }
        for (size_t i = 0; i < kept; ++i) propagate(batch_[i], paths_[i]);  // children go to other half-edges
    }

    // The window's rays across its face onto the two other edges (x: its distances and its path to the
    // opposite vertex, from sweep), each side cut at the best path's crossing unless it is its own.
    void propagate(const Window& w, const Paths& x) {
        const int h = w.h;
        const double L = len_[h], cx = cx_[h], cy = cy_[h], sp = x.sp;
        double left_end = std::min(w.b1, sp), right_start = std::max(w.b0, sp);
        if (x.planar > best_d_[h] * keep_) {
            left_end = std::min(left_end, best_sp_[h]);
            right_start = std::max(right_start, best_sp_[h]);
        }
        if (left_end > w.b0) {  // rays onto edge C -> A (prev(h)), from A's side
            const double m0 = hit(w.sx, w.sy, w.b0, 0.0, 0.0, cx, cy);
            const double m1 = hit(w.sx, w.sy, left_end, 0.0, 0.0, cx, cy);
            emit_child(prev(h), cx, cy, 0.0, 0.0, L, 0.0, w.sx, w.sy, m0 * cx, m0 * cy, m1 * cx, m1 * cy, w.sigma);
        }
        if (right_start < w.b1) {  // rays onto edge B -> C (next(h))
            const double m0 = hit(w.sx, w.sy, right_start, L, 0.0, cx, cy);
            const double m1 = hit(w.sx, w.sy, w.b1, L, 0.0, cx, cy);
            emit_child(next(h), L, 0.0, cx, cy, 0.0, 0.0, w.sx, w.sy, L + m0 * (cx - L), m0 * cy, L + m1 * (cx - L),
                       m1 * cy, w.sigma);
        }
    }
};

using Vertices = nb::ndarray<const double, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu>;
using Faces = nb::ndarray<const int32_t, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu>;
using Sources = nb::ndarray<const int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;

}  // namespace

NB_MODULE(_exact_geodesic, m) {
    m.doc() = "Exact polyhedral geodesic distances by window propagation (see src/exact_geodesic.cpp).";
    nb::class_<Surface>(m, "Surface")
        .def(
            "__init__",
            [](Surface* self, Vertices V, Faces F) { new (self) Surface(V.data(), V.shape(0), F.data(), F.shape(0)); },
            nb::arg("vertices"), nb::arg("faces"),
            "Precompute a mesh: vertices (N, 3) float64 and faces (M, 3) int32, both C-contiguous.")
        .def(
            "distances",
            [](const Surface& self, Sources sources, double tolerance, int64_t threads) {
                const size_t k = sources.shape(0), n = static_cast<size_t>(self.n_vertices());
                const int64_t* src = sources.data();
                for (size_t i = 0; i < k; ++i)
                    if (src[i] < 0 || src[i] >= self.n_vertices()) throw std::invalid_argument("source vertex out of range");
                if (!(tolerance >= 0.0 && tolerance < 1.0)) throw std::invalid_argument("tolerance must be in [0, 1)");
                double* out = new double[std::max<size_t>(k * n, 1)];
                nb::capsule owner(out, [](void* p) noexcept { delete[] static_cast<double*>(p); });
                {
                    nb::gil_scoped_release release;
                    std::atomic<size_t> next{0};
                    const int64_t team = std::max<int64_t>(1, std::min<int64_t>(threads, static_cast<int64_t>(k)));
                    run_parts(team, [&](int64_t) {  // each thread takes sources until none is left
                        Front front(self);
                        for (size_t i; (i = next++) < k;) front.distances(src[i], out + i * n, tolerance);
                    });
                }
                return nb::ndarray<nb::numpy, double, nb::ndim<2>>(out, {k, n}, owner);
            },
            nb::arg("sources"), nb::arg("tolerance") = 0.0, nb::arg("threads") = 1,
            "Distances (len(sources), N) float64 from each source vertex to every vertex; inf where unreached. "
            "tolerance > 0 prunes windows within that relative factor of a real path: faster, every value still a "
            "real path's length (src/exact_geodesic.cpp). threads: sources solved at once, each thread with its own "
            "wavefront (the result does not depend on it).");
}
