/* chimera-soak-servo: the chaos soak's servo controller (docs/backplane.md,
 * "Chaos soak"; modlog.h). A host process (killed and stopped by the chaos
 * too, below); while the driver kills, stops and restarts RTPUs 1..3 it
 * keeps modules on them and switches them, through the public servo API
 * only:
 *   - A (RTPU 1) and B (RTPU 2) write soak.hand; one of them is kept ON and
 *     the variable is handed from it to the other at every step;
 *   - S (RTPU 3) writes soak.solo and is switched on and off alone.
 * A module whose RTPU died is found DEAD (or gone) and spawned again once
 * the RTPU is back (control taken again: a new RTPU process has no
 * controller). After every switch it checks the outcome on every module it
 * can still reach: a switch that returned 0 happened on each (the module
 * going on is ON, the one going off OFF, both switched at or after the
 * instant T), and a refused one on none (each state and switch instant as
 * before). Every call's duration is kept: a dead RTPU must not hang it.
 * The chaos kills and stops this process too (the driver starts the next
 * incarnation, sv->inc): each one carries on from the ledger (counters,
 * the last defect), finds the modules still there by their instance names,
 * first verifies the switch a killed predecessor was in or had not checked
 * (sv->pend: done on every module it named, or on none, once the servo
 * protocol's instant T has passed) and takes its RTPUs again: control held
 * by a dead process must be given up (a take refused as held is a
 * defect). See servo_inherit.c.
 * argv: BACKPLANE LEDGER HAND_MODULE SOLO_MODULE SEED. Exit 0 after quit. */
#define _GNU_SOURCE /* clock_gettime, nanosleep, O_CLOEXEC under -std=c11 */
#include <chimera/bp.h>
#include <chimera/err.h>
#include <chimera/servo.h>
#include <chimera/svar.h>
#include <errno.h>
#include <fcntl.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include "servo_ctl.h"

soak_servo_t* sv;
uint32_t inc; /* this incarnation */
static uint64_t busy_since; /* the first of the refusals as busy in a row, 0 none */
static int controlled[SOAK_MOD_ROLES + 1];
static int taken_before[SOAK_MOD_ROLES + 1];     /* this incarnation took RTPU n once */
static unsigned take_refused_run[SOAK_MOD_ROLES + 1]; /* takes of RTPU n refused as held in a row */
static uint64_t rng, call_t0;

uint64_t now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000ull + (uint64_t)ts.tv_nsec;
}

void nap_ms(unsigned ms) {
    struct timespec ts = {(time_t)(ms / 1000u), (long)(ms % 1000u) * 1000000L};
    nanosleep(&ts, NULL);
}

static uint64_t rnd(void) {
    rng ^= rng >> 12;
    rng ^= rng << 25;
    rng ^= rng >> 27;
    return rng * 2685821657736338717ull;
}

void begin(uint32_t call) {
    ST(sv->call, call);
    call_t0 = now_ns();
}

/* The call ended: its duration, and the heartbeat. */
uint64_t end(void) {
    const uint64_t d = now_ns() - call_t0;
    ++sv->calls;
    if (d > sv->worst_call_ns) {
        sv->worst_call_ns = d;
        sv->worst_call = sv->call;
    }
    ST(sv->call, (uint32_t)SOAK_SV_IDLE);
    ST(sv->hb_ns, now_ns());
    return d;
}

/* Counted first, then described, with sv->noting set meanwhile: a kill in
 * between leaves the count right and the driver told that the text may be
 * the one before (it reads noting after the kill). */
void unexpected(int r, const char* what, const char* name) {
    ST(sv->noting, 1u);
    ST(sv->errors, sv->errors + 1);
    sv->last_err = r;
    snprintf(sv->last_err_text, sizeof sv->last_err_text, "%s %s: %d %s", what, name, r, chm_err_last());
    ST(sv->noting, 0u);
    fprintf(stderr, "soak servo: unexpected: %s\n", sv->last_err_text);
}

