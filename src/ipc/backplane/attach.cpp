// A process's one attachment to a backplane: joining as RTPU n or as a
// host, leaving, the status snapshot. Taking a slot is one CAS on its
// status word (generation << 8 | state): FREE or DEAD (generation g) ->
// JOINING (g + 1), then the winner names itself (a CAS on the pid word,
// layout.hpp) and fills the slot, then JOINING -> RUNNING. A slot still
// held by a dead process is recovered first, so restarting an RTPU after
// kill -9 needs no cleanup.
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>

#include <pthread.h>
#include <sys/syscall.h>
#include <unistd.h>

#include "chimera/bp.h"
#include "ipc/backplane/backplane.hpp"
#include "ipc/backplane/stop_point.hpp"
#include "lib/nap.hpp"

namespace chm::bp {

namespace {

constexpr auto R = std::memory_order_relaxed;

Attachment g_att;
std::atomic<bool> g_attached{false};
std::atomic<std::uint32_t> g_attach_count{0};  // attachments made so far (attach_count)
pthread_mutex_t g_mu = PTHREAD_MUTEX_INITIALIZER;
pthread_once_t g_once = PTHREAD_ONCE_INIT;

// fork() pauses the monitor thread: the process is single-threaded at the
// fork (no recovery is in flight across it, and qemu-user 7.2 cannot
// create a thread in a child forked from a multithreaded process).
bool g_monitor_paused = false;
void before_fork() {
    if (!g_attached.load(R)) return;
    monitor_stop(/*before_fork=*/true);
    g_monitor_paused = true;
}
void after_fork_parent() {
    if (!g_monitor_paused) return;
    g_monitor_paused = false;
    monitor_start(&g_att);  // on failure lockers still find dead holders themselves
}

// A forked child does not inherit the attachment: the slot is the
// parent's, and the monitor thread does not exist in the child.
void after_fork_child() {
    g_monitor_paused = false;
    proc_after_fork_child();
    member_forget();
    if (!g_attached.load(R)) return;
    monitor_forget_after_fork();
    unmap(&g_att);
    if (g_att.fd >= 0) ::close(g_att.fd);
    std::free(g_att.local_refs);
    std::free(g_att.objects);
    g_att = Attachment{};
    g_attached.store(false, R);
    const pthread_mutex_t fresh = PTHREAD_MUTEX_INITIALIZER;  // the parent may have held it
    g_mu = fresh;
}
// A normal exit() without chm_bp_leave() still leaves cleanly (a crash
// or _exit is a death, recovered by the survivors).
void leave_at_exit() { (void)chm_bp_leave(); }
void register_atfork() {
    ::pthread_atfork(before_fork, after_fork_parent, after_fork_child);
    std::atexit(leave_at_exit);
}

// After the naming CAS: the slot is ours until we leave or die.
void fill_slot(RtpuEntry* e, SlotKind kind, const char* name) {
    // No kernel thread yet: a ring now must not send the timer signal to a
    // thread that has no handler for it (its default action kills). The
    // kernel publishes itself in ipc::wake_bind_kernel.
    e->tid.store(0, R);
    e->kind.store(std::uint32_t(kind), R);
    e->mailbox.store(0, R);
    e->pending.store(0, R);
    e->idle.store(0, R);
    e->urgency.store(0, R);
    e->running.store(0, R);
    e->poll_ns.store(0, R);
    e->heartbeat_ms.store(mono_ms(), R);
    e->joined_ms.store(mono_ms(), R);
    std::memset(e->name, 0, sizeof e->name);
    std::memcpy(e->name, name, std::strlen(name));
}

// Vacate a slot this process holds (status `gen`, state `from`): the pid
// word becomes the generation's vacancy before the slot is FREE, so a
// FREE slot never names a process (the next joiner's naming CAS expects a
// vacancy). The final CAS fails only when a judge recovered it meanwhile.
void vacate(RtpuEntry* e, std::uint32_t gen, SlotState from) {
    e->pid_start.store(0);
    e->pid.store(vacant_pid(gen), std::memory_order_release);
    std::uint32_t st = make_status(gen, from);
    e->status.compare_exchange_strong(st, make_status(gen, SlotState::Free), std::memory_order_acq_rel);
}

// Take slot s. `wait` = the caller asked for this very slot (an RTPU
// number): wait out a recovery in progress; a host just moves on.
//
// The identity is written only by the process that won the slot. Writing
// it before the status CAS (as layout 3 did) let a loser that stalled
// between its write and its CAS overwrite the winner's pid, and the
// winner was later "recovered" as dead when the loser exited. Now the
// status CAS comes first; the pid word stays a vacancy until the winner's
// naming CAS, which fails if a judge gave the unnamed joiner up meanwhile
// (a joiner stalled there for kUnnamedConfirmMs looks dead to everyone: it loses
// that generation and starts over, having written nothing).
int take_slot(const View& v, std::uint32_t s, SlotKind kind, const char* name, bool wait,
              std::uint32_t* gen_out) {
    RtpuEntry* e = v.rtpu(s);
    const std::uint32_t deadline = mono_ms() + 5000;
    auto busy_wait = [&]() -> int {  // someone else is recovering the slot
        if (!wait) return -EBUSY;
        if (std::int32_t(mono_ms() - deadline) > 0) return -ETIMEDOUT;
        nap_ms(1);
        return 0;
    };
    for (;;) {
        std::uint32_t st = e->status.load(std::memory_order_acquire);
        const std::uint32_t gen = status_gen(st);
        switch (status_state(st)) {
        case SlotState::Free:
        case SlotState::Dead: {
            const std::uint32_t ng = (gen + 1) & 0xFFFFFF ? (gen + 1) & 0xFFFFFF : 1;
            // The vacancy our naming CAS will expect, read while the slot is
            // FREE/DEAD g. A pid or the next generation's vacancy here is
            // not something this protocol leaves: a damaged file.
            std::uint32_t vacancy = e->pid.load(std::memory_order_acquire);
            if (pid_named(vacancy) || vacancy == vacant_pid(ng)) return -EBADMSG;
            CHM_STOP_POINT("bp.take_slot.before_cas");
            if (!e->status.compare_exchange_strong(st, make_status(ng, SlotState::Joining),
                                                   std::memory_order_acq_rel))
                continue;
            CHM_STOP_POINT("bp.take_slot.before_name");
            if (!e->pid.compare_exchange_strong(vacancy, std::uint32_t(::getpid()), std::memory_order_acq_rel))
                continue;  // given up as dead while we stalled: that generation is lost
            e->pid_start.store(self_start_time());
            fill_slot(e, kind, name);
            // A recoverer killed between its last step and clearing its word
            // left it behind; a live one's (about to clear it) stays.
            if (std::uint32_t w = e->recoverer.load(std::memory_order_acquire); w && !recoverer_alive(w))
                e->recoverer.compare_exchange_strong(w, 0, std::memory_order_acq_rel);
            std::uint32_t joining = make_status(ng, SlotState::Joining);
            if (!e->status.compare_exchange_strong(joining, make_status(ng, SlotState::Running),
                                                   std::memory_order_acq_rel))
                continue;  // recovered under us (a pid_start the judges misread): start over
            *gen_out = ng;
            return 0;
        }
        case SlotState::Joining: {
            // Named or not, its death is believed only when it lasts.
            const std::uint32_t p = e->pid.load(std::memory_order_acquire);
            if (pid_named(p) && !slot_holder_dead(v, s, st)) return -EBUSY;
            nap_ms(pid_named(p) ? kConfirmMs : kUnnamedConfirmMs);
            if (!joining_abandon(v, s, st, p)) continue;  // it named itself, or moved on
            if (!recover_slot(v, s, gen))
                if (int r = busy_wait()) return r;
            break;
        }
        case SlotState::Running:
        case SlotState::Leaving:
            if (!slot_holder_dead(v, s, st)) return -EBUSY;
            if (!recover_slot(v, s, gen))
                if (int r = busy_wait()) return r;
            break;
        case SlotState::Recovering:
            if (!slot_holder_dead(v, s, st) || !recover_slot(v, s, gen))
                if (int r = busy_wait()) return r;
            break;
        default:
            return -EBADMSG;  // not a state this layout writes
        }
    }
}

int attach(const char* path, int want, SlotKind kind, const char* name, int* slot_out) {
    char defpath[4096];
    if (int r = path_or_default(&path, defpath, sizeof defpath)) return r;
    if (std::strlen(path) >= sizeof g_att.path) return set_error("backplane path too long"), -ENAMETOOLONG;
    char autoname[kNameMax + 1];
    if (!name) {
        std::snprintf(autoname, sizeof autoname, kind == SlotKind::Host ? "host%d" : "rtpu%d", int(::getpid()));
        if (kind == SlotKind::Rtpu) std::snprintf(autoname, sizeof autoname, "rtpu%d", want);
        name = autoname;
    }
    if (std::strlen(name) > kNameMax) return set_error("backplane %s: name \"%s\" longer than %u", path, name, kNameMax), -ENAMETOOLONG;
    if (kind == SlotKind::Rtpu && want < 0) return set_error("backplane %s: RTPU %d out of range", path, want), -ECHRNG;

    ::pthread_once(&g_once, register_atfork);
    ::pthread_mutex_lock(&g_mu);
    if (g_attached.load(R)) {
        ::pthread_mutex_unlock(&g_mu);
        return set_error("this process is already attached to %s", g_att.path), -EBUSY;
    }
    Attachment& a = g_att;
    char why[768];
    int r = map_file(path, true, &a, &a.fd, why, sizeof why, true);
    if (r == 0 && (r = validate_structure(a, why, sizeof why)) != 0) {
        unmap(&a);
        ::close(a.fd);
        a = Attachment{};
    }
    if (r) {
        ::pthread_mutex_unlock(&g_mu);
        set_error("backplane %s: %s", path, why);
        return r;
    }
    std::uint32_t slot = 0, gen = 0;
    if (kind == SlotKind::Rtpu) {
        if (std::uint32_t(want) >= a.slots()) {
            r = -ECHRNG;
            set_error("backplane %s: RTPU %d out of range (slots 0..%u)", path, want, a.slots() - 1);
        } else {
            slot = std::uint32_t(want);
            r = take_slot(a, slot, kind, name, true, &gen);
            if (r == -EBUSY) set_error("backplane %s: RTPU %d belongs to live process %u", path, want, a.rtpu(slot)->pid.load(R));
            else if (r == -EBADMSG) set_error("backplane %s: RTPU %d: slot words inconsistent (damaged file)", path, want);
            else if (r) set_error("backplane %s: RTPU %d: recovery by another process did not finish", path, want);
        }
    } else {
        r = -ENOSPC;
        for (std::uint32_t s = a.slots() - 1; s >= 1 && r; --s) {
            if (take_slot(a, s, kind, name, false, &gen) == 0) {
                slot = s;
                r = 0;
            }
        }
        if (r) set_error("backplane %s: every slot belongs to a live process", path);
    }
    if (r == 0 && (r = validate_fresh_token(a, make_token(slot, gen), why, sizeof why)) != 0) {
        set_error("backplane %s: %s", path, why);
        vacate(a.rtpu(slot), gen, SlotState::Running);
    }
    if (r == 0) {
        a.slot = slot;
        a.gen = gen;
        a.token = make_token(slot, gen);
        a.kind = kind;
        std::strcpy(a.path, path);
        a.local_refs = static_cast<std::uint32_t*>(std::calloc(a.geo().registry_capacity, sizeof(std::uint32_t)));
        a.objects = static_cast<Attachment::OpenObject*>(std::calloc(a.geo().registry_capacity, sizeof(Attachment::OpenObject)));
        if (!a.local_refs || !a.objects) r = -ENOMEM;
        else if ((r = monitor_start(&a)) != 0) set_error("backplane %s: cannot start the monitor thread", path);
        if (r) {
            std::free(a.local_refs);
            std::free(a.objects);
            vacate(a.rtpu(slot), gen, SlotState::Running);
        }
    }
    if (r) {
        unmap(&a);
        ::close(a.fd);
        a = Attachment{};
    } else {
        g_attach_count.fetch_add(1, std::memory_order_relaxed);
        g_attached.store(true, std::memory_order_release);
        if (slot_out) *slot_out = int(slot);
    }
    ::pthread_mutex_unlock(&g_mu);
    return r;
}

}  // namespace

Attachment* current() { return g_attached.load(std::memory_order_acquire) ? &g_att : nullptr; }

Attachment* need_attachment(const char* fn) {
    Attachment* a = current();
    if (!a && fn) set_error("%s: not attached to a backplane (chm_bp_join / chm_bp_attach_host first)", fn);
    else if (!a) set_error("not attached to a backplane (chm_bp_join / chm_bp_attach_host first)");
    return a;
}

int lock_registry(Attachment* a, const char* fn) {
    const int r = registry_lock(*a, a->token);
    if (r && fn) set_error("%s: backplane %s: registry lock: a live holder kept it past the bound", fn, a->path);
    else if (r) set_error("backplane %s: registry lock: a live holder kept it past the bound", a->path);
    return r;
}

std::uint32_t attach_count() { return g_attach_count.load(std::memory_order_relaxed); }

}  // namespace chm::bp

