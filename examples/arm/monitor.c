/* chimera-arm-monitor: the pick-and-place demo's live figures, a host
 * process that only reads. Once a second it prints the joint positions and
 * their errors against the reference, the contact force, the jaws and the
 * object, which modules are on and each one's cycles and misses; every
 * switch the job makes is printed as it appears (its instant and cost).
 * The modules it shows are those of the system file (--system).
 * It samples the state variables every 10 ms into a CSV file (--csv) for
 * the plot (plot.py), and ends when the job says it is done, or after
 * --seconds. Exit status 0, or 1 when the job never finished. */
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

static uint64_t now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

static void nap_ms(int ms) {
    struct timespec ts = {ms / 1000, (long)(ms % 1000) * 1000000L};
    nanosleep(&ts, NULL);
}

typedef struct {
    double q[2], q_ref[2], f[2], grip[2], obj[3], t_arm;
    int32_t phase;
    double sw[DEMO_SW_MAX * 4];
} sample_t;

static int take(sample_t* s) {
    return chm_svar_get(SV_Q, s->q, sizeof s->q) | chm_svar_get(SV_Q_REF, s->q_ref, sizeof s->q_ref) |
           chm_svar_get(SV_F, s->f, sizeof s->f) | chm_svar_get(SV_GRIP, s->grip, sizeof s->grip) |
           chm_svar_get(SV_OBJ, s->obj, sizeof s->obj) | chm_svar_get(SV_T, &s->t_arm, sizeof s->t_arm) |
           chm_svar_get(SV_PHASE, &s->phase, sizeof s->phase) |
           chm_svar_get(SV_SWITCHES, s->sw, sizeof s->sw);
}

static void print_modules(const chm_servo_system_t* sys) {
    char on[160] = "", counts[400] = "";
    size_t a = 0, b = 0;
    for (size_t i = 0; i < chm_servo_system_modules(sys); ++i) {
        chm_servo_system_entry_t e;
        chm_servo_module_t m;
        chm_servo_status_t st;
        if (chm_servo_system_module_at(sys, i, &e) != 0 || chm_servo_find(e.rtpu, e.name, &m) != 0 ||
            chm_servo_status(m, &st) != 0)
            continue;
        if (st.state == CHM_SERVO_ON && a < sizeof on)
            a += (size_t)snprintf(on + a, sizeof on - a, " %s", st.name);
        if (b < sizeof counts)
            b += (size_t)snprintf(counts + b, sizeof counts - b, " %s %llu/%llu%s", st.name,
                                  (unsigned long long)st.cycles, (unsigned long long)st.misses,
                                  st.state == CHM_SERVO_ERROR ? "(ERROR)" : st.state == CHM_SERVO_DEAD ? "(DEAD)" : "");
    }
    printf("       on:%s\n       cycles/misses:%s\n", a ? on : " (none)", b ? counts : " (no modules)");
}

static void usage(const char* why) {
    fprintf(stderr, "chimera-arm-monitor: %s\nusage: chimera-arm-monitor --system FILE [--backplane PATH] [--seconds N]\n"
            "                           [--csv FILE]\n",
            why);
    exit(2);
}

