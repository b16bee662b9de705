// A triangle mesh laid out for virtual source propagation (src/virtual_source_geodesic.cpp): faces in
// Morton order and vertices in the order the faces first use them, each face in its own plane frame, each
// half-edge's unfolding into the face across it, each vertex's corners, and the tables of the relaxations
// (a glued soup's edges, each corner's opposite edge). Built once a mesh; read by every source's
// propagation.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "vertex_corners.h"

namespace vsp {

constexpr double INF = std::numeric_limits<double>::infinity();

struct Point {
    double x, y;
};
inline double norm(double x, double y) { return std::sqrt(x * x + y * y); }
inline double cross(Point o, Point a, Point b) { return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x); }

// The faces (M, 3) sorted by the Morton code of their centroids (21 bits an axis over the bounding box).
inline std::vector<int> morton_order(const double* V, int64_t n, const int64_t* F, int64_t m) {
    double lo[3] = {INF, INF, INF}, hi[3] = {-INF, -INF, -INF};
    for (int64_t i = 0; i < n; ++i)
        for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], V[3 * i + k]), hi[k] = std::max(hi[k], V[3 * i + k]);
    auto spread = [](uint64_t x) {  // the 21 bits of x to every third bit
        x &= 0x1fffff;
        x = (x | x << 32) & 0x1f00000000ffffULL;
        x = (x | x << 16) & 0x1f0000ff0000ffULL;
        x = (x | x << 8) & 0x100f00f00f00f00fULL;
        x = (x | x << 4) & 0x10c30c30c30c30c3ULL;
        return (x | x << 2) & 0x1249249249249249ULL;
    };
    std::vector<std::pair<uint64_t, int>> keys(m);
    for (int64_t f = 0; f < m; ++f) {
        uint64_t code = 0;
        for (int k = 0; k < 3; ++k) {
            const double c = (V[3 * F[3 * f] + k] + V[3 * F[3 * f + 1] + k] + V[3 * F[3 * f + 2] + k]) / 3.0;
            const double unit = hi[k] > lo[k] ? (c - lo[k]) / (hi[k] - lo[k]) : 0.0;
            code |= spread(static_cast<uint64_t>(unit * 2097151.0)) << k;
        }
        keys[f] = {code, static_cast<int>(f)};
    }
    std::sort(keys.begin(), keys.end());
    std::vector<int> order(m);
    for (int64_t f = 0; f < m; ++f) order[f] = keys[f].second;
    return order;
}

// Half-edge h = 3 f + k (face f's edge from corner k to corner k + 1) and the face g across it, seen in
// the frame of that edge in g: its start A at the origin, its end B at (L, 0), g's third vertex C at
// (cx, cy), cy >= 0. One cache line.
struct alignas(64) Across {
    double ex, ey, tx, ty;  // f's frame -> the edge's frame in g: (s (ex x + ey y) + tx, ey x - ex y + ty)
    double L, cx, cy;
    int packed = -1;        // g << 3 | (g's corner at A) << 1 | (f and g oriented alike, s = 1); -1: none
    int vc;                 // the vertex at C
    int g() const { return packed >> 3; }
    int kg() const { return (packed >> 1) & 3; }
    bool reflects() const { return packed & 1; }
    Point map(Point p) const {
        const double along = ex * p.x + ey * p.y;
        return {(reflects() ? along : -along) + tx, ey * p.x - ex * p.y + ty};
    }
};
static_assert(sizeof(Across) == 64, "one cache line");

