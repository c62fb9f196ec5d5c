// Work distribution: tasks pulled from an atomic counter by worker threads, while the
// calling thread polls (progress reports, cancellation) until they are done.
#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <exception>
#include <mutex>
#include <system_error>
#include <thread>
#include <utility>
#include <vector>

namespace splat {

// Test seam: how many more threads the core may start before thread creation fails as if
// the system had refused it (-1: no limit). The tests use it to prove that a refused
// thread degrades to fewer threads instead of aborting the process.
inline std::atomic<int> &thread_budget() {
    static std::atomic<int> budget{-1};
    return budget;
}

// std::thread(f), or std::system_error when the system (or the test seam) refuses one.
template <class F>
std::thread start_thread(F &&f) {
    for (int b = thread_budget().load(); b >= 0;) {
        if (b == 0) throw std::system_error(std::make_error_code(std::errc::resource_unavailable_try_again));
        if (thread_budget().compare_exchange_weak(b, b - 1)) break;
    }
    return std::thread(std::forward<F>(f));
}

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
    int running = 0;  // workers started and not yet finished (guarded by mutex)

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

    // Workers the system refuses are simply not there: the others take their tasks. An
    // exception escaping here with threads running would abort the process (their
    // std::thread destructors call std::terminate).
    std::vector<std::thread> pool;
    pool.reserve(n_workers);
    for (int w = 0; w < n_workers; ++w) {
        {
            std::lock_guard<std::mutex> lock(mutex);
            ++running;
        }
        try {
            pool.push_back(start_thread(worker));
        } catch (const std::system_error &) {
            std::lock_guard<std::mutex> lock(mutex);
            --running;
            break;
        }
    }
    if (pool.empty()) {
        // Not a single thread: run the tasks here, polling between them.
        auto last = std::chrono::steady_clock::now();
        for (size_t i = 0; i < count && !cancel; ++i) {
            task(i);  // an exception propagates: nothing is running
            done.fetch_add(1);
            const auto now = std::chrono::steady_clock::now();
            if (now - last >= std::chrono::milliseconds(poll_ms)) {
                last = now;
                if (!poll(done.load())) cancel = true;
            }
        }
        return !cancel;
    }
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
