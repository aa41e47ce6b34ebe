// MUF's critical set (Stewart & Khosla): the user-marked critical tasks,
// then the other periodic tasks in rate order (period, then admission)
// while the worst-case utilisation stays <= 1: the longest such prefix.
//
// Kept incrementally, so admitting or retiring a task costs O(log n) plus
// the tasks whose membership actually changes (it was a scan and a sort of
// every task per periodic spawn: 344 us with 10,000 tasks). The non-critical
// periodic tasks sit in a treap ordered by rate with subtree utilisation
// sums; the prefix ends at the first task whose running sum exceeds the
// budget 1 - U(critical), found in one descent. MUF's ordering key and
// this set's data structures are in sched/muf.hpp.
#include "kernel.hpp"

namespace chm::kernel {

namespace {

constexpr std::uint64_t kOne = 1000000000ull;  // utilisation 1.0, in parts per billion

MufSet& set() { return g_k.muf; }

std::uint64_t util_of(const chm_sched_task_t* s) { return s->wcet_ns * kOne / s->period_ns; }

bool rate_less(const Tcb* a, const Tcb* b) {
    if (a->mn.period != b->mn.period) return a->mn.period < b->mn.period;
    return a->mn.order < b->mn.order;
}

std::uint64_t sum(const Tcb* t) { return t ? t->mn.sum : 0; }
void pull(Tcb* t) { t->mn.sum = sum(t->mn.left) + t->mn.util + sum(t->mn.right); }

void relink(Tcb* parent, Tcb* old_child, Tcb* new_child) {
    if (!parent) set().root = new_child;
    else if (parent->mn.left == old_child) parent->mn.left = new_child;
    else parent->mn.right = new_child;
    if (new_child) new_child->mn.parent = parent;
}

// Lift x above its parent (subtree sums of both recomputed; the pair's
// total, hence every ancestor's, is unchanged).
void rotate_up(Tcb* x) {
    Tcb* p = x->mn.parent;
    relink(p->mn.parent, p, x);
    if (p->mn.left == x) {
        p->mn.left = x->mn.right;
        if (p->mn.left) p->mn.left->mn.parent = p;
        x->mn.right = p;
    } else {
        p->mn.right = x->mn.left;
        if (p->mn.right) p->mn.right->mn.parent = p;
        x->mn.left = p;
    }
    p->mn.parent = x;
    pull(p);
    pull(x);
}

void pull_up(Tcb* t) {
    for (; t; t = t->mn.parent) pull(t);
}

void insert(Tcb* t) {
    MufSet& m = set();
    m.rng ^= m.rng << 13;  // xorshift32: treap priorities
    m.rng ^= m.rng >> 17;
    m.rng ^= m.rng << 5;
    t->mn.prio = m.rng;
    t->mn.left = t->mn.right = nullptr;
    Tcb* p = nullptr;
    for (Tcb* c = m.root; c; c = rate_less(t, c) ? c->mn.left : c->mn.right) p = c;
    t->mn.parent = p;
    if (!p) m.root = t;
    else if (rate_less(t, p)) p->mn.left = t;
    else p->mn.right = t;
    pull_up(t);
    while (t->mn.parent && t->mn.prio < t->mn.parent->mn.prio) rotate_up(t);
    t->mn.in_tree = true;
}

void erase(Tcb* t) {
    while (t->mn.left || t->mn.right) {
        Tcb* l = t->mn.left;
        Tcb* r = t->mn.right;
        rotate_up(!r || (l && l->mn.prio < r->mn.prio) ? l : r);
    }
    Tcb* p = t->mn.parent;
    relink(p, t, nullptr);
    pull_up(p);
    t->mn = MufNode{};
}

Tcb* next(Tcb* t) {
    if (Tcb* c = t->mn.right) {
        while (c->mn.left) c = c->mn.left;
        return c;
    }
    while (t->mn.parent && t->mn.parent->mn.right == t) t = t->mn.parent;
    return t->mn.parent;
}

// First task (in rate order) outside the prefix; nullptr when all fit.
Tcb* first_outside() {
    const std::uint64_t cu = set().crit_util;
    if (cu > kOne) {  // the critical tasks alone overload: no other task fits
        Tcb* c = set().root;
        while (c && c->mn.left) c = c->mn.left;
        return c;
    }
    const std::uint64_t budget = kOne - cu;
    std::uint64_t acc = 0;
    for (Tcb* c = set().root; c;) {
        const std::uint64_t before = acc + sum(c->mn.left);
        if (before > budget) {
            c = c->mn.left;
        } else if (before + c->mn.util > budget) {
            return c;
        } else {
            acc = before + c->mn.util;
            c = c->mn.right;
        }
    }
    return nullptr;
}

bool before_boundary(const Tcb* t, const Tcb* boundary) {
    return !boundary || rate_less(t, boundary);
}

// Set or clear the flag; a ready task's heap key changes with it. A task
// that lends its urgency keeps the loan; its own flags take the change.
void set_member(Tcb* t, bool on) {
    std::int32_t& f = t->boosted ? t->own.flags : t->s.flags;
    if (bool(f & kInCriticalSet) == on) return;
    // (A fallback to MUF re-admits ready tasks before it queues them.)
    const bool requeue = !t->boosted && t->in_ready && g_k.rq.contains(t);
    if (requeue) g_k.rq.remove(t);
    f = on ? (f | kInCriticalSet) : (f & ~kInCriticalSet);
    if (requeue) g_k.rq.push(t, rq_key<CHM_SCHED_MUF>(&t->s));
}

// After a change of the tree or of the critical utilisation: flip the
// tasks between the old and the new end of the prefix.
void move_boundary(Tcb* old_b) {
    Tcb* new_b = first_outside();
    set().boundary = new_b;
    if (old_b == new_b) return;
    const bool grew = !new_b || (old_b && rate_less(old_b, new_b));
    Tcb* from = grew ? old_b : new_b;
    Tcb* to = grew ? new_b : old_b;
    for (Tcb* t = from; t && t != to; t = next(t)) set_member(t, grew);
}

}  // namespace

int muf_admit(void*, chm_sched_task_t* s) {
    s->flags = 0;
    Tcb* t = tcb_of(s);
    if (s->critical) {
        s->flags |= kInCriticalSet;
        if (s->period_ns) {
            t->mn.crit_util = util_of(s);
            set().crit_util += t->mn.crit_util;
            move_boundary(set().boundary);
        }
    } else if (s->period_ns) {
        Tcb* old_b = set().boundary;
        t->mn.period = s->period_ns;
        t->mn.order = ++set().order;
        t->mn.util = util_of(s);
        insert(t);
        move_boundary(old_b);
        if (before_boundary(t, set().boundary)) s->flags |= kInCriticalSet;
    }
    return 0;
}

void muf_retire(void*, chm_sched_task_t* s) {
    Tcb* t = tcb_of(s);
    if (t->mn.in_tree) {
        Tcb* old_b = set().boundary;
        if (old_b == t) old_b = next(t);  // the same end among the others
        erase(t);
        move_boundary(old_b);
    } else if (t->mn.crit_util) {
        set().crit_util -= t->mn.crit_util;
        t->mn.crit_util = 0;
        move_boundary(set().boundary);
    }
}

}  // namespace chm::kernel