// A mesh's tables: refused where an edge has three or more faces or a vertex's faces form two or more
// fans (unless twins are given).
class UnfoldedSurface {
public:
    // twins (3 M, optional): the half-edge glued to each half-edge 3 f + k (-1: none), for surfaces whose
    // edges are not told by their two vertices (a point cloud's triangle soup, glued in pairs around each
    // edge or as its tufted cover); each field then ends relaxed along the edges (relax_along_edges).
    // excess (N, optional): each vertex's angle excess where the faces' corners do not give it (a cloud's
    // local triangulations overlap; a cover counts each corner twice).
    UnfoldedSurface(const double* V, int64_t n, const int64_t* F, int64_t m, const int64_t* twins = nullptr,
                    const double* excess = nullptr)
        : n_(n), m_(m) {
        if (n >= (int64_t(1) << 31) || m >= (int64_t(1) << 28))  // a face's index is packed in 29 bits
            throw std::invalid_argument("more than 2^31 vertices or 2^28 faces");
        for (int64_t i = 0; i < 3 * n; ++i)
            if (!std::isfinite(V[i])) throw std::invalid_argument("a vertex coordinate is not finite");
        for (int64_t i = 0; i < 3 * m; ++i)
            if (F[i] < 0 || F[i] >= n) throw std::invalid_argument("face index out of range");
        // Faces in the order of their centroids along a Morton curve, vertices in the order the faces
        // first use them: neighbours sit close in memory, whatever the caller's order (84k vertices: 73 ms
        // a field in trimesh's order of a subdivided mesh, 125 ms shuffled, 47 ms either way sorted)
        const std::vector<int> faces = morton_order(V, n, F, m);
        std::vector<int> face_of_old(m);
        for (int64_t i = 0; i < m; ++i) face_of_old[faces[i]] = static_cast<int>(i);
        new_of_old_.assign(n, -1);
        old_of_new_.reserve(n);
        F_.resize(3 * m);
        for (int64_t i = 0; i < m; ++i)
            for (int k = 0; k < 3; ++k) {
                const int64_t v = F[3 * faces[i] + k];
                if (new_of_old_[v] < 0) new_of_old_[v] = static_cast<int>(old_of_new_.size()), old_of_new_.push_back(v);
                F_[3 * i + k] = new_of_old_[v];
            }
        for (int64_t v = 0; v < n; ++v)
            if (new_of_old_[v] < 0) new_of_old_[v] = static_cast<int>(old_of_new_.size()), old_of_new_.push_back(v);
        std::vector<double> positions(3 * n);
        for (int64_t i = 0; i < n; ++i)
            for (int k = 0; k < 3; ++k) positions[3 * i + k] = V[3 * old_of_new_[i] + k];
        build_frames(positions.data());
        position_ = std::move(positions);
        if (excess)
            for (int64_t i = 0; i < n; ++i) excess_[i] = excess[old_of_new_[i]];
        if (twins) {
            std::vector<int> glued(3 * m);
            for (int64_t h = 0; h < 3 * m; ++h) {
                const int64_t o = twins[h];
                if (o < -1 || o >= 3 * m || o == h || (o >= 0 && twins[o] != h))
                    throw std::invalid_argument("twins: each half-edge glued to one other that is glued back");
                glued[3 * face_of_old[h / 3] + h % 3] = o < 0 ? -1 : 3 * face_of_old[o / 3] + static_cast<int>(o % 3);
            }
            across_.assign(3 * m_, Across{});
            for (int h = 0; h < 3 * m_; ++h) {
                const int o = glued[h];
                if (o < 0) continue;
                const int a = F_[h], b = F_[h % 3 == 2 ? h - 2 : h + 1];
                const int c = F_[o], e = F_[o % 3 == 2 ? o - 2 : o + 1];
                if (std::min(a, b) != std::min(c, e) || std::max(a, b) != std::max(c, e))
                    throw std::invalid_argument("twins: a half-edge glued to one of two other vertices");
                link(h, o);
            }
        } else {
            build_unfoldings();
        }
        vertex_corners(F_, n_, vf_start_, vf_);
        if (twins) {  // a soup's vertices may join several fans: paths bend there (d of the vertex)
            build_edges();
            return;
        }
        if (const int64_t pinched = count_pinched())
            throw std::invalid_argument(std::to_string(pinched) +
                                        " non-manifold vertices (their faces form two or more fans)");
        build_opposites();
    }

