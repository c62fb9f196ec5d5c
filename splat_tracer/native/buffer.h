// An array whose elements are left uninitialised when it is made: the pages are first
// touched by whoever fills them (the threads of a parallel loop), and the part never
// written is never touched at all. For plain data (trivially copyable types) only.
#pragma once

#include <cstddef>
#include <cstdlib>
#include <memory>
#include <new>
#include <type_traits>

namespace splat {

template <class T>
class Buffer {
    static_assert(std::is_trivially_copyable<T>::value, "Buffer holds plain data");
    struct Free {
        void operator()(T *p) const { std::free(p); }
    };
    std::unique_ptr<T, Free> data_;
    size_t size_ = 0;

  public:
    Buffer() = default;
    explicit Buffer(size_t n) { allocate(n); }
    void allocate(size_t n) {
        data_.reset(n ? static_cast<T *>(std::malloc(n * sizeof(T))) : nullptr);
        if (n && !data_) throw std::bad_alloc();
        size_ = n;
    }
    void release() { data_.reset(), size_ = 0; }
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
