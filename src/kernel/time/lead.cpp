// Timer lead: an idle RTPU wakes ahead of its next timer event and polls
// until the event is due, so a release starts on time rather than one
// host wake-up latency late (chm_kernel_config.timer_lead_ns; the design
// is in docs/architecture.md, "Timer lead").
//
// The host's timer wake-up latency on a virtual machine is tens of
// microseconds, on a loaded one more: a plain timer loop (timer_create +
// sigwaitinfo) starts its cycle that late. The idle loop knows the next
// event, so it sets the host timer for what follows the event, sleeps on
// the doorbell until `lead` before it (the futex's own timeout, the
// thread's timer slack set to 1 ns), then polls the doorbell until the
// event is due and runs it itself. Never early: the event runs only once
// the clock has reached it. Not led: events within lead + 20 µs or
// beyond 20 ms, and an RTPU whose waits rings end far more often than its
// events (lead_score).
//
// Automatic lead: the 75th percentile of the sleep's own wake-up lateness
// (how long after its timeout the thread ran), learnt online one sample
// per anticipated sleep (up by 3 steps when a wake came later than the
// lead, down by 1 when earlier: it settles where a quarter come later),
// between 0 and kLeadMaxAutoNs. Three wake-ups in four then come before
// the event; the polling costs the rest of the lead in CPU, per idle
// period that ends at a timer event.
#include "kernel.hpp"

namespace chm::kernel {

namespace {

constexpr std::uint64_t kLeadStartNs = 30'000;     // a first guess: typical of a virtual machine
// An event nearer than the lead and this is waited for as before (the
// host timer's tick): a timed sleep that short is not worth its system
// calls.
constexpr std::uint64_t kLeadMinSleepNs = 20'000;
// Nor is an event further off than this led: a timed sleep costs the host
// a timer reprogramming when it starts and when a ring ends it early, and
// an RTPU woken by messages every few microseconds while a timeout seconds
// away is pending (the backplane rows) would pay that at every message
// for nothing. 20 ms covers control loops of 50 Hz and faster.
constexpr std::uint64_t kLeadHorizonNs = 20'000'000;

}  // namespace

std::uint64_t timer_lead_locked() {
    if (g_k.cfg.virtual_clock || g_k.cfg.timer_lead_ns == 0) return 0;
    return g_k.cfg.timer_lead_ns > 0 ? std::uint64_t(g_k.cfg.timer_lead_ns) : g_k.lead_ns;
}

void timer_lead_reset_locked() {
    g_k.lead_ns = kLeadStartNs;
    g_k.lead_score = kLeadServed;
}

std::uint32_t lead_score_next(std::uint32_t score, bool served) {
    if (served) return score + kLeadServed < kLeadScoreMax ? score + kLeadServed : kLeadScoreMax;
    return score ? score - 1 : 0;
}

std::uint64_t lead_learn(std::uint64_t lead, std::uint64_t late) {
    if (late > lead) lead += 3 * kLeadStepNs;
    else if (lead >= kLeadStepNs) lead -= kLeadStepNs;
    return lead < kLeadMaxAutoNs ? lead : kLeadMaxAutoNs;
}

bool idle_lead_wait_locked(std::uint64_t now, std::uint64_t poll_ns) {
    const std::uint64_t lead = timer_lead_locked();
    if (!lead || g_k.current) return false;
    const std::uint64_t due = next_due_locked();
    if (!due || due <= now + lead + kLeadMinSleepNs || due > now + kLeadHorizonNs) return false;
    // An RTPU woken by rings far more often than by its timer events (a
    // message every few microseconds, a timeout 10 ms away) sleeps plainly:
    // for it the lead's two re-arms and timed sleep would come at every
    // message, for nothing (~0.4 µs a message here). lead_score counts up
    // by kLeadServed for each wait that ended at its event and down by 1
    // for each a ring ended; the plain sleep goes on observing.
    auto ticked = [] { return (port::g_irq.pending & port::kPendingTick) != 0; };
    if (g_k.lead_score == 0) {
        port::idle_wait_locked(poll_ns);
        g_k.lead_score = lead_score_next(g_k.lead_score, ticked());
        return true;
    }
    // The host timer must not fire for `due`: its signal, even to a thread
    // already awake and polling, costs more than the lead saves (~20 µs on
    // a virtual machine), and a sleep that oversleeps `due` is better woken
    // by its own timeout than by that signal. So it is set for what
    // follows (`due` and the events within kArmSlackNs of it are this
    // wait's): the next event the heap holds, or sooner what `due` itself
    // brings (a release brings its cycle's deadline), so that running
    // `due` finds the timer set already; the re-arm happens here, before
    // the sleep, not in front of the tasks the event releases. Cleared
    // when nothing follows.
    std::uint64_t after = g_k.timers.next_due_after<TimerHeap::kIdleLookBudget>(due + kArmSlackNs);
    if (const std::uint64_t gap = next_gap_guess_locked(due); gap && (!after || due + gap < after))
        after = due + gap;
    if (g_k.armed_at != after) {
        port::timer_arm_locked(after);
        g_k.armed_at = after;
    }
    std::uint64_t late;
    port::IdleEnd end = port::idle_sleep_until_locked(poll_ns, due - lead, &late);
    if (late != UINT64_MAX && g_k.cfg.timer_lead_ns < 0) g_k.lead_ns = lead_learn(g_k.lead_ns, late);
    if (end == port::kIdleTimedOut) end = port::idle_poll_until_locked(due);
    g_k.lead_score = lead_score_next(g_k.lead_score, end == port::kIdleDue || ticked());
    if (end == port::kIdleDue) {
        // The events due run here (the host timer, set for what follows,
        // has not fired); the timer stays as it is.
        ++g_k.lead_on_time;
        const std::uint64_t t = now_exact_locked();
        timers_run_locked(t);
        timer_program_locked(t);
    } else {
        // A ring (or a tick: the idle loop takes it next) came first:
        // `due` lies ahead with the timer set beyond it, so it is set for
        // the earliest event again before any task runs.
        timer_program_locked(now_exact_locked());
    }
    return true;
}

}  // namespace chm::kernel

extern "C" uint64_t chm_kernel_timer_lead(void) {
    return chm::kernel::g_k.initialised ? chm::kernel::timer_lead_locked() : 0;
}
