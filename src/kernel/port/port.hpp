// The port contract: everything the kernel needs from a processor and its
// host, and nothing more. The kernel includes only this header; each target
// folder (x86_64/, aarch64/, m68k/) supplies `arch.hpp` (inline pieces) and
// `switch.S` (the context switch), and posix/ supplies the timer, the clock,
// the interrupt mask and idle for every target that runs as a Linux process.
// template/ documents a new port entry by entry.
//
// Calling-context suffixes (see docs/architecture.md): none = task context,
// `_locked` = interrupt mask held, `_from_signal` = async-signal-safe.
#pragma once

#include <cstddef>
#include <cstdint>

#include "arch.hpp"  // resolved per target by the build: port/<arch>/arch.hpp

struct pollfd;

namespace chm::port {

// ---------------------------------------------------------------- contexts

// A suspended execution context. The only state kept outside the context's
// own stack is its stack pointer: a switch pushes the callee-saved registers
// and FP control state onto the outgoing stack and pops them from the
// incoming one.
struct Context {
    void* sp = nullptr;
};

// Prepare `ctx` so that the first context_switch() into it calls
// `entry(arg)` on the stack [stack_lo, stack_lo + size).
//
// Pre:  stack_lo is at least 16-byte aligned; size >= kMinStack.
// Post: ctx->sp points inside the stack; nothing below ctx->sp is touched.
//       On entry to `entry`, the stack pointer satisfies the ABI's alignment
//       at a function call (x86-64: rsp+8 ≡ 0 mod 16; aarch64: sp ≡ 0 mod 16;
//       m68k: sp ≡ 0 mod 4), the FP control state is the ABI default
//       (round-to-nearest, exceptions masked), and callee-saved registers hold
//       unspecified values. `entry` must never return: the kernel ends a task
//       by switching away from it for good.
void context_init(Context* ctx, void* stack_lo, std::size_t size,
                  void (*entry)(void*), void* arg);

// Minimum stack a context needs for the switch frame and the entry call.
inline constexpr std::size_t kMinStack = 1024;

}  // namespace chm::port

extern "C" {
// Save the running context's callee-saved registers and FP control state on
// its stack, store its stack pointer in *save_sp, load `load_sp` and resume
// the context found there (returning from its own call to chm_port_switch,
// or entering it for the first time).
//
// Pre:  `load_sp` was produced by context_init or by an earlier switch out of
//       that context, and that context is not running. Called in task or
//       kernel context with the interrupt mask held (the kernel never switches
//       from a signal handler).
// Post: returns when some other context switches back to the saved one; all
//       callee-saved integer and FP registers and the FP control state (x86-64:
//       MXCSR and x87 control word; aarch64: d8-d15 and FPCR; m68k: d2-d7,
//       a2-a6, fp2-fp7, FPCR) are as they were at the call.
void chm_port_switch(void** save_sp, void* load_sp);
}

