/* chimera-arm-job: the pick-and-place demo's job program, a host process.
 * It reads the system's layout (system.toml: the state variables, which
 * module runs on which RTPU at what rate), declares the variables, takes
 * control of the RTPUs the file names, spawns the modules and runs the
 * phases, switching the module set live at one cycle boundary each time:
 *   start     on: arm_io gravity traj joint_pd gripper (jaws open)
 *   approach  free motion to 8 cm above the object
 *   pick      joint_pd -> force_ctl: press on the object with 5 N; close
 *             the jaws until they squeeze it with 10 N
 *   move      force_ctl gripper -> joint_pd: lift, carry to above the target
 *   place     joint_pd -> force_ctl gripper: press it down, open the jaws
 *   retreat   force_ctl gripper -> joint_pd: lift away
 * Then it checks the outcome: the object rests on the surface within the
 * tolerance of its target and no critical module missed a deadline. Exit
 * status 0 when both hold, 1 otherwise (the reason printed), 2 bad usage. */
#include <chimera/bp.h>
#include <chimera/err.h>
#include <chimera/servo.h>
#include <chimera/svar.h>
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "demo.h"

static chm_servo_system_t* g_sys;
static chm_servo_module_t g_mod[M_COUNT]; /* the phases' modules, by demo.h index */
static uint64_t g_period_ns;              /* the fastest module's: a switch's cost is in its cycles */
static double g_timeout_s = 60;
static uint64_t g_deadline_ns; /* the whole job's */
static chm_svar_set_t* g_set;
static int32_t* g_phase;
static double* g_sw; /* DEMO_SW_MAX x 4 */
static int g_nsw;

static uint64_t now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

static void nap_ms(int ms) {
    struct timespec ts = {ms / 1000, (long)(ms % 1000) * 1000000L};
    nanosleep(&ts, NULL);
}

static double get1(const char* name, int i) {
    double v[4] = {0};
    if (chm_svar_get(name, v, sizeof v) != 0) return NAN;
    return v[i];
}

static void publish(void) {
    if (chm_svar_set_write(g_set) != 0) fprintf(stderr, "job: publishing: %s\n", chm_bp_last_error());
}

static void set_phase(int p) {
    *g_phase = p;
    publish();
    printf("job: phase %s\n", demo_phase_name(p));
    fflush(stdout);
}

/* Module i of the system file, when spawned. */
static int entry(size_t i, chm_servo_system_entry_t* e) {
    return chm_servo_system_module_at(g_sys, i, e) == 0 && e->spawned;
}

/* Every module's misses (critical ones only when `critical_only`). */
static uint64_t misses(int critical_only) {
    uint64_t n = 0;
    chm_servo_system_entry_t e;
    for (size_t i = 0; i < chm_servo_system_modules(g_sys); ++i) {
        chm_servo_status_t st;
        if (entry(i, &e) && (!critical_only || e.critical) && chm_servo_status(e.id, &st) == 0) n += st.misses;
    }
    return n;
}

/* 0 while every spawned module is OFF or ON; else prints which is not. */
static int modules_ok(void) {
    chm_servo_system_entry_t e;
    for (size_t i = 0; i < chm_servo_system_modules(g_sys); ++i) {
        chm_servo_status_t st;
        if (!entry(i, &e)) continue;
        if (chm_servo_status(e.id, &st) != 0) {
            fprintf(stderr, "job: status of %s: %s\n", e.name, chm_err_last());
            return -1;
        }
        if (st.state == CHM_SERVO_ERROR || st.state == CHM_SERVO_DEAD) {
            fprintf(stderr, "job: module %s on RTPU %d is %s: %s\n", e.name, e.rtpu,
                    st.state == CHM_SERVO_DEAD ? "DEAD (its RTPU is gone)" : "in ERROR",
                    st.last_error[0] ? st.last_error : "no message");
            return -1;
        }
    }
    return 0;
}

/* A switch requested at t_req took effect at `at`: wait 5 cycles, then
 * record its instant and cost for the monitor: how many cycles of the base
 * period it took to take effect, and the deadlines missed around it (the
 * count was `before` at the request). */
