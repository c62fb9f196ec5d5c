// Work distribution: tasks pulled from an atomic counter by worker threads, while the
// calling thread polls (progress reports, cancellation) until they are done.
#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace splat {

inline int resolve_threads(int requested) {
    if (requested > 0) return requested;
    return std::max(1u, std::thread::hardware_concurrency());
}

// Runs task(i) for every i in [0, count) on `threads` workers (0: all cores). The calling
// thread meanwhile calls poll(done) about every `poll_ms`; when poll returns false the
// remaining tasks are skipped. Returns false when cancelled. An exception thrown by a
// task cancels the rest and is rethrown here once every worker has stopped.
template <class Task, class Poll>
bool parallel_for(size_t count, int threads, Task &&task, Poll &&poll, int poll_ms = 50) {
    const int n_workers = int(std::min<size_t>(size_t(resolve_threads(threads)), std::max<size_t>(count, 1)));
    std::atomic<size_t> next{0}, done{0};
    std::atomic<bool> cancel{false};
    std::exception_ptr error;
    std::mutex mutex;
    std::condition_variable finished;
    int running = n_workers;

    auto worker = [&] {
        for (;;) {
            if (cancel.load(std::memory_order_relaxed)) break;
            const size_t i = next.fetch_add(1);
            if (i >= count) break;
            try {
                task(i);
            } catch (...) {
                std::lock_guard<std::mutex> lock(mutex);
                if (!error) error = std::current_exception();
                cancel = true;
            }
            done.fetch_add(1);
        }
        std::lock_guard<std::mutex> lock(mutex);
        --running;
        finished.notify_all();
    };

    std::vector<std::thread> pool;
    pool.reserve(n_workers);
    for (int w = 0; w < n_workers; ++w) pool.emplace_back(worker);
    {
        std::unique_lock<std::mutex> lock(mutex);
        while (running > 0) {
            finished.wait_for(lock, std::chrono::milliseconds(poll_ms));
            if (running == 0) break;
            lock.unlock();
            const bool go_on = cancel ? true : poll(done.load());
            lock.lock();
            if (!go_on) cancel = true;
        }
    }
    for (auto &t : pool) t.join();
    if (error) std::rethrow_exception(error);
    return !cancel;
}

}  // namespace splat