    int64_t n_vertices() const { return n_; }

protected:
    int64_t n_, m_;
    std::vector<int> F_;                      // in the solver's own numbering
    std::vector<double> excess_;              // per vertex: its corner angles' sum less 2 pi
    std::vector<double> position_;            // per vertex: x, y, z (no path from the source is shorter)
    std::vector<int> new_of_old_;             // per vertex of the caller: its number here
    std::vector<int64_t> old_of_new_;
    std::vector<double> frame_;        // per face: corner 1's x, corner 2's x and y (corner 0 at the origin)
    std::vector<Across> across_;       // per half-edge
    std::vector<int> vf_start_, vf_;   // per vertex: its faces' corners 3 f + k (CSR)
    std::vector<int> edge_start_, edge_to_;  // a glued soup's: per vertex its neighbours along edges (CSR)
    std::vector<double> edge_length_;

    double mean_edge_ = 1.0;

    // Each face's corner k seen from the edge opposite it, from corner k + 1 (the origin) to k + 2 (at
    // (L, 0)): the corner at (cx, cy), cy > 0 (0: a degenerate face, never relaxed).
    struct Opposite {
        double L, half_inv_L, cx, cy;
    };
    std::vector<Opposite> opposite_;  // per corner 3 f + k (manifold meshes only)

    void build_opposites() {
        opposite_.assign(3 * m_, Opposite{0.0, 0.0, 0.0, 0.0});
        for (int64_t f = 0; f < m_; ++f)
            for (int k = 0; k < 3; ++k) {
                const Point pa = corner(f, (k + 1) % 3), pb = corner(f, (k + 2) % 3), pc = corner(f, k);
                const double L = norm(pb.x - pa.x, pb.y - pa.y);
                if (!(L > 0.0)) continue;
                const double ux = (pb.x - pa.x) / L, uy = (pb.y - pa.y) / L;  // c is left of a -> b
                opposite_[3 * f + k] = {L, 0.5 / L, (pc.x - pa.x) * ux + (pc.y - pa.y) * uy,
                                        ux * (pc.y - pa.y) - uy * (pc.x - pa.x)};
            }
    }
    Point corner(int f, int k) const {
        const double* q = &frame_[3 * f];
        return k == 0 ? Point{0.0, 0.0} : (k == 1 ? Point{q[0], 0.0} : Point{q[1], q[2]});
    }
    Point centroid(int f) const {
        const double* q = &frame_[3 * f];
        return {(q[0] + q[1]) / 3.0, q[2] / 3.0};
    }

    // A glued soup's edges: each vertex's neighbours and the lengths to them (a half-edge's own length in its
    // face's frame: the faces of an edge agree on it to rounding; the last face's is kept).
    void build_edges() {
        struct Edge {
            int from, to;
            double length;
        };
        std::vector<Edge> edges;
        edges.reserve(6 * m_);
        for (int h = 3 * m_ - 1; h >= 0; --h) {  // the last face first: it stays first among equal edges
            const int f = h / 3, k = h % 3, a = F_[h], b = F_[k == 2 ? h - 2 : h + 1];
            const Point p = corner(f, k), q = corner(f, (k + 1) % 3);
            const double l = norm(q.x - p.x, q.y - p.y);
            edges.push_back({a, b, l}), edges.push_back({b, a, l});
        }
        auto key = [](const Edge& e) { return std::pair{e.from, e.to}; };
        std::stable_sort(edges.begin(), edges.end(), [&](const Edge& x, const Edge& y) { return key(x) < key(y); });
        edges.erase(std::unique(edges.begin(), edges.end(), [&](const Edge& x, const Edge& y) { return key(x) == key(y); }),
                    edges.end());
        edge_start_.assign(n_ + 1, 0);
        edge_to_.resize(edges.size());
        edge_length_.resize(edges.size());
        for (size_t i = 0; i < edges.size(); ++i) {
            ++edge_start_[edges[i].from + 1];
            edge_to_[i] = edges[i].to, edge_length_[i] = edges[i].length;
        }
        for (int64_t v = 0; v < n_; ++v) edge_start_[v + 1] += edge_start_[v];
    }

