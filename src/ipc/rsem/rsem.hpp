// Remote semaphores (chimera/rsem.h): the semaphore's layout in backplane
// memory and what the files of this folder share. rsem.cpp has the calls
// (P, V, create, open), check.cpp the open-time validation, the repair
// after a dirty lock, the recovery of a dead slot and the checker.
//
// A semaphore is the payload of a registry entry of kind kKindRemoteSem: a
// count and CHM_RSEM_WAITERS waiter records under one robust lock, then the
// records' grant words, each in its own cache line. A waiter parks on its
// record's grant word (ipc/wake); V picks the most urgent record, marks it
// GRANTED, stores its grant word under the lock (the lock dirty between
// the two) and wakes it after the unlock.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "chimera/rsem.h"
#include "ipc/backplane/backplane.hpp"
#include "ipc/wake/wake.hpp"
#include "kernel/sync/remote_wait.hpp"

namespace chm::ipc::rsem {

constexpr std::uint32_t kRsemMagic = 0x5253454d;  // "RSEM"
enum WaiterState : std::uint32_t { kFree = 0, kWaiting = 1, kGranted = 2 };

// Six words, so that the lock, the counters and record 0 fill one cache
// line: a V that takes the lock has the usual single waiter's record too.
struct Waiter {
    bp::A32 state;
    bp::A32 owner;    // make_token(slot, generation) of the waiting process
    bp::A32 prio;     // task priority (higher first); host threads 0
    bp::A32 seq;      // arrival, FIFO among equals
    bp::A32 task;     // the parked task's id (WaiterId); 0: the futex
    bp::A32 urgency;  // WaiterId::urgency
};

struct Rsem {
    bp::Lock lock;
    bp::A32 magic;
    bp::A32 kind;
    bp::A32 count;
    bp::A32 nwaiting;
    bp::A32 seq;
    bp::A32 broken;
    Waiter w[CHM_RSEM_WAITERS];  // taken lowest index first
    // The word record i's owner waits on, alone in its cache line: a
    // granter's exchange then moves one line the waiter spins on, and
    // reading the records does not take it from the spinner first.
    struct GrantLine {
        bp::A32 word;
        std::uint32_t pad[15];
    } grant[CHM_RSEM_WAITERS];
};
static_assert(std::is_standard_layout_v<Rsem>);
static_assert(offsetof(Rsem, w) + sizeof(Waiter) == 64, "lock, counters and record 0: one line");

// The backplane's allocator aligns to 16 bytes; a semaphore takes 48 more
// and starts at the first 64-byte boundary inside, the same in every
// process (mappings are page-aligned).
constexpr std::uint32_t kAllocSize = sizeof(Rsem) + 48;
inline Rsem* rsem_at(void* allocation) {
    const auto p = reinterpret_cast<std::uintptr_t>(allocation);
    return reinterpret_cast<Rsem*>((p + 63) & ~std::uintptr_t(63));
}

inline std::uint32_t* grant_of(Rsem* s, const Waiter* w) {
    return reinterpret_cast<std::uint32_t*>(&s->grant[w - s->w].word);
}
inline const std::uint32_t* grant_of(const Rsem* s, const Waiter* w) {
    return reinterpret_cast<const std::uint32_t*>(&s->grant[w - s->w].word);
}

inline std::uint32_t owner_slot(const Waiter* w) { return bp::token_slot(w->owner.load()); }

inline WaiterId recorded(const Waiter* w) { return WaiterId{w->task.load(), w->urgency.load()}; }

// A record marked GRANTED whose grant word was never stored: its granter
// (a V, a withdrawal, a recovery) ended between give_locked's two stores.
// Only ever seen under a lock left dirty.
inline bool half_granted(const Rsem* s, const Waiter& w) {
    return w.state.load() == kGranted &&
           !chm::kernel::word_granted(__atomic_load_n(grant_of(s, &w), __ATOMIC_ACQUIRE));
}

// check.cpp. The open-time check of a semaphore's words: 0 or kCorrupt
// with `why` naming the field.
int validate_sem(const Rsem* s, char* why, std::size_t n);
// The repair after a holder left the lock dirty (lock held).
void repair_locked(Rsem* s);

// rsem.cpp. Give one unit: to the most urgent waiter (returned in *woken
// when it must be woken after the unlock) or to the count. Lock held.
// -EOVERFLOW when the count is full.
int give_locked(Rsem* s, Waiter** woken);

}  // namespace chm::ipc::rsem
