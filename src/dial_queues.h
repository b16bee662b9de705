// The queues of virtual source propagation (src/virtual_source_geodesic.cpp): faces by their source's
// distance at their centroid.
#pragma once

#include <algorithm>
#include <cstddef>
#include <functional>
#include <queue>
#include <tuple>
#include <utility>
#include <vector>

namespace vsp {

// Dial's buckets of width `width`, first in first out within a bucket; keys below the current bucket
// go into it, keys beyond the last of `count` buckets into the last (a mesh of tiny edges and a few
// long ones must not allocate a bucket per tiny edge along its diameter; the order only costs time).
class Buckets {
public:
    void reset(double width, size_t count) {
        for (auto& b : buckets_) b.clear();
        width_ = width;
        last_ = count - 1;
        current_ = pos_ = 0;
    }
    void push(double key, int id) {
        const double slot = std::min(key / width_, static_cast<double>(last_));
        const size_t b = std::max(current_, static_cast<size_t>(slot));
        if (b >= buckets_.size()) buckets_.resize(b + 1);
        buckets_[b].emplace_back(key, id);
    }
    bool pop(double& key, int& id) {
        for (; current_ < buckets_.size(); ++current_, pos_ = 0) {
            auto& b = buckets_[current_];
            if (pos_ < b.size()) {
                std::tie(key, id) = b[pos_++];
                return true;
            }
            b.clear();
        }
        return false;
    }

private:
    std::vector<std::vector<std::pair<double, int>>> buckets_;
    double width_ = 1.0;
    size_t last_ = 0, current_ = 0, pos_ = 0;
};

class Heap {
public:
    void reset(double, size_t) { heap_ = {}; }
    void push(double key, int id) { heap_.emplace(key, id); }
    bool pop(double& key, int& id) {
        if (heap_.empty()) return false;
        std::tie(key, id) = heap_.top();
        heap_.pop();
        return true;
    }

private:
    std::priority_queue<std::pair<double, int>, std::vector<std::pair<double, int>>, std::greater<>> heap_;
};

}  // namespace vsp