static void switched(uint64_t t_req, uint64_t at, uint64_t before) {
    while (now_ns() < at + 5 * g_period_ns) nap_ms(1);
    const double cost = (double)(at - t_req) / (double)g_period_ns;
    const uint64_t missed = misses(0) - before;
    if (g_nsw < DEMO_SW_MAX) {
        double* row = g_sw + 4 * g_nsw;
        row[0] = (double)at * 1e-9;
        row[1] = cost;
        row[2] = (double)missed;
        row[3] = *g_phase;
        ++g_nsw;
        publish();
    }
    printf("job: switch %d (%s) effective at T = %.6f s, %.1f cycles after the request, %llu cycles missed\n",
           g_nsw, demo_phase_name(*g_phase), (double)at * 1e-9, cost, (unsigned long long)missed);
    fflush(stdout);
}

/* Switch `off` -> `on` (module indices, -1 ends each list) at one boundary. */
static int do_switch(const int* off, const int* on) {
    chm_servo_module_t o[M_COUNT], n[M_COUNT];
    size_t no = 0, nn = 0;
    for (; *off >= 0; ++off) o[no++] = g_mod[*off];
    for (; *on >= 0; ++on) n[nn++] = g_mod[*on];
    const uint64_t before = misses(0), t_req = now_ns();
    uint64_t at = 0;
    int r;
    /* -ETIME: a commit came too late for the instant, so nothing switched
     * anywhere (a switch is all or nothing): ask again. */
    for (int tries = 0; (r = chm_servo_switch(o, no, n, nn, 0, &at)) == -ETIME && tries < 20; ++tries)
        fprintf(stderr, "job: switch %d refused whole (%s), asking again\n", g_nsw + 1, chm_err_last());
    if (r != 0) {
        fprintf(stderr, "job: switch %d refused (%s): %s\n", g_nsw + 1, strerror(-r), chm_err_last());
        return -1;
    }
    switched(t_req, at, before);
    return 0;
}

/* Switch on every module the file marks `on`, in one switch. */
static int start_system(void) {
    const uint64_t before = misses(0), t_req = now_ns();
    uint64_t at = 0;
    int r;
    for (int tries = 0; (r = chm_servo_system_start(g_sys, &at)) == -ETIME && tries < 20; ++tries)
        fprintf(stderr, "job: start refused whole (%s), asking again\n", chm_err_last());
    if (r != 0) {
        fprintf(stderr, "job: start: %s\n", chm_err_last());
        return -1;
    }
    switched(t_req, at, before);
    return 0;
}

static int control(int m, const char* param, double v) {
    const int r = chm_servo_control(g_mod[m], param, v);
    if (r != 0) fprintf(stderr, "job: %s.%s = %g: %s\n", demo_module_names[m], param, v, chm_err_last());
    return r;
}

/* A new trajectory segment to (x, z) in dur seconds. */
static int traj_go(double x, double z, double dur, int from_q) {
    static double seq;
    return control(M_TRAJ, "x", x) || control(M_TRAJ, "z", z) || control(M_TRAJ, "dur", dur) ||
           control(M_TRAJ, "from_q", from_q) || control(M_TRAJ, "seq", ++seq);
}

/* Wait until cond() holds for `hold_ms` in a row, at most `limit_s`. */
static int wait_for(const char* what, int (*cond)(void), int hold_ms, double limit_s) {
    const uint64_t end = now_ns() + (uint64_t)(limit_s * 1e9);
    uint64_t since = 0;
    unsigned polls = 0;
    for (;;) {
        const uint64_t t = now_ns();
        if (cond()) {
            if (!since) since = t;
            if (t - since >= (uint64_t)hold_ms * 1000000u) return 0;
        } else {
            since = 0;
        }
        if (t > end || t > g_deadline_ns) {
            fprintf(stderr, "job: %s: not within %.1f s\n", what, limit_s);
            return -1;
        }
        /* Status travels by express mail: every 100 ms is enough. */
        if (++polls % 20 == 0 && modules_ok() != 0) return -1;
        nap_ms(5);
    }
}

static int always(void) { return 1; }
static int arm_sampled(void) { return get1(SV_T, 0) > 0; }
static int pressing(void) { return fabs(get1(SV_F, 1) - 5.0) < 1.0; }
static int holding(void) { return get1(SV_OBJ, 2) == 1 && get1(SV_GRIP, 1) >= 8.0; }
static int released(void) { return get1(SV_OBJ, 2) == 0 && get1(SV_GRIP, 0) >= 0.07; }

/* Read the system file, declare its variables, spawn its modules OFF and
 * find the ones the phases switch. */
