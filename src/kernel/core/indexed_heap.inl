// IndexedHeap (kernel.hpp): a binary min-heap whose elements know their slot.
#pragma once

#include <cstdlib>

namespace chm::kernel {

template <class T, class Less, class Slot>
bool IndexedHeap<T, Less, Slot>::reserve(std::size_t n) {
    if (n <= cap_) return true;
    std::size_t cap = cap_ ? cap_ : 64;
    while (cap < n) cap *= 2;
    auto* d = static_cast<T**>(std::realloc(data_, cap * sizeof(T*)));
    if (!d) return false;
    data_ = d;
    cap_ = cap;
    return true;
}

template <class T, class Less, class Slot>
void IndexedHeap<T, Less, Slot>::push(T* x) {
    place(size_, x);
    sift_up(size_++);
}

template <class T, class Less, class Slot>
void IndexedHeap<T, Less, Slot>::remove(T* x) {
    std::size_t i = 0;
    for (;;) {  // find x's slot through the element itself
        if constexpr (requires { x->idx; }) i = std::size_t(x->idx);
        else i = std::size_t(x->slot);
        break;
    }
    Slot::set(x, -1);
    --size_;
    if (i == size_) return;
    place(i, data_[size_]);
    sift_up(i);
    sift_down(i);
}

template <class T, class Less, class Slot>
void IndexedHeap<T, Less, Slot>::sift_up(std::size_t i) {
    T* x = data_[i];
    while (i > 0) {
        std::size_t p = (i - 1) / 2;
        if (!less(x, data_[p])) break;
        place(i, data_[p]);
        i = p;
    }
    place(i, x);
}

template <class T, class Less, class Slot>
void IndexedHeap<T, Less, Slot>::sift_down(std::size_t i) {
    T* x = data_[i];
    for (;;) {
        std::size_t c = 2 * i + 1;
        if (c >= size_) break;
        if (c + 1 < size_ && less(data_[c + 1], data_[c])) ++c;
        if (!less(data_[c], x)) break;
        place(i, data_[c]);
        i = c;
    }
    place(i, x);
}

}  // namespace chm::kernel
