// An array whose elements are left uninitialised when it is made: the pages are first
// touched by whoever fills them (the threads of a parallel loop), and the part never
// written is never touched at all. For plain data (trivially copyable types) only.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <new>
#include <type_traits>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace splat {

// Asks for the cache line at p ahead of a read at a random place (no effect where the
// compiler has no such hint).
inline void prefetch(const void *p) {
#if defined(__GNUC__) || defined(__clang__)
    __builtin_prefetch(p);
#else
    (void)p;
#endif
}

// Items a random-order gather asks for ahead of the one it reads: somewhat more than the
// cache misses a core keeps in flight (10 to 12 line-fill buffers on x86-64), so that none
// idles.
constexpr size_t kPrefetchAhead = 16;

namespace buffer_detail {

#if defined(__linux__)
// Blocks of their own pages on request (Buffer's own_pages), from mmap and back to the system
// with munmap: glibc serves a block below its mmap threshold (which rises up to 32 MiB once
// a large block is freed) from the arena of the thread that asks, and what a worker
// thread's arena gets back stays resident (malloc_trim does not trim those arenas): the BVH
// builder's per-thread node arrays stayed in the process after the build, 5-13 bytes a
// splat at 1-2M splats. Not for every buffer: the main thread's freed heap memory is what
// glibc reuses for its large blocks, and a build's peak grew by half at 1M splats when
// they all came from fresh pages.
constexpr size_t kMapped = size_t(64) << 10;  // from this size on (smaller: malloc)
// In front of the data: the mapping's length (0 for a malloc'd block); 64 bytes keep the
// data as aligned as malloc's and on a cache line boundary in a mapping.
constexpr size_t kHeader = 64;

inline void *allocate(size_t bytes, bool own_pages) {
    char *base;
    if (own_pages && bytes >= kMapped) {
        void *m = mmap(nullptr, bytes + kHeader, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
        if (m == MAP_FAILED) return nullptr;
        base = static_cast<char *>(m);
        *reinterpret_cast<size_t *>(base) = bytes + kHeader;
    } else {
        base = static_cast<char *>(std::malloc(bytes + kHeader));
        if (!base) return nullptr;
        *reinterpret_cast<size_t *>(base) = 0;
    }
    return base + kHeader;
}

inline void release(void *p) {
    if (!p) return;
    char *base = static_cast<char *>(p) - kHeader;
    const size_t mapped = *reinterpret_cast<size_t *>(base);
    if (mapped) munmap(base, mapped);
    else std::free(base);
}

// Asks for transparent huge pages over the 2 MiB pages inside [p, p + bytes): many
// distributions grant them only on request ("madvise"), and a buffer filled once all over
// then takes one page fault per 2 MiB instead of 512. Writing 80 MB of fresh memory: 35 ms
// in 4 KiB pages against 9 ms in huge ones (numpy asks the same for its large arrays). A
// refusal (no THP in the kernel, or "never") only costs that time.
inline void advise_huge_pages(void *p, size_t bytes) {
#ifdef MADV_HUGEPAGE
    constexpr uintptr_t kHuge = uintptr_t(2) << 20;
    const uintptr_t begin = (uintptr_t(p) + kHuge - 1) & ~(kHuge - 1);
    const uintptr_t end = (uintptr_t(p) + bytes) & ~(kHuge - 1);
    if (end > begin) madvise(reinterpret_cast<void *>(begin), end - begin, MADV_HUGEPAGE);
#else
    (void)p, (void)bytes;
#endif
}
#else
// Windows' and macOS' allocators give large blocks their own pages and return them on free.
inline void *allocate(size_t bytes, bool) { return std::malloc(bytes); }
inline void release(void *p) { std::free(p); }
inline void advise_huge_pages(void *, size_t) {}
#endif

}  // namespace buffer_detail

template <class T>
class Buffer {
    static_assert(std::is_trivially_copyable<T>::value, "Buffer holds plain data");
    struct Free {
        void operator()(T *p) const { buffer_detail::release(p); }
    };
    std::unique_ptr<T, Free> data_;
    size_t size_ = 0;

  public:
    Buffer() = default;
    // own_pages: memory that a worker thread allocates and that is freed soon after (see
    // buffer_detail above).
    explicit Buffer(size_t n, bool own_pages = false) { allocate(n, own_pages); }
    void allocate(size_t n, bool own_pages = false) {
        data_.reset(n ? static_cast<T *>(buffer_detail::allocate(n * sizeof(T), own_pages)) : nullptr);
        if (n && !data_) throw std::bad_alloc();
        size_ = n;
    }
    void release() { data_.reset(), size_ = 0; }
    // For a large buffer about to be written all over: see buffer_detail::advise_huge_pages.
    void prefer_huge_pages() { buffer_detail::advise_huge_pages(data(), bytes()); }
    // Takes over the memory of another buffer of a type of the same size (its elements are
    // then whatever this type's were written there): storage reused instead of a fresh
    // allocation whose pages would all be faulted in again.
    template <class U>
    void adopt(Buffer<U> &other) {
        static_assert(sizeof(U) == sizeof(T), "same element size");
        data_.reset(reinterpret_cast<T *>(other.take())), size_ = other.size(), other.release();
    }
    void *take() { return data_.release(); }
    size_t size() const { return size_; }
    bool empty() const { return size_ == 0; }
    size_t bytes() const { return size_ * sizeof(T); }
    T *data() { return data_.get(); }
    const T *data() const { return data_.get(); }
    T &operator[](size_t i) { return data_.get()[i]; }
    const T &operator[](size_t i) const { return data_.get()[i]; }
    T *begin() { return data(); }
    T *end() { return data() + size_; }
    const T *begin() const { return data(); }
    const T *end() const { return data() + size_; }
};

}  // namespace splat