void defect(const char* fmt, ...) {
    ST(sv->noting, 1u);
    ST(sv->defects, sv->defects + 1);
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(sv->last_defect, sizeof sv->last_defect, fmt, ap);
    va_end(ap);
    ST(sv->noting, 0u);
    fprintf(stderr, "soak servo: DEFECT (incarnation %u): %s\n", inc, sv->last_defect);
}

/* The RTPU (or the module) is gone, restarted under us, stopped past the
 * express-mail bound or its ring full: try again later. */
int transient(int r) {
    return r == -EHOSTDOWN || r == -ESTALE || r == -EPERM || r == -ETIMEDOUT || r == -EBUSY;
}

static void lost(role_t* m) {
    m->have = 0;
    controlled[m->rtpu] = 0; /* a restarted RTPU has no controller */
}

/* Read m's status; 1 with m->st filled, 0 when gone (counted) or unknown. */
int refresh(role_t* m) {
    if (!m->have) return 0;
    chm_servo_status_t st;
    begin(SOAK_SV_STATUS);
    const int r = chm_servo_status(m->id, &st);
    const uint64_t d = end();
    if (r == 0 && st.state != CHM_SERVO_DEAD && st.state != CHM_SERVO_NONE) {
        m->st = st;
        if (st.state == CHM_SERVO_ERROR) { /* report and get out of it (clear is open to the controller) */
            ++sv->errors_cleared;
            fprintf(stderr, "soak servo: %s in ERROR: %s\n", m->name, st.last_error);
            begin(SOAK_SV_SWITCH);
            const int c = chm_servo_clear(m->id);
            end();
            if (c && !transient(c)) unexpected(c, "clear", m->name);
            return 0;
        }
        return 1;
    }
    if (r == 0 || r == -ESTALE) { /* DEAD (its RTPU died or left), or a new RTPU without it */
        ++sv->dead_seen;
        if (d > sv->dead_seen_worst_ns) sv->dead_seen_worst_ns = d;
        lost(m);
        return 0;
    }
    if (r == -EPERM) controlled[m->rtpu] = 0;
    else if (!transient(r)) unexpected(r, "status", m->name);
    return 0;
}

/* Take control of RTPU n; 1 when this process holds it. The only other
 * controller these RTPUs have had is an incarnation of this one that the
 * driver killed and reaped before it started this one: a take refused as
 * held ("controlled by", the holder's slot) means a dead process's control
 * was not given up. A defect at once (each run of refusals once): an RTPU
 * restarted meanwhile would hide it, and RTPUs restart every few seconds. */
static int take_rtpu(int n, const char* name) {
    begin(SOAK_SV_TAKE);
    const int r = chm_servo_take(1u << n);
    end();
    if (r == 0) {
        controlled[n] = 1;
        ++sv->takes;
        if (inc > 1 && !taken_before[n]) ++sv->takes_after_restart;
        taken_before[n] = 1;
        take_refused_run[n] = 0;
        return 1;
    }
    if (r == -EBUSY && strstr(chm_err_last(), "controlled by")) {
        ++sv->take_refused;
        if (!take_refused_run[n]++)
            defect("incarnation %u: RTPU %d refused control as held, and no controller but dead ones was ever "
                   "there: %s", inc, n, chm_err_last());
        return 0;
    }
    if (!transient(r)) unexpected(r, "take", name);
    return 0;
}

/* Take m's RTPU if needed and spawn m there, OFF. */
static void ensure(role_t* m) {
    if (m->have) return;
    if (!controlled[m->rtpu] && !take_rtpu(m->rtpu, m->name)) return;
    chm_servo_spawn_t s;
    chm_servo_spawn_init(&s);
    s.rtpu = m->rtpu;
    s.path = m->path;
    s.name = m->name;
    s.period_ns = SOAK_MOD_PERIOD_NS;
    s.priority = 5;
    const char* pn[] = {"role"};
    const double pv[] = {(double)m->index};
    s.n_params = 1;
    s.param_names = pn;
    s.param_values = pv;
    begin(SOAK_SV_SPAWN);
    int r = chm_servo_spawn(&s, &m->id);
    end();
    if (r == -EEXIST) { /* spawned by a call whose reply was lost: find it */
        begin(SOAK_SV_STATUS);
        r = chm_servo_find(m->rtpu, m->name, &m->id);
        end();
    }
    if (r == 0) {
        m->have = 1;
        ++sv->spawns;
        (void)refresh(m);
        return;
    }
    if (r == -EPERM) controlled[m->rtpu] = 0;
    else if (!transient(r) && r != -ENOENT) unexpected(r, "spawn", m->name);
}

