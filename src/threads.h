// Work split over std::threads that never aborts: a thread that cannot be started (a cgroup's pids.max, no
// memory for its stack: std::system_error, or no memory for the pool: std::bad_alloc) leaves its part to the
// calling thread, where an exception escaping std::thread's constructor would otherwise destroy the started
// ones unjoined (std::terminate); and an exception of a part (std::bad_alloc where a limit is reached) is
// kept, every thread joined, then rethrown on the calling thread, where the bindings turn it into Python's
// (MemoryError), instead of leaving its thread (std::terminate: the process killed).
#pragma once

#include <cstdint>
#include <exception>
#include <mutex>
#include <new>
#include <system_error>
#include <thread>
#include <vector>

// part(t) for t = 0..parts-1: part 0 and any part whose thread could not be started on the calling thread.
// The first exception a part throws is rethrown once all have ended.
template <class Part>
void run_parts(int64_t parts, Part part) {
    std::exception_ptr failed;
    std::mutex lock;
    auto guarded = [&](int64_t t) {
        try {
            part(t);
        } catch (...) {
            const std::lock_guard<std::mutex> hold(lock);
            if (!failed) failed = std::current_exception();
        }
    };
    std::vector<std::thread> pool;
    int64_t t = 1;
    try {
        for (; t < parts; ++t) pool.emplace_back(guarded, t);
    } catch (const std::system_error&) {
    } catch (const std::bad_alloc&) {
    }
    guarded(0);
    for (; t < parts; ++t) guarded(t);
    for (auto& th : pool) th.join();
    if (failed) std::rethrow_exception(failed);
}
