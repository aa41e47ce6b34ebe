/* The soak's servo controller (servo_main.c) after a restart: what a
 * killed incarnation left. Its modules run on on the RTPUs: found by
 * instance name (chm_servo_find, open to anyone) and kept. The switch it
 * was in (or whose outcome it had not yet checked), recorded in the ledger
 * before the call (sv->pend), is verified before anything else is switched:
 * the servo layer promises that a switch is done on every module it names
 * or on none (include/chimera/servo.h; docs/architecture.md: the parties
 * read the switch's decision cell at T, and one CAS decides between the
 * controller's COMMITTED and the first party's ABORTED), so once T has
 * passed (within SETTLE_NS) each module named is either switched (the one
 * going on ON, the one going off OFF, both switched since the call began)
 * or as before (state and switch instant). Anything else is a defect; so
 * is an outcome against what the call had returned before the kill. A
 * module gone (its RTPU died, or killed) or out of reach cannot be judged. */
#define _GNU_SOURCE
#include <chimera/err.h>
#include <errno.h>
#include <stdio.h>
#include <string.h>

#include "servo_ctl.h"

void adopt(role_t** all) {
    for (int i = 0; i < SOAK_MOD_ROLES; ++i) {
        role_t* m = all[i];
        begin(SOAK_SV_STATUS);
        const int r = chm_servo_find(m->rtpu, m->name, &m->id);
        end();
        if (r == 0) {
            m->have = 1;
            ++sv->adopted;
            fprintf(stderr, "soak servo: found %s on RTPU %d (index %d generation %u)\n", m->name, m->rtpu,
                    m->id.index, m->id.gen);
        } else if (r != -ENOENT && !transient(r)) {
            unexpected(r, "find", m->name);
        }
        /* Not found: spawned again once its RTPU is there (ensure). */
    }
}

void pend_begin(const role_t* off, const role_t* on) {
    soak_servo_pend_t* p = &sv->pend;
    ST(p->phase, 0u);
    const role_t* ms[2] = {off, on};
    for (int i = 0; i < 2; ++i) {
        const role_t* m = ms[i];
        p->role[i] = m ? (int32_t)m->index : -1;
        p->rtpu[i] = m ? m->id.rtpu : 0;
        p->index[i] = m ? m->id.index : 0;
        p->gen[i] = m ? m->id.gen : 0;
        p->state[i] = m ? m->st.state : 0;
        p->switched_at[i] = m ? m->st.switched_at_ns : 0;
    }
    p->r = 0;
    p->at_ns = 0;
    p->t_call = now_ns();
    ST(p->phase, 1u);
}

void pend_returned(int r, uint64_t at_ns) {
    sv->pend.r = r;
    sv->pend.at_ns = at_ns;
    ST(sv->pend.phase, 2u);
}

/* One module of the inherited switch: 1 switched, 0 as before, -1 neither
 * (yet), -2 gone or in ERROR, -3 out of reach; its state in `say`. */
static int judge(const soak_servo_pend_t* p, int i, char* say, size_t n) {
    const chm_servo_module_t id = {p->rtpu[i], p->index[i], p->gen[i]};
    chm_servo_status_t st;
    begin(SOAK_SV_STATUS);
    const int r = chm_servo_status(id, &st);
    end();
    if (r == -ESTALE) {
        snprintf(say, n, "module %d:%d gone (-ESTALE)", id.rtpu, id.index);
        return -2;
    }
    if (r) {
        if (!transient(r)) unexpected(r, "status", i ? "the module going on" : "the module going off");
        return -3;
    }
    static const char* const states[] = {"NONE", "OFF", "ON", "ERROR", "DEAD"};
    snprintf(say, n, "%s %s switched at %llu (before: %s at %llu)", st.name,
             st.state >= 0 && st.state <= CHM_SERVO_DEAD ? states[st.state] : "?",
             (unsigned long long)st.switched_at_ns, p->state[i] == CHM_SERVO_ON ? "ON" : "OFF",
             (unsigned long long)p->switched_at[i]);
    if (st.state != CHM_SERVO_ON && st.state != CHM_SERVO_OFF) return -2; /* DEAD, ERROR, NONE */
    const int want = i ? CHM_SERVO_ON : CHM_SERVO_OFF;
    if (st.state == want && st.switched_at_ns >= p->t_call) return 1;
    if (st.state == p->state[i] && st.switched_at_ns == p->switched_at[i]) return 0;
    return -1;
}

void verify_inherited(void) {
    soak_servo_pend_t p;
    memcpy(&p, &sv->pend, sizeof p);
    if (!LD(sv->pend.phase)) return;
    const char* where = p.phase == 1 ? "in the call" : p.r ? "refused" : "returned 0";
    fprintf(stderr, "soak servo: the killed controller left a switch %s (begun at %llu): verifying\n", where,
            (unsigned long long)p.t_call);
    const uint64_t until = now_ns() + SETTLE_NS;
    char say[2][200] = {"-", "-"};
    int verdict; /* 1 done, 0 nothing, -1 half, -2 cannot tell */
    for (;;) {
        int done = 0, same = 0, named = 0, gone = 0, unread = 0;
        for (int i = 0; i < 2; ++i) {
            if (p.role[i] < 0) continue;
            ++named;
            const int j = judge(&p, i, say[i], sizeof say[i]);
            done += j == 1, same += j == 0, gone += j == -2, unread += j == -3;
        }
        if (gone) verdict = -2;
        else if (done == named) verdict = 1;
        else if (same == named) verdict = 0;
        else if (now_ns() < until) {
            nap_ms(5);
            continue;
        } else verdict = unread ? -2 : -1;
        break;
    }
    if (verdict == 1 && p.phase == 2 && p.r) {
        defect("a switch refused (%d) before its controller was killed is done: %s; %s", p.r, say[0], say[1]);
    } else if (verdict == 0 && p.phase == 2 && !p.r) {
        defect("a switch that returned 0 (T %llu) before its controller was killed is done nowhere: %s; %s",
               (unsigned long long)p.at_ns, say[0], say[1]);
    } else if (verdict == -1) {
        defect("a switch its controller was killed %s is half done 10 s on: %s; %s", where, say[0], say[1]);
    }
    if (verdict == 1) ++sv->inherited_done;
    else if (verdict == 0) ++sv->inherited_nothing;
    else if (verdict == -2) ++sv->inherited_unverifiable;
    fprintf(stderr, "soak servo: the switch left %s: %s (%s; %s)\n", where,
            verdict == 1 ? "done everywhere" : verdict == 0 ? "done nowhere" : verdict == -2 ? "cannot tell" : "HALF DONE",
            say[0], say[1]);
    ST(sv->pend.phase, 0u);
}
