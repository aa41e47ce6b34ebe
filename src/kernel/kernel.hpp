// The kernel's internal state: the task control block, the kernel object
// and the functions kernel files call on one another. Nothing here is public
// API (that is include/chimera/*.h).
//
// Locking rule: every field below is read and written only with the port's
// interrupt mask held (functions named *_locked), except where a comment
// says otherwise.
#pragma once

#include <cstddef>
#include <cstdint>

#include "chimera/kernel.h"
#include "chimera/sched.h"
#include "chimera/task.h"
#include "chimera/usig.h"
#include "port.hpp"
#include "sched/muf.hpp"
#include "sched/readyq.hpp"
#include "time/timer_heap.hpp"

namespace chm::kernel {

// Builds with assertions (NDEBUG not defined: meson's debug and
// debugoptimized buildtypes; release defines it, b_ndebug=if-release): the
// central `_locked` entries (ready queue insert and remove, timers,
// schedule, block) check that their caller holds the interrupt mask. One
// load and a compare; compiled out in release.
[[noreturn]] void mask_not_held(const char* fn);  // core/dispatch.cpp: reports, aborts
#ifndef NDEBUG
#define CHM_ASSERT_LOCKED() \
    (__builtin_expect(::chm::port::irq_masked(), 1) ? (void)0 : ::chm::kernel::mask_not_held(__func__))
#else
#define CHM_ASSERT_LOCKED() ((void)0)
#endif

struct Tcb;

// Tasks blocked on one object, most urgent first (by the scheduler's
// `before`, then arrival).
struct WaitQueue {
    Tcb* head = nullptr;
};

enum class TaskState : std::uint8_t {
    Ready, Running, Blocked, Suspended, WaitPeriod, Paused, Ended
};

struct Tcb {
    port::Context ctx;
    chm_sched_task_t s{};    // the scheduler's view
    TaskState state = TaskState::Ready;
    bool in_ready = false;   // enqueued in the scheduler
    bool used = false;
    std::uint64_t gen = 0;   // 1..kGenMax; the id's bits 16..62 (tid_of)
    std::uint32_t index = 0;
    std::uint32_t short_id = 0;  // tid_short of its id, set at spawn (read at every switch)
    std::int32_t next_free = -1;
    int saved_errno = 0;
    std::uint32_t lock_nest = 0;      // chm_task_lock depth
    std::uint32_t suspend_count = 0;
    TaskState suspended_from = TaskState::Ready;

    // Blocking.
    WaitQueue* wq = nullptr;
    Tcb* wnext = nullptr;
    int wait_result = 0;
    bool interruptible = false;
    TimerNode tmr;  // wake-up (pause, timeout) or release of a periodic task
    struct IoWait* io = nullptr;  // the descriptors it waits on (io/fdwait.cpp)
    std::uint32_t* rword = nullptr;  // shared word it waits on (sync/remote_wait.cpp)
    TimerNode dl;   // deadline of the current cycle

    // Global error handling (err/): the task's handler set, allocated on
    // first use; the binary semaphores it holds (sync/sem.cpp), released
    // with owner-died semantics if it is aborted.
    struct ErrTask* err = nullptr;
    void* held = nullptr;

    // Inside backplane calls (task/holds.cpp, issue 15): how deep; what
    // the task holds there (a lock, a waiter record), each given back by
    // its release function however the task ends; and an end (destroy) or
    // an aborted cycle owed for when the outermost call returns or reaches
    // its wait (a cancellation point).
    struct Hold {
        void (*release)(void*, std::uint32_t);
        void* obj;
        std::uint32_t tag;
    };
    static constexpr int kMaxHolds = 6;
    std::uint8_t nholds = 0;  // entries of `holds` (below) in use
    std::uint8_t call_depth = 0;
    bool at_cancel_point = false;  // in a call's wait: handlers may run, cancels take effect
    bool end_owed = false;         // destroyed inside a call
    bool abort_cycle_owed = false; // a deadline handler aborted the cycle inside a call