    void build_frames(const double* V) {
        frame_.resize(3 * m_);
        std::vector<double> angle_sum(n_, 0.0);
        double total = 0.0;
        for (int64_t f = 0; f < m_; ++f) {
            const double* p0 = &V[3 * F_[3 * f]];
            const double* p1 = &V[3 * F_[3 * f + 1]];
            const double* p2 = &V[3 * F_[3 * f + 2]];
            double e[3], g[3];
            for (int i = 0; i < 3; ++i) e[i] = p1[i] - p0[i], g[i] = p2[i] - p0[i];
            const double l01 = std::sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
            const double l02 = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
            const double dot = e[0] * g[0] + e[1] * g[1] + e[2] * g[2];
            const double n0 = e[1] * g[2] - e[2] * g[1], n1 = e[2] * g[0] - e[0] * g[2], n2 = e[0] * g[1] - e[1] * g[0];
            const double area2 = std::sqrt(n0 * n0 + n1 * n1 + n2 * n2);
            double* q = &frame_[3 * f];
            if (l01 > 0.0)
                q[0] = l01, q[1] = dot / l01, q[2] = area2 / l01;
            else
                q[0] = 0.0, q[1] = l02, q[2] = 0.0;
            total += l01;
            const double angle[3] = {std::atan2(q[2], q[1]), std::atan2(q[2], q[0] - q[1]), 0.0};
            angle_sum[F_[3 * f]] += angle[0], angle_sum[F_[3 * f + 1]] += angle[1];
            angle_sum[F_[3 * f + 2]] += M_PI - angle[0] - angle[1];
        }
        excess_.resize(n_);
        for (int64_t v = 0; v < n_; ++v) excess_[v] = angle_sum[v] - 2.0 * M_PI;
        mean_edge_ = m_ > 0 && total > 0.0 ? total / m_ : 1.0;
        excess_of_coincident(V);
    }

    // Vertices at one place (joined by edges of zero length: a point split onto its own endpoint, a face
    // collapsed in a scan) are one point of the surface, and their corner angles in the faces that join them
    // are arbitrary (the direction of a zero-length edge is none): each gets the excess of the point, the
    // sum of their angle sums less pi for each face with a zero-length edge (its angles at the point; the
    // third corner's is 0) less 2 pi. Without it, a plane with one such split had two false gates (a field
    // 0.8-1.4% off where the plane's is exact).
    void excess_of_coincident(const double* V) {
        std::vector<int> root(n_);
        for (int64_t v = 0; v < n_; ++v) root[v] = static_cast<int>(v);
        auto find = [&](int v) {
            while (root[v] != v) v = root[v] = root[root[v]];
            return v;
        };
        std::vector<int> collapsed(m_, -1);  // per face: a vertex of its zero-length edge (-1: none)
        bool any = false;
        for (int64_t f = 0; f < m_; ++f)
            for (int k = 0; k < 3; ++k) {
                const int a = F_[3 * f + k], b = F_[3 * f + (k + 1) % 3];
                const double* p = &V[3 * a];
                const double* q = &V[3 * b];
                if (a == b || p[0] != q[0] || p[1] != q[1] || p[2] != q[2]) continue;
                collapsed[f] = a, any = true;
                const int ra = find(a), rb = find(b);
                if (ra != rb) root[std::max(ra, rb)] = std::min(ra, rb);
            }
        if (!any) return;
        std::vector<double> sum(n_, 0.0);
        std::vector<int> members(n_, 0);
        for (int64_t v = 0; v < n_; ++v) {
            const int r = find(static_cast<int>(v));
            sum[r] += excess_[v] + 2.0 * M_PI, ++members[r];
        }
        for (int64_t f = 0; f < m_; ++f)
            if (collapsed[f] >= 0) sum[find(collapsed[f])] -= M_PI;
        for (int64_t v = 0; v < n_; ++v) {
            const int r = find(static_cast<int>(v));
            if (members[r] > 1) excess_[v] = sum[r] - 2.0 * M_PI;
        }
    }

    void build_unfoldings() {
        std::vector<std::pair<std::pair<int, int>, int>> keys(3 * m_);
        for (int h = 0; h < 3 * m_; ++h) {
            const int a = F_[h], b = F_[h % 3 == 2 ? h - 2 : h + 1];
            keys[h] = {{std::min(a, b), std::max(a, b)}, h};
        }
        std::sort(keys.begin(), keys.end());
        across_.assign(3 * m_, Across{});
        int64_t non_manifold = 0;
        for (size_t i = 0; i < keys.size();) {
            size_t j = i;
            while (j < keys.size() && keys[j].first == keys[i].first) ++j;
            if (j - i > 2) ++non_manifold;
            if (j - i == 2 && keys[i].first.first != keys[i].first.second) {
                link(keys[i].second, keys[i + 1].second);
                link(keys[i + 1].second, keys[i].second);
            }
            i = j;
        }
        if (non_manifold > 0)
            throw std::invalid_argument(std::to_string(non_manifold) + " non-manifold edges (three or more faces)");
    }