/* After a switch that returned 0 at instant T: the module going on is ON
 * and the one going off OFF, each switched at or after T (its first
 * release from T on), checked once T has passed; a module that died
 * meanwhile, or one that stays out of reach, cannot be judged. */
static void check_done(role_t* off, role_t* on, uint64_t t) {
    while (now_ns() < t + 3 * SOAK_MOD_PERIOD_NS) nap_ms(1);
    role_t* ms[2] = {off, on};
    for (int i = 0; i < 2; ++i) {
        role_t* m = ms[i];
        if (!m) continue;
        const int want = m == on ? CHM_SERVO_ON : CHM_SERVO_OFF;
        const uint64_t until = now_ns() + 4000000000ull; /* a stopped RTPU runs again within 1 s */
        int seen = 0, read = 0;
        while (now_ns() < until) {
            if (!(read = refresh(m))) break; /* gone, in ERROR or out of reach: cannot judge */
            if ((seen = m->st.state == want && m->st.switched_at_ns >= t)) break;
            nap_ms(5);
        }
        if (seen) continue;
        if (!read) {
            ++sv->unverifiable;
            return;
        }
        defect("switch at %llu returned 0, but %s is %s, switched at %llu", (unsigned long long)t, m->name,
               m->st.state == CHM_SERVO_ON ? "ON" : "OFF", (unsigned long long)m->st.switched_at_ns);
        return;
    }
    ++sv->checked_done;
}

/* After a refused switch: every module it named that can still be read is
 * as it was (state and switch instant). */
static void check_nothing(role_t* off, role_t* on, const chm_servo_status_t* before_off,
                          const chm_servo_status_t* before_on) {
    role_t* ms[2] = {off, on};
    const chm_servo_status_t* was[2] = {before_off, before_on};
    int judged = 0;
    for (int i = 0; i < 2; ++i) {
        role_t* m = ms[i];
        if (!m || !refresh(m)) continue;
        /* A module armed by the refused switch whose resolve it missed shows
         * ON until T (SETTLE_NS), then is as before. */
        const uint64_t until = now_ns() + SETTLE_NS;
        int same = 0, read = 1;
        while (!(same = m->st.state == was[i]->state && m->st.switched_at_ns == was[i]->switched_at_ns) &&
               now_ns() < until) {
            nap_ms(5);
            if (!(read = refresh(m))) break;
        }
        if (!read) continue;
        ++judged;
        if (!same)
            defect("a refused switch changed %s: state %d -> %d, switched at %llu -> %llu", m->name, was[i]->state,
                   m->st.state, (unsigned long long)was[i]->switched_at_ns,
                   (unsigned long long)m->st.switched_at_ns);
    }
    if (judged) ++sv->checked_nothing;
    else ++sv->unverifiable;
}