static int set_up(const char* path) {
    if (chm_servo_system_open(path, &g_sys) != 0) {
        fprintf(stderr, "job: %s\n", chm_err_last());
        return -1;
    }
    chm_servo_system_entry_t e;
    for (size_t i = 0; i < chm_servo_system_modules(g_sys); ++i)
        if (chm_servo_system_module_at(g_sys, i, &e) == 0 && (!g_period_ns || e.period_ns < g_period_ns))
            g_period_ns = e.period_ns;
    if (chm_servo_system_declare(g_sys) != 0 || chm_servo_system_spawn(g_sys) != 0) {
        fprintf(stderr, "job: %s\n", chm_err_last());
        return -1;
    }
    for (int m = 0; m < M_COUNT; ++m)
        if (chm_servo_system_find(g_sys, demo_module_names[m], &g_mod[m]) != 0) {
            fprintf(stderr, "job: the phases need module %s: %s\n", demo_module_names[m], chm_err_last());
            return -1;
        }
    return 0;
}

/* Everything off and killed (brakes on: arm_io's actuator closes). */
static void teardown(void) {
    if (!g_sys) return;
    chm_servo_system_entry_t e;
    unsigned rtpus = 0;
    for (size_t i = 0; i < chm_servo_system_modules(g_sys); ++i)
        if (chm_servo_system_module_at(g_sys, i, &e) == 0) {
            rtpus |= 1u << e.rtpu;
            if (e.spawned) (void)!chm_servo_kill(e.id);
        }
    if (rtpus) (void)!chm_servo_release(rtpus);
    chm_servo_system_close(g_sys);
    g_sys = NULL;
}

static int run(double tol) {
    const double zs = ARM_SURFACE_Z, xo = ARM_OBJECT_X, xt = ARM_TARGET_X;
    set_phase(PH_START);
    if (start_system() ||
        wait_for("the arm's first sample", arm_sampled, 0, 5) || wait_for("settling", always, 300, 5))
        return -1;
    set_phase(PH_APPROACH);
    if (traj_go(xo, zs + 0.08, 1.5, 0) || wait_for("approach", always, 1800, 5)) return -1;
    set_phase(PH_PICK);
    if (do_switch((int[]){M_PD, -1}, (int[]){M_FORCE, -1}) ||
        wait_for("pressing on the object with 5 N", pressing, 200, 5) || control(M_GRIPPER, "close", 1) ||
        wait_for("the object held with 8 N or more", holding, 100, 5))
        return -1;
    set_phase(PH_MOVE);
    if (traj_go(xo, zs + 0.15, 0.8, 1) || do_switch((int[]){M_FORCE, M_GRIPPER, -1}, (int[]){M_PD, -1}) ||
        wait_for("lift", always, 1000, 5) || traj_go(xt, zs + 0.08, 1.5, 0) || wait_for("carry", always, 1800, 5))
        return -1;
    set_phase(PH_PLACE);
    if (do_switch((int[]){M_PD, -1}, (int[]){M_FORCE, M_GRIPPER, -1}) ||
        wait_for("pressing the object down with 5 N", pressing, 200, 5) || control(M_GRIPPER, "close", 0) ||
        wait_for("the object let go", released, 100, 5))
        return -1;
    set_phase(PH_RETREAT);
    if (traj_go(xt, zs + 0.25, 1.0, 1) || do_switch((int[]){M_FORCE, M_GRIPPER, -1}, (int[]){M_PD, -1}) ||
        wait_for("retreat", always, 1200, 5))
        return -1;
    set_phase(PH_STOP);
    if (do_switch((int[]){M_IO, M_GRAVITY, M_TRAJ, M_PD, -1}, (int[]){-1})) return -1;

    /* The outcome. */
    double obj[3];
    if (chm_svar_get(SV_OBJ, obj, sizeof obj) != 0) return -1;
    const double err = hypot(obj[0] - xt, obj[1] - zs);
    const uint64_t missed = misses(1);
    printf("job: object at x = %.4f m, z = %.4f m, %s; target x = %.4f m: placement error %.2f mm "
           "(tolerance %.1f mm)\n",
           obj[0], obj[1], obj[2] != 0 ? "still held" : "resting", xt, err * 1e3, tol * 1e3);
    chm_servo_system_entry_t e;
    for (size_t i = 0; i < chm_servo_system_modules(g_sys); ++i) {
        chm_servo_status_t st;
        if (entry(i, &e) && chm_servo_status(e.id, &st) == 0)
            printf("job: %-9s RTPU %d  %6llu cycles  %llu missed%s  worst cycle %.1f us\n", e.name, e.rtpu,
                   (unsigned long long)st.cycles, (unsigned long long)st.misses, e.critical ? " (critical)" : "",
                   (double)st.worst_cycle_ns / 1e3);
    }
    int bad = 0;
    if (obj[2] != 0 || !(err <= tol)) {
        fprintf(stderr, "job: FAILED: the object is not within %.1f mm of its target\n", tol * 1e3);
        bad = 1;
    }
    /* A deadline miss here is the host's latency as much as ours (a shared
     * virtual machine stalls whole processes for over a millisecond): the
     * test suite reports misses without judging them (DEMO_MISSES_ALLOWED);
     * make demo judges them. */
    const char* allowed = getenv("DEMO_MISSES_ALLOWED");
    if (missed && !(allowed && *allowed == '1')) {
        fprintf(stderr, "job: FAILED: critical modules missed %llu deadlines (on a loaded or virtual host, "
                "run as root or with an rtprio limit for SCHED_FIFO; see README, Privileges)\n",
                (unsigned long long)missed);
        bad = 1;
    } else if (missed) {
        printf("job: NOTE: critical modules missed %llu deadlines on this host (reported, not judged)\n",
               (unsigned long long)missed);
    }
    if (!bad)
        printf("job: OK: object placed within %.1f mm of its target, %s\n", tol * 1e3,
               missed ? "deadlines missed on this host (see NOTE)" : "no critical deadline missed");
    return bad ? -1 : 0;
}