    // User signals.
    std::uint32_t sig_pending = 0;
    std::uint32_t sig_blocked = 0;
    std::uint32_t sigs_taken = 0;    // handlers run (a spinning remote wait's -EINTR)
    std::uint32_t sigs_at_wait = 0;  // sigs_taken when a planned spin's record was written
    std::uint32_t sig_handled = 0;   // bit n: sig_handler[n] and sig_arg[n] (below) were set

    // Periodic timing and deadline failures.
    std::uint64_t cycle = 0;          // index of the current cycle
    std::uint64_t releases = 0;       // cycles released so far
    bool miss_pending = false;        // handler owed for cycle `missed_cycle`
    std::uint64_t missed_cycle = 0;
    std::uint64_t missed_deadline = 0;
    chm_deadline_handler_t on_deadline = nullptr;
    void* on_deadline_arg = nullptr;
    int handler_priority = 0;
    bool abort_cycle = false;         // restart the entry at the next release
    bool awaiting_release = false;    // cycle completed, next release not yet taken
    bool release_pending = false;     // the release came while it was not waiting
    std::uint64_t pending_release = 0;

    // Statistics.
    std::uint64_t cpu_ns = 0;
    std::uint64_t cycles_done = 0;
    std::uint64_t misses = 0;
    std::uint64_t worst_lateness = 0;
    std::uint64_t worst_cycle_cpu = 0;
    std::uint64_t misses_unhandled = 0;  // since its deadline handler last ran
    std::size_t final_high_water = 0;    // stack high water when the stack was released

    // Its end (task/lifecycle.cpp): how and with what status; a joinable
    // task keeps its slot until joined; hooks and task-local values live
    // in `ext`, allocated on first use; a timing change waits for the
    // next release.
    std::uint8_t end_reason = 0;      // chm_task_end_reason
    bool joinable = false;
    bool stack_gone = false;          // its stack was released (slot held for a joiner)
    bool joined = false;              // chm_task_join took its status: its id is stale
    bool timing_pending = false;
    int exit_status = 0;
    WaitQueue joiners;
    struct TaskExt* ext = nullptr;
    std::uint64_t timing_refused = 0;

    // Priority inheritance: the view fields this task owns (`own`, below)
    // while it lends a waiter's urgency.
    bool boosted = false;

    MufNode mn;

    // Stack (from the stack pool) and entry.
    unsigned char* stack_lo = nullptr;
    std::size_t stack_size = 0;
    std::size_t stack_dirty = 0;  // bytes below the top ever written (high water)
    void (*entry)(void*) = nullptr;
    void* arg = nullptr;

    // Not initialised at spawn: slot_take_locked default-initialises the
    // TCB (`new (t) Tcb`, not `Tcb()`), so these 800 bytes, rarely used,
    // are not zeroed for every task (a cold TCB: 22 cache lines were
    // written). Each is valid only where the field named says so.
    Hold holds[kMaxHolds];                            // below nholds
    chm_usig_handler_t sig_handler[CHM_USIG_MAX + 1];  // where sig_handled has the bit
    void* sig_arg[CHM_USIG_MAX + 1];
    chm_sched_task_t own;                             // while boosted
    chm_task_timing_t new_timing;                     // while timing_pending
    char name[CHM_TASK_NAME_MAX + 1];                 // written at spawn
};

inline constexpr std::uint32_t kMaxTasks = 32768;
// An ended task's slot is not taken again while this many slots freed
// after it are free (task/task.cpp: slot_release_locked).
inline constexpr std::uint32_t kSlotRetain = 64;

// Timers due at the same instant fire in task-index order (spawn order in
// a fresh kernel): simultaneous releases arrive in a defined order, which
// decides first come among equals (sched.h). Owner-less timers first.
inline std::uint32_t timer_order(const TimerNode* n) { return n->owner ? n->owner->index + 1 : 0; }

inline Tcb* tcb_of(chm_sched_task_t* s) {
    return reinterpret_cast<Tcb*>(reinterpret_cast<char*>(s) - offsetof(Tcb, s));
}

struct Kernel {
    bool initialised = false;
    bool running = false;
    bool stop_requested = false;  // chm_kernel_stop called: hooks running
    struct Tcb* hooks_runner = nullptr;  // the task running the shutdown hooks
    bool stopping = false;        // hooks done: the run loop returns
    // A task spun out idle_poll_ns before it parked (sync/remote_wait.cpp):
    // the idle loop sleeps without polling again.
    bool idle_poll_spent = false;
    int stop_code = 0;
    chm_kernel_config_t cfg{};

