// The timer heap: every pending timed event of an RTPU (releases,
// deadlines, pauses, timeouts), earliest first; among events due at the
// same instant, by `order` (the owner's task index + 1, 0 for owner-less
// timers: simultaneous releases arrive in a defined order, sched.h).
//
// A 4-ary min-heap whose array holds each event's key (due, order) beside
// its node, and whose nodes know their slot (O(log n) removal). Why not a
// binary heap of node pointers (as before): with 10,000 periodic tasks,
// each comparison read a key from a TCB of its own, scattered in memory,
// and a pop compared ~2 x 14 of them: three cache misses per level, about
// half of the kernel's cost per job (bench row sched_ops_10k_over_10).
// Here comparisons read the array only (a node's four children are 96
// contiguous bytes) and the heap has half the levels; the one write per
// level that stays scattered is the moved node's slot.
//
// Storage grows only in reserve(), outside the interrupt mask.
// tests/kernel/test_kernel_timer_heap.cpp checks it against a sorted set
// over thousands of random operation sequences.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdlib>

namespace chm::kernel {

struct Tcb;

// One pending timed event, intrusive in its owner; lives in the timer heap.
enum class TimerKind : std::uint8_t { Wake, Release, Deadline, IoPoll };
struct TimerNode {
    std::uint64_t due = 0;
    std::int32_t idx = -1;  // slot in the timer heap; -1 = not armed
    TimerKind kind = TimerKind::Wake;
    Tcb* owner = nullptr;
};

class TimerHeap {
public:
    static constexpr std::size_t kArity = 4;

    // Room for n events without growing; false when memory ran out.
    bool reserve(std::size_t n) {
        if (n <= cap_) return true;
        std::size_t cap = cap_ ? cap_ : 64;
        while (cap < n) cap *= 2;
        auto* d = static_cast<Entry*>(std::realloc(data_, cap * sizeof(Entry)));
        if (!d) return false;
        data_ = d;
        cap_ = cap;
        return true;
    }
    // Insert n (not in the heap) at n->due with tie order `order`.
    void push(TimerNode* n, std::uint32_t order) {
        sift_up(size_++, Entry{n->due, order, n});
    }
    // Take n (in the heap) out.
    void remove(TimerNode* n) {
        const std::size_t i = std::size_t(n->idx);
        n->idx = -1;
        const Entry last = data_[--size_];
        if (i == size_) return;
        if (i > 0 && before(last, data_[(i - 1) / kArity])) sift_up(i, last);
        else sift_down(i, last);
    }
    // Free the storage (empty the heap first). A plain handle otherwise,
    // copied as one: the kernel keeps its heap's storage from one init to
    // the next (core/kernel.cpp, chm_kernel_fini).
    void free_storage() {
        std::free(data_);
        data_ = nullptr;
        size_ = cap_ = 0;
    }
    // The earliest due later than `after`, or 0 when there is none or it
    // takes more than kLookBudget steps to tell (an event due at or before
    // `after` is visited with its children: a subtree holding the root).
    static constexpr std::size_t kLookBudget = 64;  // its queue: 256 bytes of a task's stack
    // The idle loop's (time/lead.cpp), on the kernel thread's own stack:
    // 8 KiB, enough for 400 events at one instant (200 tasks' releases and
    // deadlines) and their children.
    static constexpr std::size_t kIdleLookBudget = 2048;
    template <std::size_t Budget = kLookBudget>
    std::uint64_t next_due_after(std::uint64_t after) const {
        std::uint32_t todo[Budget];
        std::size_t head = 0, tail = 0;
        std::uint64_t best = 0;
        if (size_) todo[tail++] = 0;
        while (head < tail) {
            const std::size_t i = todo[head++];
            if (data_[i].due > after) {
                if (!best || data_[i].due < best) best = data_[i].due;
                continue;
            }
            for (std::size_t c = kArity * i + 1; c < size_ && c <= kArity * i + kArity; ++c) {
                if (tail == Budget) return 0;
                todo[tail++] = std::uint32_t(c);
            }
        }
        return best;
    }
    TimerNode* top() const { return size_ ? data_[0].node : nullptr; }
    std::uint64_t top_due() const { return data_[0].due; }  // size() > 0
    std::size_t size() const { return size_; }

private:
    struct Entry {
        std::uint64_t due;
        std::uint32_t order;
        TimerNode* node;
    };
    static bool before(const Entry& a, const Entry& b) {
        return a.due != b.due ? a.due < b.due : a.order < b.order;
    }
    void place(std::size_t i, const Entry& e) {
        data_[i] = e;
        e.node->idx = std::int32_t(i);
    }
    // Put x at hole i or above it.
    void sift_up(std::size_t i, const Entry& x) {
        while (i > 0) {
            const std::size_t p = (i - 1) / kArity;
            if (!before(x, data_[p])) break;
            place(i, data_[p]);
            i = p;
        }
        place(i, x);
    }
    // Put x at hole i or below it.
    void sift_down(std::size_t i, const Entry& x) {
        for (;;) {
            const std::size_t first = kArity * i + 1;
            if (first >= size_) break;
            const std::size_t end = first + kArity < size_ ? first + kArity : size_;
            std::size_t c = first;
            for (std::size_t k = first + 1; k < end; ++k)
                if (before(data_[k], data_[c])) c = k;
            if (!before(data_[c], x)) break;
            place(i, data_[c]);
            i = c;
        }
        place(i, x);
    }

    Entry* data_ = nullptr;
    std::size_t size_ = 0, cap_ = 0;
};

}  // namespace chm::kernel