namespace chm::port {

inline void context_switch(Context* from, Context* to) {
    chm_port_switch(&from->sp, to->sp);
}

// The same switch for a caller that makes every switch from one call site
// (the kernel's dispatcher): the incoming context resumes at the address
// the processor's return predictor expects, so a port may end it with a
// plain return. Frames are identical to chm_port_switch's; a port without
// its own version (CHM_PORT_HAS_SWITCH_SAME_SITE) uses chm_port_switch.
#if defined(CHM_PORT_HAS_SWITCH_SAME_SITE)
extern "C" void chm_port_switch_same_site(void** save_sp, void* load_sp);
inline void context_switch_same_site(Context* from, Context* to) {
    chm_port_switch_same_site(&from->sp, to->sp);
}
#else
inline void context_switch_same_site(Context* from, Context* to) { context_switch(from, to); }
#endif

// Call `fn()`, then return to the caller of the function that tail-calls
// this through an indirect jump instead of a return: for a kernel entry
// that switches tasks, whose return address is the incoming task's caller
// rather than the one the return predictor holds. A port without it
// (CHM_PORT_HAS_CALL_INDIRECT_RETURN) simply calls fn.
// The two-argument form returns fn's result.
using IndirectEntry2 = int (*)(void*, std::uintptr_t);
#if defined(CHM_PORT_HAS_CALL_INDIRECT_RETURN)
extern "C" void chm_port_call_indirect_return(void (*fn)());
extern "C" int chm_port_call2_indirect_return(IndirectEntry2 fn, void* a, std::uintptr_t b);
inline void call_indirect_return(void (*fn)()) { chm_port_call_indirect_return(fn); }
inline int call_indirect_return(IndirectEntry2 fn, void* a, std::uintptr_t b) {
    return chm_port_call2_indirect_return(fn, a, b);
}
#else
inline void call_indirect_return(void (*fn)()) { fn(); }
inline int call_indirect_return(IndirectEntry2 fn, void* a, std::uintptr_t b) { return fn(a, b); }
#endif

// Just before a switch to the task of slot `key`: make the branch history
// tell incoming tasks apart, so the indirect jump that returns to the
// incoming task's caller is predicted (x86_64/arch.hpp says why). A port
// without it (CHM_PORT_HAS_STEER_BRANCH_HISTORY) does nothing.
#if !defined(CHM_PORT_HAS_STEER_BRANCH_HISTORY)
inline void steer_branch_history(std::uint32_t) {}
#endif

// ------------------------------------------------------- test-and-set lock

// Atomically set the byte at `b` and report whether it was clear before:
// true means the caller now owns it. Full barrier: accesses after a
// successful tas() do not move before it. Works on memory shared between
// processes (the backplane) and between threads. Any context.
//   bool tas(volatile std::uint8_t* b);            -- in arch.hpp
// Clear a byte set by tas(), with release ordering. Any context.
//   void tas_clear(volatile std::uint8_t* b);      -- in arch.hpp
// Tell the processor we are in a spin-wait loop (pause / yield / nop).
//   void relax();                                  -- in arch.hpp

// ----------------------------------------------------------- the clock

// Monotonic time in nanoseconds since an arbitrary epoch fixed at process
// start (CLOCK_MONOTONIC). Never goes backwards. Any context, including a
// signal handler. It may trail or lead CLOCK_MONOTONIC by well under a
// microsecond (posix/clock.cpp: extrapolated with the cycle counter where
// the arch has one, CHM_PORT_HAS_CYCLE_COUNTER and cycle_counter() in
// arch.hpp). Inline (posix/clock_fast.hpp, included at the end).
//   std::uint64_t now_ns();
// CLOCK_MONOTONIC read now, and now_ns() continues from it: for judging
// timer expiries against the clock that fired them. Never trails
// CLOCK_MONOTONIC; since the thread's clock never goes back, it returns the
// thread's last reading instead when that one ran ahead (by well under a
// microsecond).
std::uint64_t now_exact_ns();
// Whether now_ns() extrapolates with the cycle counter in this process
// (decided at the first reading, which this makes if none was made yet;
// false for good once an interval missed the clock: posix/clock.cpp).
bool clock_extrapolates();
// Whether this process turned the counter off; then the interval that
// missed: by how much, and how long it was (either may be null).
bool clock_counter_dropped(std::uint64_t* miss_ns, std::uint64_t* span_ns);

// ------------------------------------------------------ the interrupt mask

// The cheap interrupt mask. On POSIX it is a per-process nesting count read
// by the timer signal handler, not a sigprocmask() call: while it is held,
// the handler only records that the tick is pending, and irq_restore() takes
// it when the count returns to zero. Task or kernel context.
struct IrqState {
    volatile std::uint32_t nest;     // > 0: interrupts masked
    volatile std::uint32_t pending;  // what arrived while masked: kPending* bits
};
extern IrqState g_irq;
inline constexpr std::uint32_t kPendingTick = 1;  // the timer signal
inline constexpr std::uint32_t kPendingRing = 2;  // doorbell vectors to dispatch
// Record `bits` as pending (mask held). Atomic against the timer handler,
// which may set its own bit in between on the same thread.
inline void irq_mark_pending(std::uint32_t bits) { __atomic_fetch_or(&g_irq.pending, bits, __ATOMIC_RELAXED); }
// Take (and clear) what is pending.
inline std::uint32_t irq_take_pending_bits() { return __atomic_exchange_n(&g_irq.pending, 0, __ATOMIC_RELAXED); }

// Called by irq_restore() (with the mask held once more) when something
// arrived while masked, with the kPending* bits that did. Installed by the
// kernel with irq_set_pending_hook().
using PendingHook = void (*)(std::uint32_t why);
void irq_set_pending_hook(PendingHook hook);
void irq_take_pending();  // slow path of irq_restore; out of line

// Always inlined: the allocator's lock hooks use it, and none of their
// code may lie outside the allocator's section (mem/mem_text.hpp).
__attribute__((always_inline)) inline void irq_disable() {
    g_irq.nest = g_irq.nest + 1;
    __atomic_signal_fence(__ATOMIC_SEQ_CST);
}

inline void irq_restore() {
    __atomic_signal_fence(__ATOMIC_SEQ_CST);
    const std::uint32_t n = g_irq.nest - 1;
    g_irq.nest = n;
    if (n == 0 && g_irq.pending) [[unlikely]]
        irq_take_pending();
}

inline bool irq_masked() { return g_irq.nest != 0; }

// Mask held once (nest 1) and something pending: leave it to the timer,
// which re-delivers it shortly (kPreemptRetryNs). Out of line; called
// with the mask held, so not preemptible wherever its code lies.
void irq_defer_pending_locked();

// Release the mask without ever switching here: a tick that arrived while it
// was held is re-delivered by the timer shortly instead (kPreemptRetryNs).
// For code that may run below C library frames (the malloc family called by
// libc itself, e.g. stdio allocating its buffer under the FILE lock): a
// switch there would let another task into the same libc lock. Inline, and
// the pending work done before the mask drops: after the last store only
// the caller's own code runs (the allocator's hooks are in its section;
// out of line, this function's return was preemptible code reached from a
// malloc that libc made: lost stdio lines under qemu-aarch64, 4 of 30 runs
// of CLibraryIsSafeUnderPreemption).
__attribute__((always_inline)) inline void irq_restore_no_switch() {
    if (g_irq.nest == 1 && g_irq.pending) irq_defer_pending_locked();
    __atomic_signal_fence(__ATOMIC_SEQ_CST);
    g_irq.nest = g_irq.nest - 1;
}

// ------------------------------------------------------------- the timer

// The timer handler the port calls, in signal context on the kernel thread's
// alternate signal stack, with the interrupt mask taken (nest == 1) and the
// interrupted PC already known to be preemptible. It runs the kernel's timer
// work and returns true when the interrupted task must give up the CPU.
using TickHandler = bool (*)(std::uint64_t now);

// Create the one POSIX timer of this process, directed at the calling thread
// (SIGEV_THREAD_ID), install the signal handler on an alternate signal stack
// and unblock the signal in the calling thread. Other threads never receive
// it from the timer; a copy sent to the process that reaches one is ignored.
// Returns 0 or -errno. Call once, on the kernel thread, before any timer_arm.
int timer_init(TickHandler handler);

// Arm the timer for absolute monotonic time `at_ns` (0 disarms); with
// `interval_ns`, it fires again every interval after that until re-armed
// (the kernel's guess of the next event: it then needs no system call to
// re-arm after the tick). Replaces any earlier setting. Task or kernel
// context, mask held.
void timer_arm_locked(std::uint64_t at_ns, std::uint64_t interval_ns = 0);
// The interval of the last arming (0: one-shot or disarmed). Read inline
// at every quantum's arming (kernel thread only).
inline std::uint64_t g_timer_interval = 0;
inline std::uint64_t timer_interval() { return g_timer_interval; }
// How many times timer_arm_locked set the timer (a system call each):
// tests check that a periodic set does not re-arm it at every cycle.
inline std::uint64_t g_timer_arms = 0;
inline std::uint64_t timer_arm_count() { return g_timer_arms; }

// Tear the timer down (process exit, tests).
void timer_fini();

// The timer signal number (a real-time signal).
int timer_signal();

// True on the kernel thread: the thread that called timer_init, or that the
// kernel named with set_kernel_thread (a virtual-clock kernel has no timer).
// Any context.
extern constinit __attribute__((tls_model("initial-exec"))) thread_local bool t_kernel_thread;
// Inline for the allocator's lock hooks (see irq_disable).
__attribute__((always_inline)) inline bool on_kernel_thread() { return t_kernel_thread; }
void set_kernel_thread(bool on);
// The kernel thread's process and thread ids, the target of a directed
// signal (a doorbell ring); tid 0 when no timer is live (virtual clock).
int kernel_pid();
int kernel_tid();

// Number of timer signals that reached a thread other than the kernel thread
// (they are ignored; a test proves this stays zero).
std::uint64_t stray_signal_count();

// Number of preemptions deferred because the task was outside preemptible
// code (statistics; the kernel reports it).
std::uint64_t deferred_preemption_count();

// ------------------------------------------------------------ preemption
//
// How a timer signal preempts a green thread without switching inside the
// handler: the handler (on the alternate stack) rewrites the interrupted
// context so that, after sigreturn, the interrupted task itself calls the
// kernel through a trampoline on its own stack, as if it had called
// chm_kernel's preempt entry at that instruction. Consequences, on purpose:
//  * no signal frame (~3.3 KB on x86-64) ever sits on a task stack;
//  * no task is ever first entered inside a handler, so none inherits the
//    handler's blocked signal mask (sigreturn restores it before the switch);
//  * the switch itself is the ordinary chm_port_switch, in task context.

// A port that implements this section defines CHM_PORT_HAS_PREEMPTION to 1
// in its arch.hpp and provides <arch>/preempt.cpp and <arch>/preempt.S; until
// then the kernel on that port switches only at kernel calls.

// The function the trampoline calls, with the interrupt mask held (nest == 1,
// set by the handler before it redirects). It returns, with the mask
// released, when the preempted task is scheduled again.
using PreemptHook = void (*)();
extern "C" __attribute__((visibility("hidden"))) PreemptHook chm_port_preempt_hook;

// Rewrite `ucontext` (the handler's third argument) so that the interrupted
// task, once the handler returns, runs chm_port_preempt_trampoline on its own
// stack: it saves every register (caller-saved and callee-saved integer
// registers, flags / condition codes, the full FP/SIMD state and its control
// and status registers), calls chm_port_preempt_hook, restores everything
// and resumes at the interrupted PC as if nothing happened.
//
// Pre:  signal context on the kernel thread; the interrupted PC is
//       preemptible (see below); the interrupted stack has room for the
//       trampoline's frame (kPreemptFrameMax bytes, the ABI's red zone
//       included) below its stack pointer: the timer handler checks this
//       against chm_port_preempt_floor_hook before it redirects.
// Post: only the ucontext is modified; nothing runs yet.
void redirect_to_preempt_from_signal(void* ucontext);

// Where the trampoline's frame may go: called by the timer handler (signal
// context, mask held) with the interrupted stack pointer before it
// redirects; returns the lowest address the frame and the hook's own calls
// may reach on that stack (0: a stack the kernel does not know, no check).
// When sp - kPreemptFrameMax falls below it, the task is not redirected:
// the handler reports it to the fault handler as a stack overflow
// (fault_no_room_from_signal, fault.hpp), so a task preempted near its
// guard page is aborted instead of faulting inside the trampoline with the
// mask held, which would fail-stop the whole RTPU. Installed by the kernel
// (err/fault.cpp).
using PreemptFloorHook = std::uintptr_t (*)(std::uintptr_t sp);
extern "C" __attribute__((visibility("hidden"))) PreemptFloorHook chm_port_preempt_floor_hook;

// The interrupted program counter and stack pointer of a signal's ucontext.
std::uintptr_t interrupted_pc_from_signal(const void* ucontext);
std::uintptr_t interrupted_sp_from_signal(const void* ucontext);

// Code ranges in which a task may be preempted. Outside them (the C
// library, the dynamic linker, any other shared object) a preemption is
// deferred: the tick is recorded as pending and retried after
// kPreemptRetryNs, so a task is never switched out while it holds a C
// library lock. By default the main executable's code is preemptible; the
// kernel adds each control program it loads. Task context, mask held.
int preemptible_range_add(std::uintptr_t lo, std::uintptr_t hi);
void preemptible_range_remove(std::uintptr_t lo, std::uintptr_t hi);
// Carve [lo, hi) out of every preemptible range (code that must never be
// preempted although it lives in the main program: the allocator, which
// libc calls with its own locks held).
int preemptible_range_exclude(std::uintptr_t lo, std::uintptr_t hi);
// Carve the PLT entries of the loaded object holding `addr` out of
// every preemptible range: the allocator's calls into the C library go
// through them where the compiler has no -fno-plt (m68k). Returns the
// number of PLT sections carved out, -ENOENT when no loaded object holds
// `addr`, -errno when its file cannot be read, -ENOEXEC when the file is
// not an ELF object of this class. Mask held.
int preemptible_exclude_plt(const void* addr);
bool preemptible_pc_from_signal(std::uintptr_t pc);
// Add (remove) every executable segment of the loaded object that contains
// `addr` (a control program, or libchimera.so itself). Returns the number
// of ranges, -ENOENT when no loaded object holds `addr`. Mask held.
int preemptible_object_add(const void* addr);
void preemptible_object_remove(const void* addr);
inline constexpr std::uint64_t kPreemptRetryNs = 20000;

// ------------------------------------------------------------- doorbell

// How other threads and processes interrupt an RTPU (its mailbox
// interrupts) and how it sleeps. Three 32-bit words, in the process's own
// memory by default, or in the backplane's RTPU entry so that other
// processes can ring them.
enum DoorbellState : std::uint32_t {
    kDbRunning = 0,     // running tasks: a ring sends the directed signal
    kDbSleeping = 1,    // in FUTEX_WAIT on `seq`: a ring wakes the futex
    kDbPolling = 2,     // spinning on `pending` before sleeping: nothing to do
    kDbSleepingFds = 3  // in ppoll on parked descriptors: a ring sends the signal
};
struct Doorbell {
    std::uint32_t* pending = nullptr;  // raised mailbox vectors, one bit each
    std::uint32_t* seq = nullptr;      // futex word, bumped by every ring and tick
    std::uint32_t* state = nullptr;    // DoorbellState
    // Published at every switch when present (a backplane doorbell): the
    // running task's id (0: none) and urgency (0: lowest), so a ring that
    // would not preempt it need not interrupt it (RingFor). Running 0: the
// kernel is between tasks (idle loop), where it looks at `pending` before
// it runs a task or sleeps.
    std::uint32_t* running = nullptr;  // kRunningUnknown until the kernel publishes
    std::uint32_t* urgency = nullptr;
    bool shared = false;               // a futex shared between processes
};

inline constexpr std::uint32_t kRunningUnknown = UINT32_MAX;

// What a ring is for, to decide whether a running RTPU must be interrupted:
// a ring for the task it runs now (that task looks at its word before it
// parks), or of urgency no higher than the running task's, sets the vector
// without a signal; the RTPU takes it at its next switch or tick. The
// default is an interrupt: vectors with handlers, and any doorbell that
// publishes nothing.
struct RingFor {
    std::uint32_t urgency = UINT32_MAX;
    std::uint32_t task = 0;  // the task the ring wakes (0: none in particular)
};
inline constexpr RingFor kRingInterrupt{};

// Make `db` this RTPU's doorbell (nullptr: back to the private default).
// Bits already pending in the old one move over. Kernel thread, mask held.
void doorbell_use(const Doorbell* db);
// This RTPU's doorbell, for publishing to others (read-only use).
const Doorbell& doorbell();
// Take the pending vectors (cleared). Any context on the kernel thread.
std::uint32_t doorbell_take();
// True when vectors are pending (not taken). Any context on the kernel thread.
bool doorbell_raised();
// Sends the directed timer signal to the kernel thread behind a doorbell;
// 0 when sent. A peer's goes through the backplane's identity check
// (ipc/backplane/member.cpp), never to a pid taken from shared memory.
using Interrupt = int (*)(void* ctx);
// This process's own kernel thread (ctx unused).
int interrupt_own_kernel(void* ctx);
// Raise `bits` on the RTPU behind `db` and wake it as its state requires
// (futex wake, `interrupt(ctx)`, or nothing while it polls). Any thread
// or process; async-signal-safe when `interrupt` is.
void doorbell_ring(const Doorbell& db, std::uint32_t bits, Interrupt interrupt, void* ctx,
                   RingFor why = kRingInterrupt);
// Publish what this RTPU runs now (the kernel's switch and scheduler, mask
// held): a no-op unless the doorbell has running/urgency words. When the
// published state may let a skipped ring matter (another task, or a lower
// urgency), or when nothing changed (the scheduler ran without a switch:
// some task's order may have), the doorbell's pending vectors are looked
// at, and kPendingRing marks them for the next irq_restore: no ring is
// left behind a switch or a change of order.
void doorbell_publish_locked(std::uint32_t running, std::uint32_t urgency);
inline bool g_db_publishes = false;  // the doorbell in use has those words
// How many rings carrying vectors this process made, and how many of them
// sent a directed signal (statistics).
std::uint32_t doorbell_rings_sent();
std::uint32_t doorbell_signals_sent();


// ------------------------------------------------------------------ idle

// Sleep until the timer fires or the doorbell rings, using no CPU after
// `poll_ns` of polling the doorbell (0: sleep at once). Called by the
// kernel's idle loop with the mask held and nothing ready; returns with the
// mask held. A ring or tick that happens between the caller's check and the
// sleep is not lost.
// `watch`, when given, is what else the poll looks at (the kernel's parked
// tasks' words): begin() before the poll and end() after it (before any
// sleep), each true when something woke; woken() in the poll loop.
struct IdleWatch {
    bool (*begin)();
    bool (*woken)();
    bool (*end)();
};
void idle_wait_locked(std::uint64_t poll_ns = 0, const IdleWatch* watch = nullptr);

// The idle wait ahead of a timer event (the kernel's timer lead), in two
// steps. idle_sleep_until_locked: poll the doorbell `poll_ns`, then sleep
// on it until `wake_ns` (now_ns()); kIdleTimedOut when that instant came
// with nothing else, kIdleWoken when a ring or tick came first.
// *woke_late: how long after `wake_ns` the sleep's own timeout woke the
// thread (the host's wake-up latency), or UINT64_MAX when it did not end
// by that timeout. idle_poll_until_locked: poll the doorbell until
// `due_ns`; kIdleDue when it came with nothing else (the caller runs the
// event itself), kIdleWoken when a ring or tick came first. Mask held.
enum IdleEnd { kIdleWoken, kIdleTimedOut, kIdleDue };
IdleEnd idle_sleep_until_locked(std::uint64_t poll_ns, std::uint64_t wake_ns, std::uint64_t* woke_late);
IdleEnd idle_poll_until_locked(std::uint64_t due_ns);

// idle_wait_locked() that also returns when one of `fds` is ready (their
// revents are filled in) or at `until_ns` (monotonic; 0 = no limit).
// Returns poll's count of ready descriptors, or 0 after a tick, a ring or
// the time limit. The timer signal is blocked from the check to the sleep
// and unblocked atomically by ppoll, so no tick is lost.
int idle_wait_fds_locked(struct pollfd* fds, unsigned long nfds, std::uint64_t until_ns);

// Ring this RTPU's own doorbell with no vector: any thread, signal handler.
void idle_wake();

}  // namespace chm::port

// ------------------------------------------------- processor exceptions
// (global error handling, err/) SIGSEGV/SIGBUS/SIGFPE/SIGILL of the kernel
// thread on the alternate signal stack, and redirecting a faulting context
// into a kernel entry: fault_init, fault_fini, on_fault_thread and, per
// target in <arch>/fault.cpp, redirect_to_call_from_signal. Documented
// entry by entry in fault.hpp.
#include "fault.hpp"

// now_ns(), inline (the clock section above).
#include "posix/clock_fast.hpp"