/* One switch: `off` going off and/or `on` going on; its outcome checked. */
static void do_switch(role_t* off, role_t* on, uint64_t* kind) {
    chm_servo_status_t b_off = off ? off->st : (chm_servo_status_t){0};
    chm_servo_status_t b_on = on ? on->st : (chm_servo_status_t){0};
    uint64_t t = 0;
    pend_begin(off, on);
    begin(SOAK_SV_SWITCH);
    const int r = chm_servo_switch(off ? &off->id : NULL, off ? 1 : 0, on ? &on->id : NULL, on ? 1 : 0, 0, &t);
    end();
    pend_returned(r, t);
    fprintf(stderr, "switch off %s on %s: %d at %llu (now %llu)\n", off ? off->name : "-", on ? on->name : "-", r,
            (unsigned long long)t, (unsigned long long)now_ns());
    if (r == 0) {
        ++*kind;
        ST(sv->switched_inc, inc);
        busy_since = 0;
        check_done(off, on, t);
        ST(sv->pend.phase, 0u);
        return;
    }
    if (r != -EALREADY && r != -EBUSY) busy_since = 0;
    if (r == -ETIME) ++sv->refused_late; /* a commit came too late: nothing switched anywhere */
    else if (r == -EALREADY || r == -EBUSY) {
        /* A module still finishing its last switch, or a ring full: brief.
         * Refused so for 10 s in a row, a module is stuck. */
        ++sv->refused_busy;
        if (!busy_since) busy_since = now_ns();
        else if (now_ns() - busy_since > 10000000000ull) {
            defect("switches refused as busy for 10 s in a row, the last: %d %s", r, chm_err_last());
            busy_since = 0;
        }
    }
    else if (transient(r)) ++sv->refused_gone;
    else {
        unexpected(r, "switch", on ? on->name : off->name);
        ST(sv->pend.phase, 0u);
        return;
    }
    if (r == -EPERM) controlled[(off ? off : on)->rtpu] = 0, controlled[(on ? on : off)->rtpu] = 0;
    check_nothing(off, on, &b_off, &b_on);
    ST(sv->pend.phase, 0u);
}

/* soak.hand must always be one whole value. */
static void read_hand(void) {
    double v[SOAK_HAND_ELEMS];
    if (chm_svar_get("soak.hand", v, sizeof v) != 0) return; /* -EAGAIN: read again next time */
    ++sv->hand_reads;
    for (int i = 1; i < SOAK_HAND_ELEMS; ++i)
        if (v[i] != v[0]) {
            ++sv->hand_torn;
            defect("soak.hand torn: %.0f and %.0f", v[0], v[i]);
            return;
        }
}

/* A and B both ON by their statuses: legitimate only for a while (above,
 * or a handed-over module that has not yet run a release from the other's
 * instant on); one must go OFF within SETTLE_NS while both stay readable.
 * Whether two ran the same cycle is the cycle log's to say (modlog.h). */
static void settle_both_on(role_t* a, role_t* b) {
    const uint64_t t0 = now_ns(), until = t0 + SETTLE_NS;
    fprintf(stderr, "A and B both ON: A switched at %llu, %llu cycles; B switched at %llu, %llu cycles; now %llu\n",
            (unsigned long long)a->st.switched_at_ns, (unsigned long long)a->st.cycles,
            (unsigned long long)b->st.switched_at_ns, (unsigned long long)b->st.cycles, (unsigned long long)t0);
    while (now_ns() < until) {
        nap_ms(5);
        const int ra = refresh(a), rb = refresh(b);
        if (!a->have || !b->have) return; /* one died: its cycles stop with it */
        if (!ra || !rb) continue;         /* out of reach for now: ask again */
        if (a->st.state == CHM_SERVO_ON && b->st.state == CHM_SERVO_ON) continue;
        ++sv->both_on_settled;
        fprintf(stderr, "  settled after %llu ms: %s OFF\n", (unsigned long long)((now_ns() - t0) / 1000000u),
                a->st.state == CHM_SERVO_ON ? b->name : a->name);
        return;
    }
    defect("A and B both ON for 10 s: two writers of soak.hand (A switched at %llu, %llu cycles; B switched at "
           "%llu, %llu cycles)",
           (unsigned long long)a->st.switched_at_ns, (unsigned long long)a->st.cycles,
           (unsigned long long)b->st.switched_at_ns, (unsigned long long)b->st.cycles);
}

static void step(role_t* a, role_t* b, role_t* s) {
    role_t* all[3] = {a, b, s};
    for (int i = 0; i < 3; ++i) {
        (void)refresh(all[i]);
        /* A module found by name (or one whose RTPU a status said is not
         * ours any more): control taken again first. */
        if (all[i]->have && !controlled[all[i]->rtpu]) (void)take_rtpu(all[i]->rtpu, all[i]->name);
        ensure(all[i]);
    }
    const int a_on = a->have && a->st.state == CHM_SERVO_ON, b_on = b->have && b->st.state == CHM_SERVO_ON;
    const int a_off = a->have && a->st.state == CHM_SERVO_OFF, b_off = b->have && b->st.state == CHM_SERVO_OFF;
    if (a_on && b_on) settle_both_on(a, b);
    else if (a_on && b_off) do_switch(a, b, &sv->handovers);
    else if (b_on && a_off) do_switch(b, a, &sv->handovers);
    else if (!a_on && !b_on && (a_off || b_off)) do_switch(NULL, a_off ? a : b, &sv->first_on);
    if (s->have && rnd() % 2) {
        if (s->st.state == CHM_SERVO_ON) do_switch(s, NULL, &sv->solo_switches);
        else if (s->st.state == CHM_SERVO_OFF) do_switch(NULL, s, &sv->solo_switches);
    }
    read_hand();
}