    Tcb* current = nullptr;     // the running task; nullptr = kernel/idle
    port::Context idle_ctx;     // chm_kernel_run's own context
    Tcb* zombie = nullptr;      // ended task whose stack is freed after the switch
    int* errno_loc = nullptr;   // the kernel thread's errno (every task runs there)
    bool in_irq = false;        // an interrupt handler runs (irq/irq.cpp): no switch
    bool switch_timed = false;  // cfg.cpu_accounting || cfg.quantum_ns: a switch reads the clock

    // Scheduling.
    const chm_sched_ops_t* ops = nullptr;
    void* ops_self = nullptr;
    chm_sched_policy policy = CHM_SCHED_MUF;
    // A built-in policy is in force (not CHM_SCHED_USER): the dispatcher
    // calls its queue and comparison directly instead of through `ops`
    // (same operations, no indirect call per switch).
    bool builtin = true;
    std::uint64_t seq = 0;
    ReadyQueue rq;              // the ready queue of the built-in policies
    MufSet muf;                 // MUF's critical set (sched/muf.cpp)

    // Time.
    TimerHeap timers;
    std::uint64_t vnow = 0;           // virtual clock
    std::uint64_t switched_in_at = 0; // CPU accounting of `current`
    std::uint64_t quantum_due = 0;    // end of `current`'s quantum, when armed
    // The switch left the quantum's arming to the tick already armed at or
    // before its end (core/dispatch.cpp, quantum_arm_at_switch_locked):
    // the first event of the slice arms it; until then its end
    // (slice_start + quantum) counts as expired and as due.
    bool quantum_lazy = false;
    std::uint64_t slice_start = 0;    // when `current` was dispatched: its quanta end slice_start + k*q
    bool decision_owed = false;       // virtual clock: timers fired as a task's work ended
    std::uint64_t armed_at = 0;       // what the port timer is set to (0 none)
    std::uint64_t lead_ns = 0;        // the automatic timer lead (time/lead.cpp)
    std::uint64_t lead_on_time = 0;   // timer events the idle loop reached by polling
    std::uint32_t lead_score = 0;     // > 0: waits end at their events often enough to lead
    std::uint64_t now_cache = 0;      // last clock reading

    // Tasks: TCBs live in one reserved array, so an id or a pointer handed
    // back by a user scheduler is checked in O(1).
    Tcb* tcbs = nullptr;
    std::uint32_t tcb_hw = 0;       // slots ever used
    std::uint32_t alive = 0;
    // Free slots (task/task.cpp, slot_release_locked): the last
    // kSlotRetain freed, oldest first, then the ones freed before them,
    // newest first; both linked through Tcb::next_free.
    std::int32_t free_slot = -1;    // the oldest of the recently freed
    std::int32_t free_tail = -1;    // the newest of them
    std::uint32_t free_recent = 0;  // how many (at most kSlotRetain)
    std::int32_t cold_slot = -1;    // freed before them: a stack, newest on top
    std::uint32_t slots_retired = 0;  // slots whose generations are all used (kGenMax)

    // Tasks parked in blocking UNIX calls (io/fdwait.cpp): the idle loop
    // waits on their descriptors; while other tasks run, io_tmr polls them.
    WaitQueue io_waiters;
    TimerNode io_tmr{0, -1, TimerKind::IoPoll, nullptr};

    // Shutdown hooks.
    struct Hook { void (*fn)(void*); void* arg; };
    Hook hooks[32];
    int nhooks = 0;

    // Tests only: called at every switch with the task switched to
    // (nullptr: the idle loop) and the time; the differential scheduler
    // test records the timeline with it.
    void (*trace_switch)(const Tcb* next, std::uint64_t now) = nullptr;

