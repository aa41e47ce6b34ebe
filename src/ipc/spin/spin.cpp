// Spin-locks for user data: the backplane's robust lock (lock.cpp) with
// the caller's polling interval and retry bound. chm_spin_t has the layout
// of bp::Lock, so one implementation serves both.
#include <cerrno>
#include <cstdint>

#include "chimera/bp.h"
#include "chimera/spin.h"
#include "ipc/backplane/backplane.hpp"
#include "ipc/err/report.hpp"

using namespace chm::bp;

static_assert(sizeof(chm_spin_t) == sizeof(Lock));
static_assert(alignof(chm_spin_t) >= alignof(A32), "a chm_spin_t anywhere is a valid lock (m68k: chimera/spin.h)");
static_assert(offsetof(chm_spin_t, word) == offsetof(Lock, token));
static_assert(offsetof(chm_spin_t, owner_task) == offsetof(Lock, owner_task));
static_assert(offsetof(chm_spin_t, dirty) == offsetof(Lock, dirty));

namespace {

Lock* as_lock(chm_spin_t* l) {
    if (!l || reinterpret_cast<std::uintptr_t>(l) % alignof(A32)) return nullptr;
    return reinterpret_cast<Lock*>(l);
}

}  // namespace

// Each public call leaves through ipc::leave: a failure becomes an error
// signal of module "ipc" under global handling (ipc/err/report.hpp).
// chm_spin_lock's -ETIMEDOUT and -EOWNERDEAD, and trylock's -EBUSY, are
// outcomes and never raise; unlocking a lock one does not hold (-EPERM)
// is a bug and does.
namespace {
// A user's spin-lock guards data the library cannot see, so it is dirty
// for as long as it is held: a holder that ends without unlocking it (a
// dead process, or a task ended holding it: its hold list orphans a
// dirty lock) hands it on as owner-died (-EOWNERDEAD) and the next
// holder repairs the data. Released clean, the next holder would take
// a half-made change for a whole one (the chaos soak's seqlock block
// did: its sequence's parity inverted after an RTPU stopped mid-write).
int held(Lock* l, int r) {
    if (r == 0 || r == -EOWNERDEAD) lock_mark_dirty(l);
    return r;
}
}  // namespace

extern "C" {

int chm_spin_init(chm_spin_t* lock) {
    Lock* l = as_lock(lock);
    if (!l) return chm::ipc::leave(-EINVAL, "chm_spin_init");
    l->owner_task.store(0, std::memory_order_relaxed);
    l->dirty.store(0, std::memory_order_relaxed);
    l->reserved = 0;
    l->token.store(0, std::memory_order_release);
    return 0;
}

int chm_spin_lock(chm_spin_t* lock, uint64_t poll_interval_ns, uint64_t timeout_ns) {
    Lock* l = as_lock(lock);
    if (!l) return chm::ipc::leave(-EINVAL, "chm_spin_lock");
    const Attachment* a = current();
    if (!a) return chm::ipc::leave(-ENOTCONN, "chm_spin_lock");
    if (timeout_ns == CHM_NO_WAIT) {  // one attempt; busy is -EAGAIN, as every CHM_NO_WAIT
        const int r = held(l, lock_try(*a, l, a->token));
        return chm::ipc::leave(r == -EBUSY ? -EAGAIN : r, "chm_spin_lock");
    }
    return chm::ipc::leave(held(l, lock_acquire(*a, l, a->token, poll_interval_ns, timeout_ns)), "chm_spin_lock");
}

int chm_spin_try_lock(chm_spin_t* lock) {
    Lock* l = as_lock(lock);
    if (!l) return chm::ipc::leave(-EINVAL, "chm_spin_try_lock");
    const Attachment* a = current();
    if (!a) return chm::ipc::leave(-ENOTCONN, "chm_spin_try_lock");
    const int r = held(l, lock_try(*a, l, a->token));
    return chm::ipc::leave(r == -EBUSY ? -EAGAIN : r, "chm_spin_try_lock");
}

// The name before API 1.0 (kept for one release): busy is -EBUSY.
int chm_spin_trylock(chm_spin_t* lock) {
    const int r = chm_spin_try_lock(lock);
    return r == -EAGAIN ? -EBUSY : r;
}

int chm_spin_unlock(chm_spin_t* lock) {
    Lock* l = as_lock(lock);
    if (!l) return chm::ipc::leave(-EINVAL, "chm_spin_unlock");
    const Attachment* a = current();
    if (!a) return chm::ipc::leave(-ENOTCONN, "chm_spin_unlock");
    if (l->token.load(std::memory_order_relaxed) != a->token) return chm::ipc::leave(-EPERM, "chm_spin_unlock");
    lock_clear_dirty(l);
    lock_release(l);
    return 0;
}

}  // extern "C"
