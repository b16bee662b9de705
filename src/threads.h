// Work split over std::threads that never aborts for want of a thread: a thread that cannot be started (a
// cgroup's pids.max, no memory for its stack: std::system_error) leaves its part to the calling thread, where
// an exception escaping std::thread's constructor would otherwise destroy the started ones unjoined
// (std::terminate).
#pragma once

#include <cstdint>
#include <system_error>
#include <thread>
#include <vector>

// part(t) for t = 0..parts-1: part 0 and any part whose thread could not be started on the calling thread.
template <class Part>
void run_parts(int64_t parts, Part part) {
    std::vector<std::thread> pool;
    int64_t t = 1;
    try {
        for (; t < parts; ++t) pool.emplace_back(part, t);
    } catch (const std::system_error&) {
    }
    part(int64_t{0});
    for (; t < parts; ++t) part(t);
    for (auto& th : pool) th.join();
}