using namespace chm::bp;

extern "C" {

int chm_bp_join(const char* path, int rtpu, const char* name) {
    return attach(path, rtpu, SlotKind::Rtpu, name, nullptr);
}

int chm_bp_attach_host(const char* path, const char* name, int* slot_out) {
    return attach(path, -1, SlotKind::Host, name, slot_out);
}

int chm_bp_leave(void) {
    ::pthread_mutex_lock(&g_mu);
    if (!g_attached.load(R)) {
        ::pthread_mutex_unlock(&g_mu);
        return -ENOTCONN;
    }
    Attachment& a = g_att;
    monitor_stop();
    RtpuEntry* e = a.rtpu(a.slot);
    std::uint32_t st = make_status(a.gen, SlotState::Running);
    // Not ours any more only if it was (wrongly) recovered meanwhile: then
    // its words belong to that recovery or a later generation.
    const bool ours = e->status.compare_exchange_strong(st, make_status(a.gen, SlotState::Leaving),
                                                        std::memory_order_acq_rel);
    // Withdraw the waiter records of tasks and threads still parked in a
    // backplane wait (an RTPU stopped under them), then drop every
    // attachment of this slot (ours and any left over). All of it within
    // one bound: a live process stalled holding the registry or an object
    // lock costs a leave (an exit) at most kInternalTimeoutNs; what was
    // not withdrawn then names a vacated generation (docs/backplane.md,
    // "Every wait and its bound", says who purges it).
    const WaitBound bound(kInternalTimeoutNs);
    if (registry_lock(a, a.token) == 0) {
        withdraw_departing(a, a.slot, a.gen, a.token);
        for (std::uint32_t i = 0; i < a.geo().registry_capacity; ++i)
            if (a.entry(i)->attached.load(R) & (1u << a.slot)) registry_detach_locked(a, i, a.slot, a.token);
        registry_unlock(a);
    }
    if (ours) {
        e->tid.store(0, R);
        e->idle.store(0, R);
        vacate(e, a.gen, SlotState::Leaving);
    }
    g_attached.store(false, std::memory_order_release);
    member_forget();  // verdicts about this file's members
    unmap(&a);
    ::close(a.fd);
    std::free(a.local_refs);
    std::free(a.objects);
    a = Attachment{};
    ::pthread_mutex_unlock(&g_mu);
    return 0;
}

int chm_bp_self(void) {
    const Attachment* a = current();
    return a ? int(a->slot) : -ENOTCONN;
}

int chm_bp_status(chm_bp_status_t* out) {
    if (!out) return -EINVAL;
    const Attachment* a = current();
    if (!a) return -ENOTCONN;
    std::memset(out, 0, sizeof *out);
    const Header* h = a->hdr();
    out->slots = a->geo().rtpu_slots;
    out->self = int32_t(a->slot);
    out->created_ns = h->created_ns;
    out->file_size = a->size;
    out->registry_capacity = a->geo().registry_capacity;
    for (std::uint32_t i = 0; i < a->geo().registry_capacity; ++i)
        if (a->entry(i)->state.load(R) == std::uint32_t(EntryState::Live)) ++out->objects;
    out->common_size = a->geo().common_size;
    out->common_free = arena_free_bytes(*a, a->common_arena());
    out->recoveries = h->recoveries.load(R);
    const std::uint32_t now = mono_ms();
    for (std::uint32_t s = 0; s < out->slots; ++s) {
        const RtpuEntry* e = a->rtpu(s);
        chm_bp_slot_info_t& o = out->slot[s];
        const std::uint32_t st = e->status.load(std::memory_order_acquire);
        o.state = chm_bp_slot_state(status_state(st));
        o.generation = status_gen(st);
        o.kind = chm_bp_slot_kind(e->kind.load(R));
        const std::uint32_t pid = e->pid.load(R);
        o.pid = pid_named(pid) ? int32_t(pid) : 0;  // a vacancy is no process
        o.tid = int32_t(e->tid.load(R));
        const std::uint32_t hb = e->heartbeat_ms.load(R);
        o.heartbeat_age_ms = hb ? now - hb : 0;
        std::memcpy(o.name, e->name, sizeof o.name);
        o.name[CHM_BP_NAME_MAX] = 0;
    }
    return 0;
}

}  // extern "C"