    // Statistics. remote_parks: remote waits that parked their task (a
    // wait granted while it spun is not one).
    std::uint64_t ticks = 0, switches = 0, remote_parks = 0;
};

extern Kernel g_k;

// ---- time (time/clock.cpp)
// Reads the clock (port::now_ns: ~10 ns with the cycle counter, a vDSO
// call of ~24 ns without) and remembers the reading for now_cached_locked().
inline std::uint64_t now_locked() {
    const std::uint64_t t = g_k.cfg.virtual_clock ? g_k.vnow : port::now_ns();
    g_k.now_cache = t;
    return t;
}
// The clock read exactly (port::now_exact_ns): where a timer expiry is
// judged, so it is never found a little before the instant that fired it.
inline std::uint64_t now_exact_locked() {
    const std::uint64_t t = g_k.cfg.virtual_clock ? g_k.vnow : port::now_exact_ns();
    g_k.now_cache = t;
    return t;
}
// The last clock reading: what the hot paths hand to scheduler operations
// that do not need the exact time (enqueue, wait-queue order).
inline std::uint64_t now_cached_locked() {
    return g_k.cfg.virtual_clock ? g_k.vnow : g_k.now_cache;
}
void timer_add_locked(TimerNode* n, std::uint64_t due);
void timer_remove_locked(TimerNode* n);  // an armed timer out of the heap
// Disarm `n` if it is armed (the check inline: most cancels find nothing).
inline void timer_cancel_locked(TimerNode* n) {
    CHM_ASSERT_LOCKED();
    if (n->idx >= 0) timer_remove_locked(n);
}
// Fire every due timer; returns true when the running task must reschedule.
bool timers_run_locked(std::uint64_t now);
// Program the port timer for the earliest of the timer heap and quantum.
void timer_program_locked(std::uint64_t now);
// An event at most this much before the armed time rides on it.
inline constexpr std::uint64_t kArmSlackNs = 1000;  // far below a timer signal's latency
// The port timer already serves an event at `due` (the earliest one): it
// is armed after `now`, at most kArmSlackNs after `due` (its early tick
// finds a later one), and is not a repeating timer that would tick on for
// nothing. timer_program_locked would then change nothing; checked inline
// where a quantum is armed at every switch.
inline bool timer_serves_locked(std::uint64_t due, std::uint64_t now) {
    return g_k.armed_at > now && g_k.armed_at <= due + kArmSlackNs && !port::timer_interval();
}
// The timer signal came: what is armed now (a repeating timer re-armed
// itself; a one-shot is spent).
void timer_fired_locked(std::uint64_t now);
// A tick that came while the RTPU slept (kept pending, taken after the
// wait): what is armed now, the due timers, the next arming. The one path
// for both of the RTPU's sleeps (the idle loop's, and ppoll's while tasks
// are parked on descriptors), so neither forgets a repeating timer.
void idle_tick_locked();
std::uint64_t next_due_locked();
// What follows the event at `due` (the top of the timer heap), as a gap
// from it: the repeating timer's interval (time/clock.cpp); 0 when unknown.
std::uint64_t next_gap_guess_locked(std::uint64_t due);

// ---- timer lead (time/lead.cpp)
inline constexpr std::uint64_t kLeadMaxAutoNs = 200'000;
inline constexpr std::uint64_t kLeadStepNs = 1'000;
// The automatic lead after one more sleep that woke `late` after its
// timeout: up 3 steps when later than `lead`, else down 1, at most
// kLeadMaxAutoNs. It settles where a quarter of the wake-ups come later
// than the lead: their 75th percentile.
std::uint64_t lead_learn(std::uint64_t lead, std::uint64_t late);
// Whether the idle loop's waits end at their timer events often enough to
// lead them (time/lead.cpp): up kLeadServed for a wait that did, down 1
// for one a ring ended first, within 0..kLeadScoreMax; 0: sleep plainly.
// A ring per event keeps leading; more than kLeadServed per event stops.
inline constexpr std::uint32_t kLeadServed = 16, kLeadScoreMax = 256;
std::uint32_t lead_score_next(std::uint32_t score, bool served);
inline constexpr std::int64_t kLeadMaxNs = 1'000'000;  // a fixed chm_kernel_config.timer_lead_ns
// The lead in use: 0 off (configured 0, or the virtual clock).
std::uint64_t timer_lead_locked();
// The automatic lead's first guess (chm_kernel_init).
void timer_lead_reset_locked();
// The idle loop's wait when a timer event lies ahead: sleep until the
// lead before it, poll until it is due, run it. False (nothing done) when
// the lead is off or the event too near or absent: the caller waits as
// before. Mask held.
bool idle_lead_wait_locked(std::uint64_t now, std::uint64_t poll_ns);

// ---- deadline failures (time/deadline.cpp)
// The deadline timer of `t`'s cycle fired: count the miss, owe it the handler.
void deadline_missed_locked(Tcb* t, std::uint64_t now);
// The running task `t` completed its cycle at `now` (chm_task_wait_period).
void complete_cycle_locked(Tcb* t, std::uint64_t now);
// In the current task's context (miss_pending): run its deadline handler,
// or raise the error signal, and act on continue / abort-cycle / stop-RTPU.
// Releases the mask around user code.
void deliver_deadline_miss_locked(Tcb* cur);
// Abort-cycle: restart the current task's entry from the top, on its own
// stack (after the wait for its next release).
[[noreturn]] void restart_aborted_cycle_locked(Tcb* cur);

// ---- dispatching (core/dispatch.cpp)
// Make `t` ready (not for the running task). A task that becomes ready goes
// behind its equals; a preempted one keeps its place (keep_place).
void make_ready_locked(Tcb* t, bool keep_place = false);
// Remove `t` from the ready set if it is there (the check inline).
void unready_queued_locked(Tcb* t);  // `t` is in it
inline void unready_locked(Tcb* t) {
    if (t->in_ready) unready_queued_locked(t);
}
// Run the most urgent task: switch if it is not the current one (or the
// current one stopped running). Task or kernel context, mask held.
void schedule_locked();
// The same at `now`, a clock reading the caller took in this kernel call
// (the running task already charged up to it, when accounting is on).
void schedule_at_locked(std::uint64_t now);
// After a kernel call made something ready or changed an urgency: let the
// most urgent task run and deliver what is owed to the caller. No-op outside
// a task (spawning from main before chm_kernel_run).
void reschedule_locked();
// The same with the caller's fresh reading `now` (now_locked() in this
// call) instead of a second one: it charges up to `now` itself.
void reschedule_at_locked(std::uint64_t now);
// True when the current task should give up the CPU now.
bool must_switch_locked(std::uint64_t now);
// The decision at an event (timers fired) while a task runs: charges it,
// returns must_switch_locked, else arms its quantum's end if needed.
bool decide_at_event_locked(std::uint64_t now);
// Block the current task (state already set); returns its wait_result.
int block_current_locked();
// Work owed to the current task in its own context: user signals, deadline
// handler, aborted cycle. Called with the mask held; releases it around
// user code.
// Inside a backplane call (call_depth) only at its wait (at_cancel_point):
// a handler run while the call holds an object's lock could end the task
// there, or call into the same object and wait for itself.
void deliver_pending_slow_locked();
inline void deliver_pending_locked() {
    const Tcb* cur = g_k.current;
    if (cur && (cur->miss_pending || (cur->sig_pending & ~cur->sig_blocked)) &&
        (!cur->call_depth || cur->at_cancel_point))
        deliver_pending_slow_locked();
}
// Charge the running task its CPU time up to `now` (inline: per-switch
// accounting does it at every switch).
inline void charge_current_locked(std::uint64_t now) {
    Tcb* cur = g_k.current;
    if (!cur) return;
    const std::uint64_t d = now - g_k.switched_in_at;
    cur->cpu_ns += d;
    cur->s.cycle_cpu_ns += d;
    g_k.switched_in_at = now;
}
// The reading a switch runs at: the clock only when something needs it
// (per-switch CPU accounting or a round-robin quantum: a clock read costs
// more than the rest of a switch on a virtual machine), the running task
// charged up to it.
inline std::uint64_t schedule_now_locked() {
    const bool timed = g_k.cfg.cpu_accounting || g_k.cfg.quantum_ns;
    const std::uint64_t now = timed ? now_locked() : now_cached_locked();
    if (g_k.cfg.cpu_accounting) charge_current_locked(now);
    return now;
}

// ---- interrupts (irq/irq.cpp)
// Deliver every raised, enabled vector to its handler. Mask held; kernel
// thread (signal handler, pending tick or idle loop).
void irq_dispatch_locked();
bool irq_fds_bound_locked();
// The bound line descriptors, as pollfds (a quiet line polls fd -1), and
// their results back (raising the lines that are ready).
std::size_t irq_gather_fds_locked(struct pollfd* out, std::size_t room);
void irq_scatter_fds_locked(const struct pollfd* in, std::size_t n);
void irq_reset();

// ---- blocking UNIX calls (io/fdwait.cpp)
// Anything for the idle loop to watch: parked tasks or bound IRQ lines.
inline bool io_watching_locked() { return g_k.io_waiters.head || irq_fds_bound_locked(); }
// Poll every parked task's descriptors without waiting; wake those ready.
void io_poll_locked();
// The IoPoll timer fired (any context, mask held): poll, re-arm if needed.
void io_tick_locked(std::uint64_t now);
// Idle with parked tasks: sleep until a descriptor is ready, the timer
// fires or the RTPU is woken. Kernel context, mask held.
void io_idle_wait_locked();
// About to run tasks while others are parked: keep polling them.
void io_busy_arm_locked(std::uint64_t now);

// ---- tasks (task/*.cpp)
Tcb* tcb_lookup(chm_tid_t id);
// The same, and a task that ended whose slot was not taken again (status).
Tcb* tcb_lookup_ended_too(chm_tid_t id);
// A task id: slot index in bits 0..15, the slot's generation in 16..62
// (positive: CHM_TID_NONE and errors stay negative). A slot that has used
// its last generation is retired, never reused (task.cpp, slot_take_locked),
// so an id never names a second task in one process.
inline constexpr std::uint64_t kGenMax = (std::uint64_t(1) << 47) - 1;
inline chm_tid_t tid_of(const Tcb* t) { return chm_tid_t(t->index | (t->gen << 16)); }
// The 31-bit form shared memory carries where a 32-bit word was laid out
// (a backplane lock's owner_task, a waiter's and the doorbell's task
// words): the slot, and the generation folded into 1..0x7fff (the old
// 32-bit id, exactly, for a slot's first 32,767 tasks). Exact among live
// tasks (two live tasks never share a slot), a diagnostic elsewhere.
inline std::uint32_t tid_short(chm_tid_t id) {
    if (id < 0) return 0;
    const std::uint64_t gen = std::uint64_t(id) >> 16;
    return std::uint32_t(id & 0xffff) | std::uint32_t(((gen - 1) % 0x7fff + 1) << 16);
}
inline std::uint32_t tid_short(const Tcb* t) { return t->short_id; }
// Is `s` the scheduler view of a live TCB? O(1); never dereferences a
// pointer that is not inside the TCB array.
bool tcb_view_valid(const chm_sched_task_t* s);
void task_end_locked(Tcb* t);         // unlink everywhere, mark ended
// End the running task with `reason` and `status`: its hooks first (task
// context, mask free), then the end proper. Does not return.
[[noreturn]] void task_end_current(chm_task_end_reason reason, int status);
// The switch of a spawn (op kSwitchSpawn: the spawner, charged up to the
// spawn's clock reading, lets a more urgent new task run) and of a task's
// end (kSwitchEnd: the running task `tcb` ends and never comes back): one
// path to the scheduler for both, so a spawner resumed by its child's end
// returns through the very call sites the child switched from (task.cpp).
// Entered with the mask held through port::call_indirect_return; releases
// it; returns 0.
enum : std::uintptr_t { kSwitchSpawn = 0, kSwitchEnd = 1 };
int task_switch_entry(void* tcb, std::uintptr_t op);
// Give back everything `t` holds in backplane calls (its hold list, last
// first), in the caller's context, mask free: the end of every task.
void task_release_holds(Tcb* t);
// `t` is inside a backplane call: its end is owed to the call's return
// (true), and a wait it is in is cancelled. Mask held.
bool task_owe_end_locked(Tcb* t);
// A return to an error mark from inside backplane calls: the holds taken
// since the mark (beyond `holds`) are given back, the call depth is the
// mark's, and an end or aborted cycle owed to the calls left is carried
// out (then it does not return). Task context, the task's own.
void task_leave_calls_to(Tcb* t, unsigned holds, unsigned depth);
// Another task's end hooks and local-value destructors, in the caller's
// context (destroy, teardown); `t` is already off the CPU for good.
void task_run_end_hooks(Tcb* t);
// Apply a pending chm_task_set_timing at a release (the task is not queued).
void task_apply_timing_locked(Tcb* t);
// The slot of an ended task goes back to the free list (after its stack,
// and after a join for a joinable task).
void slot_release_locked(Tcb* t);
void task_free_stack_locked(Tcb* t);         // after the last switch away from it: frees the slot too
// Entry of every task context: drops the switcher's mask, runs the entry.
void task_start(void* tcb);
void release_cycle_locked(Tcb* t, std::uint64_t release);
int stacks_reserve(std::size_t size, unsigned char** lo);
// Back to its pool (or unmapped). Its task's frames were scrubbed first
// (stack_scrub), or it never ran.
void stacks_release(unsigned char* lo, std::size_t size);
bool stack_canary_ok(const Tcb* t);
std::size_t stack_high_water(const Tcb* t);
std::size_t stack_round(std::size_t size);
// Re-zero the ended task's dirtied stack; returns its depth (bytes).
std::size_t stack_scrub(const Tcb* t);

// ---- scheduling policies (sched/*.cpp)
int sched_select(chm_sched_policy policy, const chm_sched_ops_t* user, void* user_arg);
// A user scheduler's pick, validated; falls back to MUF on failure.
Tcb* sched_pick_user_locked(std::uint64_t now);
// The task to run next (left in the ready set) or nullptr.
inline Tcb* sched_pick_locked(std::uint64_t now) {
    if (g_k.builtin) return g_k.rq.top();
    return sched_pick_user_locked(now);
}
// `a` must run before `b` (the policy's `before`).
inline bool sched_before_locked(Tcb* a, Tcb* b, std::uint64_t now) {
    if (g_k.builtin) return key_before(g_k.policy, &a->s, &b->s);
    return g_k.ops->before(g_k.ops_self, &a->s, &b->s, now) != 0;
}
// Queue a ready task in the scheduler (in_ready is set by the caller).
inline void sched_enqueue_locked(Tcb* t) {
    CHM_ASSERT_LOCKED();
    if (g_k.builtin) g_k.rq.push(t, rq_key(g_k.policy, &t->s));
    else g_k.ops->enqueue(g_k.ops_self, &t->s, now_cached_locked());
}
inline void sched_dequeue_locked(Tcb* t) {
    CHM_ASSERT_LOCKED();
    if (g_k.builtin) g_k.rq.remove(t);
    else g_k.ops->dequeue(g_k.ops_self, &t->s);
}
bool sched_reserve(std::size_t tasks);
// MUF's admit and retire, its key and its critical set: sched/muf.hpp.

// ---- wait queues (sync/waitq.cpp)
void waitq_insert_locked(WaitQueue* q, Tcb* t);
void waitq_unlink_locked(Tcb* t);  // `t` waits in a queue
// Take `t` out of the queue it waits in, if any (the check inline).
inline void waitq_remove_locked(Tcb* t) {
    if (t->wq) waitq_unlink_locked(t);
}
// Wake `t` from whatever it waits on with `result`.
void wake_locked(Tcb* t, int result);

// A scope holding the interrupt mask.
struct IrqGuard {
    IrqGuard() { port::irq_disable(); }
    ~IrqGuard() { port::irq_restore(); }
    IrqGuard(const IrqGuard&) = delete;
    IrqGuard& operator=(const IrqGuard&) = delete;
};

}  // namespace chm::kernel

#include "sched/readyq.inl"
