// Each vertex's corners 3 f + k (face f's corner k at the vertex), in increasing order, as compressed rows:
// corners[start[v] .. start[v + 1]) for vertex v. The geodesic solvers' fans and sources start from them.
#pragma once

#include <cstdint>
#include <vector>

inline void vertex_corners(const std::vector<int>& F, int64_t n, std::vector<int>& start, std::vector<int>& corners) {
    const int m3 = static_cast<int>(F.size());
    start.assign(n + 1, 0);
    for (int h = 0; h < m3; ++h) ++start[F[h] + 1];
    for (int64_t v = 0; v < n; ++v) start[v + 1] += start[v];
    corners.resize(m3);
    std::vector<int> fill(start.begin(), start.end() - 1);
    for (int h = 0; h < m3; ++h) corners[fill[F[h]]++] = h;
}
