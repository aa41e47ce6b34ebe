// ReadyQueue (sched/readyq.hpp): included at the end of kernel.hpp, where
// Tcb is complete, so the hot operations inline into the dispatcher.
#pragma once

#include <cstdlib>

namespace chm::kernel {

inline bool ReadyQueue::reserve(std::size_t n, Tcb* base) {
    base_ = base;
    if (!slot_) {
        // One slot per possible TCB: 128 KiB of address space, touched only
        // as deep as TCB indexes go.
        slot_ = static_cast<std::int32_t*>(std::calloc(kMaxTasks, sizeof(std::int32_t)));
        if (!slot_) return false;
    }
    if (n <= cap_) return true;
    std::size_t cap = cap_ ? cap_ : 64;
    while (cap < n) cap *= 2;
    auto* d = static_cast<Node*>(std::realloc(nodes_, cap * sizeof(Node)));
    if (!d) return false;
    nodes_ = d;
    cap_ = cap;
    return true;
}

inline Tcb* ReadyQueue::top() const { return size_ ? base_ + nodes_[0].idx : nullptr; }
inline Tcb* ReadyQueue::at(std::size_t i) const { return base_ + nodes_[i].idx; }

inline bool ReadyQueue::contains(const Tcb* t) const {
    if (!slot_) return false;
    const std::int32_t i = slot_[t->index];
    return i >= 0 && std::size_t(i) < size_ && nodes_[i].idx == t->index;
}

inline void ReadyQueue::push(Tcb* t, const RqKey& k) {
    sift_up(size_++, node(k, t->index));
}

inline void ReadyQueue::remove(Tcb* t) {
    const std::size_t i = std::size_t(slot_[t->index]);
    --size_;
    if (i == size_) return;
    const Node last = nodes_[size_];
    if (i > 0 && less(last, nodes_[(i - 1) / 2])) sift_up(i, last);
    else sift_down(i, last);
}

inline void ReadyQueue::replace_top(Tcb* t, const RqKey& k) {
    sift_down(0, node(k, t->index));
}

inline void ReadyQueue::sift_up(std::size_t i, Node x) {
    while (i > 0) {
        const std::size_t p = (i - 1) / 2;
        if (!less(x, nodes_[p])) break;
        place(i, nodes_[p]);
        i = p;
    }
    place(i, x);
}

inline void ReadyQueue::sift_down(std::size_t i, Node x) {
    for (;;) {
        std::size_t c = 2 * i + 1;
        if (c >= size_) break;
        if (c + 1 < size_ && less(nodes_[c + 1], nodes_[c])) ++c;
        if (!less(nodes_[c], x)) break;
        place(i, nodes_[c]);
        i = c;
    }
    place(i, x);
}

}  // namespace chm::kernel