/* The end: every module off and killed, control given back. */
static void wind_up(role_t** all) {
    for (int i = 0; i < SOAK_MOD_ROLES; ++i) {
        role_t* m = all[i];
        const uint64_t until = now_ns() + 10000000000ull;
        while (refresh(m) && m->st.state == CHM_SERVO_ON && now_ns() < until) {
            begin(SOAK_SV_SWITCH);
            const int r = chm_servo_off(m->id);
            end();
            if (r == 0) break;
            nap_ms(5);
        }
        if (!m->have) continue;
        begin(SOAK_SV_KILL);
        const int r = chm_servo_kill(m->id);
        end();
        if (r == 0) ++sv->kills;
        else if (!transient(r)) unexpected(r, "kill", m->name);
        m->have = 0;
    }
    for (int n = 1; n <= SOAK_MOD_ROLES; ++n)
        if (controlled[n] && chm_servo_release(1u << n) != 0) {
            /* its RTPU is stopping or gone: nothing to give back */
        }
}

int main(int argc, char** argv) {
    if (argc != 6) {
        fprintf(stderr, "usage: chimera-soak-servo BACKPLANE LEDGER HAND_MODULE SOLO_MODULE SEED\n");
        return 2;
    }
    const int fd = open(argv[2], O_RDWR | O_CLOEXEC);
    void* map = fd < 0 ? MAP_FAILED : mmap(NULL, SOAK_LEDGER_SIZE, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    if (fd >= 0) close(fd);
    if (map == MAP_FAILED) return fprintf(stderr, "chimera-soak-servo: %s: %s\n", argv[2], strerror(errno)), 1;
    if (((soak_ledger_t*)map)->layout != sizeof(soak_ledger_t))
        return fprintf(stderr, "chimera-soak-servo: ledger layout %u bytes, this build %zu: rebuild\n",
                       ((soak_ledger_t*)map)->layout, sizeof(soak_ledger_t)), 1;
    sv = &((soak_ledger_t*)map)->servo;
    inc = LD(sv->inc);
    rng = ((strtoull(argv[5], NULL, 10) + 0x5851F42D4C957F2Dull * (inc - 1u)) * 0x9E3779B97F4A7C15ull) | 1u;
    fprintf(stderr, "soak servo: incarnation %u starts (pid %d)\n", inc, (int)getpid());
    int r = chm_bp_attach_host(argv[1], "soak-servo", NULL);
    if (r) return fprintf(stderr, "chimera-soak-servo: attach %s: %d %s\n", argv[1], r, chm_bp_last_error()), 1;
    role_t a = {.name = "soakA", .rtpu = 1, .index = 0, .path = argv[3]};
    role_t b = {.name = "soakB", .rtpu = 2, .index = 1, .path = argv[3]};
    role_t s = {.name = "soakS", .rtpu = 3, .index = 2, .path = argv[4]};
    role_t* all[SOAK_MOD_ROLES] = {&a, &b, &s};
    adopt(all);            /* the modules a killed predecessor left */
    verify_inherited();    /* and the switch it was in */
    ST(sv->hb_ns, now_ns());
    ST(sv->started, inc);
    while (!LD(sv->quit)) {
        step(&a, &b, &s);
        nap_ms((unsigned)(20 + rnd() % 80));
    }
    wind_up(all);
    ST(sv->done, inc);
    r = chm_bp_leave();
    if (r) fprintf(stderr, "chimera-soak-servo: leave: %d %s\n", r, chm_bp_last_error());
    return r ? 1 : 0;
}
