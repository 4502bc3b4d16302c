#pragma once
// An allocator for std::vector whose value-less construction default-initializes: a vector of
// plain data resized or sized by count is left unwritten, for a caller that writes every element
// anyway (in parallel, where the first touch of fresh pages is spread over the threads).
//
// Why: std::vector<T>(n) zeroes its n elements on one thread before the caller writes them. For
// the point converter's large arrays (1.6 GB of partition items, 2.4 GB of positions at 100M
// points) that zeroing, and the page faults it takes on one thread, held the other core idle for
// seconds.
#include <memory>
#include <new>
#include <utility>
#include <vector>

namespace catpaq {

template <class T>
struct DefaultInitAllocator : std::allocator<T> {
    using value_type = T;
    template <class U>
    struct rebind {
        using other = DefaultInitAllocator<U>;
    };
    DefaultInitAllocator() noexcept = default;
    template <class U>
    DefaultInitAllocator(const DefaultInitAllocator<U>&) noexcept {}

    template <class U>
    void construct(U* p) noexcept(noexcept(::new (static_cast<void*>(p)) U)) {
        ::new (static_cast<void*>(p)) U;
    }
    template <class U, class... Args>
    void construct(U* p, Args&&... args) {
        ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
    }
};

template <class T, class U>
bool operator==(const DefaultInitAllocator<T>&, const DefaultInitAllocator<U>&) noexcept {
    return true;
}

// A vector of plain data that `resize` and `(n)` leave unwritten.
template <class T>
using UninitializedVector = std::vector<T, DefaultInitAllocator<T>>;

}  // namespace catpaq
