#pragma once
// Private to the points module: a max-heap (by `Less`, as std::priority_queue) whose elements
// move exactly as libstdc++'s push_heap and pop_heap move them, so that elements the order
// holds equal pop in the same order as there (the converter's output depends on it). The one
// difference: the larger child is chosen without a branch. The standard heap's half-and-half
// branch mispredicts on every level of every pop (the normal orientation's heap was 5% of the
// conversion's time, the simplifier's 3%).
#include <cstddef>
#include <vector>

namespace catpaq::points_detail {

template <class T, class Less>
class StdOrderHeap {
public:
    bool empty() const { return heap_.empty(); }
    void clear() { heap_.clear(); }
    const T& top() const { return heap_.front(); }

    // push_heap: the new element rises while its parent is less.
    void push(const T& value) {
        heap_.push_back(value);
        rise(heap_.size() - 1, 0, value);
    }

    // pop_heap then pop_back: the last element fills the hole left by the top after the hole
    // sinks to the bottom along the larger children (the right one on ties).
    T pop() {
        T* h = heap_.data();
        const T top = h[0];
        const size_t len = heap_.size() - 1;  // without the last, which is re-placed
        if (len > 0) {
            const T value = h[len];
            size_t hole = 0, child = 0;
            while (child < (len - 1) / 2) {
                child = 2 * (child + 1);
                child -= size_t(less_(h[child], h[child - 1]));
                h[hole] = h[child];
                hole = child;
            }
            if ((len & 1) == 0 && child == (len - 2) / 2) {
                child = 2 * (child + 1);
                h[hole] = h[child - 1];
                hole = child - 1;
            }
            rise(hole, 0, value);
        }
        heap_.pop_back();
        return top;
    }

private:
    // __push_heap: moves parents down while they are less than `value`, then places it.
    void rise(size_t hole, size_t top, const T& value) {
        T* h = heap_.data();
        size_t parent = (hole - 1) / 2;
        while (hole > top && less_(h[parent], value)) {
            h[hole] = h[parent];
            hole = parent;
            parent = (hole - 1) / 2;
        }
        h[hole] = value;
    }

    std::vector<T> heap_;
    Less less_;
};

}  // namespace catpaq::points_detail
