// The windows of exact window propagation (src/exact_geodesic.cpp) and what is computed on them: their
// storage in chunks, their distance functions and where two cross, where a ray meets an edge, and the
// queue of half-edges and vertices by distance.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

namespace windows {

struct Window {
    double b0, b1, sx, sy, sigma;
    int h;  // its half-edge
};
constexpr int CHUNK = 16;
// Windows wait on their half-edge in chunks, so that a sweep reads them from neighbouring memory (one
// window a slot, linked through a pool, cost a cache miss each: 40% of the time at 160k vertices;
// chunks of 5 / 10 / 16 / 32 windows: 7.9 / 7.0 / 6.7 / 6.8 s against 12 s, one source, 160k).
struct Chunk {
    Window w[CHUNK];
    int n;     // windows in it
    int next;  // the half-edge's next chunk, or the next free one (-1: none)
};
static_assert(std::is_trivially_copyable_v<Chunk>, "chunks live in a realloc'ed block");

// The chunks of one source, in one block that grows by realloc (for a large block the C library remaps
// the pages instead of copying them), with a list of free chunks: a half-edge that swept gives its
// chunks to the windows made next, so the block holds the largest wavefront. It is reused by the next
// source.
class ChunkStore {
public:
    ChunkStore() = default;
    ChunkStore(const ChunkStore&) = delete;
    ChunkStore& operator=(const ChunkStore&) = delete;
    ~ChunkStore() { std::free(data_); }
    void clear() { size_ = 0, free_ = -1; }
    Chunk& operator[](int i) { return data_[i]; }
    void release(int i) {
        data_[i].next = free_;
        free_ = i;
    }
    int take(int next) {  // an empty chunk before `next`; may move the store
        int i = free_;
        if (i >= 0) {
            free_ = data_[i].next;
        } else {
            if (size_ == capacity_) {
                const size_t grown = std::max<size_t>(256, 2 * capacity_);
                void* p = std::realloc(data_, grown * sizeof(Chunk));
                if (p == nullptr) throw std::bad_alloc();
                data_ = static_cast<Chunk*>(p);
                capacity_ = grown;
            }
            i = static_cast<int>(size_++);
        }
        data_[i].n = 0;
        data_[i].next = next;
        return i;
    }

private:
    Chunk* data_ = nullptr;
    size_t size_ = 0, capacity_ = 0;
    int free_ = -1;
};

inline double hypot2(double x, double y) { return std::sqrt(x * x + y * y); }
inline double at(const Window& w, double x) { return w.sigma + hypot2(x - w.sx, w.sy); }

// Where sigma_w + |S_w - x| = sigma_o + |S_o - x| on the x-axis: the real roots of the equation squared
// twice, which include every root of the equation itself (extra ones only split pieces more finely).
// Near a double root the squared equation gives only half the digits of the root, but there the two
// distances touch: misplacing the cut by delta changes them by O(delta^2), far below the margin, so no
// refinement is needed (Newton steps here cost a third of the solver's time on door.obj, and changed
// no distance by more than 5e-15).
inline int crossings(const Window& w, const Window& o, double* roots) {
    const double alpha = o.sigma - w.sigma;
    const double p = 2.0 * (o.sx - w.sx);
    const double q = w.sx * w.sx + w.sy * w.sy - o.sx * o.sx - o.sy * o.sy - alpha * alpha;
    const double a4 = 4.0 * alpha * alpha;
    const double A = p * p - a4, B = 2.0 * p * q + 2.0 * a4 * o.sx, C = q * q - a4 * (o.sx * o.sx + o.sy * o.sy);
    const double scale = std::max({std::fabs(A), std::fabs(B), std::fabs(C)});
    if (scale == 0.0) return 0;
    if (std::fabs(A) <= 1e-14 * scale) {
        if (B == 0.0) return 0;
        roots[0] = -C / B;
        return 1;
    }
    // A double root (equal sigmas) comes out with a slightly negative discriminant: keep it
    const double disc = std::max(B * B - 4.0 * A * C, 0.0);
    const double r = -0.5 * (B + std::copysign(std::sqrt(disc), B));  // no cancellation
    int n = 0;
    roots[n++] = r / A;
    if (r != 0.0) roots[n++] = C / r;
    return n;
}

// Events in buckets of distance `width`, first in first out within a bucket (the fast wavefront of
// Xu et al. 2015): any order is correct here, since every rule prunes against real paths and a vertex
// that improves lights its edges again; keeping the order only roughly sorted saves a heap's log factor.
// An id >= 0 is a half-edge, < 0 the vertex -id - 1.
class BucketQueue {
public:
    void reset(double width) {
        for (auto& b : buckets_) b.clear();
        width_ = width;
        current_ = pos_ = 0;
    }
    size_t bucket(double key) const { return std::max(current_, static_cast<size_t>(key / width_)); }
    double end() const { return (current_ + 1) * width_; }  // the current bucket's upper key
    void push_at(size_t b, int id) {
        if (b >= buckets_.size()) buckets_.resize(b + 1);
        buckets_[b].push_back(id);
    }
    void push(double key, int id) { push_at(bucket(key), id); }
    bool pop(int& id, size_t& b) {
        for (; current_ < buckets_.size(); ++current_, pos_ = 0) {
            std::vector<int>& v = buckets_[current_];
            if (pos_ < v.size()) {
                id = v[pos_++];
                b = current_;
                return true;
            }
            std::vector<int>().swap(v);  // a passed bucket's memory goes back
        }
        return false;
    }

private:
    std::vector<std::vector<int>> buckets_;
    double width_ = 1.0;
    size_t current_ = 0, pos_ = 0;
};

inline double cross(double ax, double ay, double bx, double by) { return ax * by - ay * bx; }

// Parameter mu of the point P + mu (Q - P) where the ray from S through (x, 0) meets line PQ, in [0, 1].
inline double hit(double sx, double sy, double x, double px, double py, double qx, double qy) {
    const double rx = x - sx, ry = -sy;
    const double mu = cross(rx, ry, sx - px, sy - py) / cross(rx, ry, qx - px, qy - py);
    return mu >= 0.0 ? (mu <= 1.0 ? mu : 1.0) : 0.0;  // NaN (ray along the edge) -> 0
}

}  // namespace windows