int main(int argc, char** argv) {
    char bp[512];
    int seconds = 60;
    const char* csv_path = NULL;
    const char* system = NULL;
    if (chm_bp_default_path(bp, sizeof bp) != 0) usage("the default backplane path is too long");
    for (int i = 1; i < argc; ++i) {
        if (i + 1 >= argc) usage("an option lacks its value");
        if (!strcmp(argv[i], "--backplane")) snprintf(bp, sizeof bp, "%s", argv[++i]);
        else if (!strcmp(argv[i], "--csv")) csv_path = argv[++i];
        else if (!strcmp(argv[i], "--system")) system = argv[++i];
        else if (!strcmp(argv[i], "--seconds")) {
            char* end;
            const long v = strtol(argv[++i], &end, 10);
            if (*end || v < 1 || v > 3600) usage("--seconds wants 1..3600");
            seconds = (int)v;
        } else usage("unknown argument");
    }
    if (!system) usage("--system FILE is required");
    chm_servo_system_t* sys = NULL;
    if (chm_servo_system_open(system, &sys) != 0) {
        fprintf(stderr, "chimera-arm-monitor: %s\n", chm_err_last());
        return 1;
    }
    if (chm_bp_attach_host(bp, "arm-monitor", NULL) != 0) {
        fprintf(stderr, "chimera-arm-monitor: %s: %s\n", bp, chm_bp_last_error());
        return 1;
    }
    FILE* csv = NULL;
    if (csv_path && !(csv = fopen(csv_path, "w"))) {
        fprintf(stderr, "chimera-arm-monitor: %s: %s\n", csv_path, strerror(errno));
        return 1;
    }
    const uint64_t t0 = now_ns(), end = t0 + (uint64_t)seconds * 1000000000u;
    sample_t s;
    /* The job declares the variables: wait for them (bounded by --seconds). */
    while (take(&s) != 0) {
        if (now_ns() > end) {
            fprintf(stderr, "chimera-arm-monitor: the demo's state variables never appeared on %s\n", bp);
            return 1;
        }
        nap_ms(20);
    }
    if (csv) fprintf(csv, "t,q1,q2,q1_ref,q2_ref,fx,fz,grip,fgrip,obj_x,obj_z,held,phase\n");
    int shown = 0, done = 0;
    uint64_t next_print = t0 + 1000000000u;
    while (!done && now_ns() < end) {
        if (take(&s) != 0) {
            nap_ms(10);
            continue;
        }
        const double t = (double)(now_ns() - t0) * 1e-9;
        if (csv && s.t_arm > 0) /* not before the arm's first sample: all zeros */
            fprintf(csv, "%.4f,%.6f,%.6f,%.6f,%.6f,%.3f,%.3f,%.5f,%.3f,%.5f,%.5f,%.0f,%d\n", t, s.q[0], s.q[1],
                    s.q_ref[0], s.q_ref[1], s.f[0], s.f[1], s.grip[0], s.grip[1], s.obj[0], s.obj[1], s.obj[2],
                    (int)s.phase);
        for (; shown < DEMO_SW_MAX && s.sw[4 * shown] > 0; ++shown) {
            const double* r = s.sw + 4 * shown;
            printf("  switch %d into %-8s at T = %.3f s (monitor time %.3f s): effective %.1f cycles after the "
                   "request, %.0f cycles missed\n",
                   shown + 1, demo_phase_name((int)r[3]), r[0], r[0] - (double)t0 * 1e-9, r[1], r[2]);
            if (csv) fprintf(csv, "#switch,%.4f,%.2f,%s\n", r[0] - (double)t0 * 1e-9, r[1], demo_phase_name((int)r[3]));
        }
        if (now_ns() >= next_print) {
            next_print += 1000000000u;
            printf("%4.0f s  %-8s q %+.3f %+.3f rad  err %+.4f %+.4f rad  Fz %5.2f N  jaws %.3f m %5.2f N  "
                   "object (%.3f, %.3f)%s\n",
                   t, demo_phase_name(s.phase), s.q[0], s.q[1], s.q_ref[0] - s.q[0], s.q_ref[1] - s.q[1], s.f[1],
                   s.grip[0], s.grip[1], s.obj[0], s.obj[1], s.obj[2] != 0 ? " held" : "");
            print_modules(sys);
            fflush(stdout);
        }
        done = s.phase == DEMO_DONE;
        nap_ms(10);
    }
    if (csv) fclose(csv);
    chm_servo_system_close(sys);
    (void)!chm_bp_leave();
    if (!done) {
        fprintf(stderr, "chimera-arm-monitor: the job did not finish within %d s\n", seconds);
        return 1;
    }
    return 0;
}
