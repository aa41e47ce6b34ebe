// Waking across the backplane: each RTPU's kernel doorbell lives in its
// table entry (mailbox = futex sequence, pending = vectors, idle = state),
// so any process can raise a mailbox interrupt on any RTPU; a waiter on a
// shared word parks only its task on an RTPU, or sleeps on the word's
// futex in a host process. Remote semaphores, message queues and express
// mail wait and wake through here.
#pragma once

#include <cstdint>

namespace chm::ipc {

// Mailbox vectors with a fixed meaning on every RTPU (chimera/irq.h 0..31;
// 31 is the kernel's grant vector, kernel/sync/remote_wait.hpp).
inline constexpr int kVecExpressMail = 30;

// On the kernel thread of a process that joined the backplane as an RTPU,
// after chm_kernel_init: move the kernel's doorbell into this RTPU's table
// entry, publish the kernel thread's id (the target of directed signals)
// and install the grant vector's handler. Idempotent. Errors: -ENOTCONN
// not joined as an RTPU; -EPERM no kernel on this thread.
int wake_bind_kernel();
// Undo wake_bind_kernel (before chm_kernel_fini / chm_bp_leave).
void wake_unbind_kernel();

// Raise mailbox `vector` on the RTPU in `slot`. Errors: -EINVAL bad slot
// or vector; -ENOTCONN not attached; -ESRCH the slot runs no process;
// -EPERM the slot's pid or thread id failed the identity check (reported,
// not signalled: bp::signal_member).
int wake_ring(std::uint32_t slot, int vector);

// What a waiter stores into its word when it writes its record (before a
// granter can see it): kernel::kWordWatched when wait_word will spin on it
// first (a task on an RTPU that polls and has nothing else to run), so a
// grant then rings nothing; else 0.
std::uint32_t wait_word_initial();

// The clock wait_word measures its deadline on: the kernel's (chm_time_now:
// virtual or monotonic) when it parks the caller as a task,
// CLOCK_MONOTONIC on any other thread.
std::uint64_t wait_now();

// How long a backplane call may wait (chimera/kernel.h, "Timeouts"), as
// its caller gave it. Resolved to a deadline on wait_now()'s clock only
// when the call has to wait, so the path that need not wait reads no clock.
struct WaitLimit {
    enum Kind : std::uint8_t { kForever, kNoWait, kFor, kUntil };
    Kind kind = kForever;
    std::uint64_t ns = 0;  // kFor: relative timeout; kUntil: a chm_time_now() deadline
    // The deadline on wait_now()'s clock; UINT64_MAX: none; kNoWait: 0, past
    // (callers fail with -EAGAIN before they get here).
    std::uint64_t deadline() const;
    // How long the call may still wait for an internal lock, in real time:
    // the time left of a timeout or a deadline (a virtual clock's counted
    // as real time), at most `cap`; 0 for kNoWait and a deadline reached;
    // `cap` for kForever. *own (may be NULL): true when the call's own
    // limit, not `cap`, is the bound (its end is then -ETIMEDOUT).
    std::uint64_t lock_budget(std::uint64_t cap, bool* own) const;
};
// CHM_NO_WAIT (0) gives kNoWait, CHM_FOREVER kForever.
WaitLimit wait_for(std::uint64_t timeout_ns);
// CHM_FOREVER gives kForever.
WaitLimit wait_until(std::uint64_t deadline_ns);

// Wait until *word != 0: parks only the calling task on an RTPU, sleeps on
// the word's futex on any other thread, until `deadline` on wait_now()'s
// clock (UINT64_MAX: no limit; one already reached: -ETIMEDOUT at once
// unless the word is set). Returns 0, -ETIMEDOUT or -EINTR.
int wait_word(std::uint32_t* word, std::uint64_t deadline);

// Who waits on a word, as the granter needs it; a waiter records this
// beside its word (two words in backplane memory).
struct WaiterId {
    // The parked task's id as its RTPU publishes it (kernel::
    // remote_waiter_id); 0: a thread waiting on the word's futex.
    std::uint32_t task = 0;
    // Its urgency on its RTPU's scale (kernel::remote_waiter_urgency): a
    // grant to a task that does not outrank the running one, or to the
    // running task itself, raises the vector without a directed signal.
    std::uint32_t urgency = UINT32_MAX;
    bool as_task() const { return task != 0; }
};

// The caller's WaiterId: how wait_word will wait (parked as a task, or on
// the futex) and the rest of what a granter needs.
WaiterId waiter_self();
// Only how: true when wait_word parks the caller as a task.
bool waits_as_task();

// Store the grant `value` into *word (non-zero, not kernel::kWordWatched).
// True when the waiter's RTPU was polling that word in its idle loop: it
// sees the grant there, and no wake-up is needed.
bool store_grant(std::uint32_t* word, std::uint32_t value);
// Store `value` and wake its waiter `who` in `slot` unless it watches the
// word: a task through the slot's doorbell (grant vector), anyone else by
// the futex.
void grant_word(std::uint32_t* word, std::uint32_t value, std::uint32_t slot, WaiterId who);
// Only the wake-up half: for a granter that stored the word under its own
// lock (so a waiter timing out at that moment sees the grant) and found it
// not watched.
void wake_granted(std::uint32_t* word, std::uint32_t slot, WaiterId who);

}  // namespace chm::ipc
