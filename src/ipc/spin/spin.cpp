// Spin-locks for user data: the backplane's robust lock (lock.cpp) with
// the caller's polling interval and retry bound. chm_spin_t has the layout
// of bp::Lock, so one implementation serves both.
#include <cerrno>
#include <cstdint>

#include "chimera/bp.h"
#include "chimera/spin.h"
#include "ipc/backplane/backplane.hpp"

using namespace chm::bp;

static_assert(sizeof(chm_spin_t) == sizeof(Lock));
static_assert(offsetof(chm_spin_t, word) == offsetof(Lock, token));
static_assert(offsetof(chm_spin_t, owner_task) == offsetof(Lock, owner_task));
static_assert(offsetof(chm_spin_t, dirty) == offsetof(Lock, dirty));

namespace {

Lock* as_lock(chm_spin_t* l) {
    if (!l || reinterpret_cast<std::uintptr_t>(l) % alignof(A32)) return nullptr;
    return reinterpret_cast<Lock*>(l);
}

}  // namespace

extern "C" {

int chm_spin_init(chm_spin_t* lock) {
    Lock* l = as_lock(lock);
    if (!l) return -EINVAL;
    l->owner_task.store(0, std::memory_order_relaxed);
    l->dirty.store(0, std::memory_order_relaxed);
    l->reserved = 0;
    l->token.store(0, std::memory_order_release);
    return 0;
}

int chm_spin_lock(chm_spin_t* lock, uint64_t poll_interval_ns, uint64_t timeout_ns) {
    Lock* l = as_lock(lock);
    if (!l) return -EINVAL;
    const Attachment* a = current();
    if (!a) return -ENOTCONN;
    if (timeout_ns == 0) {
        const int r = lock_try(*a, l, a->token);
        return r == -EBUSY ? -ETIMEDOUT : r;
    }
    return lock_acquire(*a, l, a->token, poll_interval_ns, timeout_ns);
}

int chm_spin_trylock(chm_spin_t* lock) {
    Lock* l = as_lock(lock);
    if (!l) return -EINVAL;
    const Attachment* a = current();
    if (!a) return -ENOTCONN;
    return lock_try(*a, l, a->token);
}

int chm_spin_unlock(chm_spin_t* lock) {
    Lock* l = as_lock(lock);
    if (!l) return -EINVAL;
    const Attachment* a = current();
    if (!a) return -ENOTCONN;
    if (l->token.load(std::memory_order_relaxed) != a->token) return -EPERM;
    lock_release(l);
    return 0;
}

}  // extern "C"