static void usage(const char* why) {
    fprintf(stderr,
            "chimera-arm-job: %s\nusage: chimera-arm-job --system FILE [--backplane PATH] [--tolerance M]\n"
            "                       [--timeout S]\n",
            why);
    exit(2);
}

int main(int argc, char** argv) {
    char bp[512];
    const char* system = NULL;
    double tol = 0.015;
    if (chm_bp_default_path(bp, sizeof bp) != 0) usage("the default backplane path is too long");
    for (int i = 1; i < argc; ++i) {
        const char* a = argv[i];
        if (i + 1 >= argc) usage("an option lacks its value");
        char* end;
        if (!strcmp(a, "--system")) system = argv[++i];
        else if (!strcmp(a, "--backplane")) snprintf(bp, sizeof bp, "%s", argv[++i]);
        else if (!strcmp(a, "--tolerance")) {
            tol = strtod(argv[++i], &end);
            if (*end || !(tol > 0 && tol < 1)) usage("--tolerance wants metres in (0, 1)");
        } else if (!strcmp(a, "--timeout")) {
            g_timeout_s = strtod(argv[++i], &end);
            if (*end || !(g_timeout_s >= 5 && g_timeout_s <= 3600)) usage("--timeout wants 5..3600 s");
        } else usage("unknown argument");
    }
    if (!system) usage("--system FILE is required");
    g_deadline_ns = now_ns() + (uint64_t)(g_timeout_s * 1e9);
    if (chm_bp_attach_host(bp, "arm-job", NULL) != 0) {
        fprintf(stderr, "chimera-arm-job: %s: %s\n", bp, chm_bp_last_error());
        return 1;
    }
    if (set_up(system) != 0) {
        teardown();
        (void)!chm_bp_leave();
        return 1;
    }
    const char* const outs[] = {SV_PHASE, SV_SWITCHES};
    if (chm_svar_set_create("arm-job", NULL, 0, outs, 2, &g_set) != 0) {
        fprintf(stderr, "chimera-arm-job: %s\n", chm_err_last());
        teardown();
        (void)!chm_bp_leave();
        return 1;
    }
    g_phase = chm_svar_set_local(g_set, SV_PHASE);
    g_sw = chm_svar_set_local(g_set, SV_SWITCHES);
    memset(g_sw, 0, sizeof(double) * DEMO_SW_MAX * 4);
    *g_phase = 0;
    publish();
    const int rc = run(tol) == 0 ? 0 : 1;
    teardown();
    *g_phase = DEMO_DONE;
    publish();
    (void)!chm_svar_set_destroy(g_set);
    (void)!chm_bp_leave();
    return rc;
}