    // The unfolding of half-edge h's face into the frame of the same edge in the face of half-edge o, its
    // twin (or its equal, where the two faces are oriented against each other).
    void link(int h, int o) {
        const int f = h / 3, k = h % 3, g = o / 3, kg = o % 3;
        Across& u = across_[h];
        const Point pa = corner(f, k), pb = corner(f, (k + 1) % 3);
        const Point qa = corner(g, kg), qb = corner(g, (kg + 1) % 3), qc = corner(g, (kg + 2) % 3);
        const double lp = norm(pb.x - pa.x, pb.y - pa.y), L = norm(qb.x - qa.x, qb.y - qa.y);
        if (!(lp > 0.0) || !(L > 0.0)) return;  // a degenerate edge hands nothing on
        // g's edge frame: x along qa -> qb, y toward g's third corner (the face's corners run
        // counter-clockwise in its frame); f's third corner goes to y < 0
        const double gx = (qb.x - qa.x) / L, gy = (qb.y - qa.y) / L;
        u.L = L;
        u.cx = (qc.x - qa.x) * gx + (qc.y - qa.y) * gy;
        u.cy = std::max(0.0, -(qc.x - qa.x) * gy + (qc.y - qa.y) * gx);
        // f's edge: unit e along pa -> pb, n = (-ey, ex) toward f's third corner (left of the edge)
        const double ex = (pb.x - pa.x) / lp, ey = (pb.y - pa.y) / lp;
        // the shared edge's start in f (vertex F[h]) is g's qa (opposite orientations: the usual case)
        // or g's qb (equal orientations); in g's edge frame x runs from qa
        const bool same = F_[h] == F_[o];
        const double sx = same ? 1.0 : -1.0, ox = same ? 0.0 : L;
        // X -> (ox + sx (X - pa).e, -(X - pa).n)
        u.ex = ex, u.ey = ey;
        u.tx = ox - sx * (ex * pa.x + ey * pa.y);
        u.ty = -(ey * pa.x - ex * pa.y);
        u.packed = g << 3 | kg << 1 | (same ? 1 : 0);
        u.vc = F_[3 * g + (kg + 2) % 3];
    }

    // Vertices whose faces fall into two or more fans joined by no edge through the vertex: a source's
    // paths would have to pass through the vertex itself, which no face hands on. A vertex's corners are
    // listed in order (vertex_corners), so the corner of the face across an edge is found by bisection:
    // n log n in the valence (a search through the list made a 40k-face fan take seconds).
    int64_t count_pinched() const {
        int64_t pinched = 0;
        std::vector<int> stack;
        std::vector<char> seen;
        for (int64_t v = 0; v < n_; ++v) {
            const int* first = vf_.data() + vf_start_[v];
            const int* last = vf_.data() + vf_start_[v + 1];
            if (first == last) continue;  // in no face
            seen.assign(last - first, 0);
            seen[0] = 1;
            stack.assign(1, 0);
            size_t reached = 1;
            while (!stack.empty()) {  // the fan of the first face, across the edges through v
                const int h = first[stack.back()];
                stack.pop_back();
                const int f = h / 3, j = h % 3;
                for (const int e : {3 * f + j, 3 * f + (j + 2) % 3}) {
                    if (across_[e].packed < 0) continue;
                    const int g = across_[e].g();
                    const int k = F_[3 * g] == v ? 0 : (F_[3 * g + 1] == v ? 1 : 2);
                    const size_t i = std::lower_bound(first, last, 3 * g + k) - first;
                    if (!seen[i]) seen[i] = 1, ++reached, stack.push_back(static_cast<int>(i));
                }
            }
            if (reached < seen.size()) ++pinched;
        }
        return pinched;
    }
};

}  // namespace vsp
