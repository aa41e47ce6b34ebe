/* Chimera multiprocessor servo task control: one controlling task (on any
 * RTPU, or a host process) takes control of RTPUs, spawns control modules
 * (chimera/module.h) on any of them, turns them on and off, switches a set
 * of them at one common cycle boundary, changes their parameters and reads
 * their status. Requests travel by express mail (chimera/rtpu.h); every
 * call waits for the RTPUs' replies, bounded.
 *
 * A switch (chm_servo_switch) takes effect at one instant T, a multiple of
 * every involved module's period: modules going off run every cycle
 * released before T and none after, modules going on every cycle released
 * at or after T and none before. A variable handed from one writer to
 * another of the same period is written by exactly one of them in every
 * cycle. A switch that cannot be honoured is refused before anything
 * changes (unless CHM_SERVO_BEST_EFFORT).
 *
 * Requires this process to be attached to a backplane. Every call returns
 * 0 or a negative errno-style status; chm_err_last() says what
 * failed, naming the module, RTPU, variable or parameter. Failures that
 * mean a bug or a missing resource are raised as error signals of module
 * "ipc" under global error handling (chimera/err.h). */
#ifndef CHIMERA_SERVO_H
#define CHIMERA_SERVO_H

#include "chimera/status.h"

#include <stddef.h>
#include <stdint.h>

#include "chimera/svar.h"

#ifdef __cplusplus
extern "C" {
#endif

#define CHM_SERVO_NAME_MAX 31
#define CHM_SERVO_MODULES_MAX 32   /* per RTPU */
#define CHM_SERVO_PATH_MAX 480     /* a module's path, bytes */

/* A module instance: its RTPU, its index there and that index's
 * generation (a later module in the same index is another module). */
typedef struct {
    int rtpu;
    int index;
    uint32_t gen;
} chm_servo_module_t;

enum chm_servo_state {
    CHM_SERVO_NONE = 0,  /* not created (killed, or never) */
    CHM_SERVO_OFF = 1,
    CHM_SERVO_ON = 2,
    CHM_SERVO_ERROR = 3,
    CHM_SERVO_DEAD = 4   /* its RTPU died or left */
};

enum chm_servo_miss_policy {
    CHM_SERVO_MISS_COUNT = 0, /* count a deadline miss, go on */
    CHM_SERVO_MISS_ERROR = 1  /* a miss sends the module to ERROR */
};

/* What chm_servo_spawn takes. */
typedef struct {
    int rtpu;
    const char* path;         /* the module's shared object */
    const char* name;         /* instance name, unique on that RTPU */
    uint64_t period_ns;       /* > 0 */
    uint64_t deadline_ns;     /* relative; 0 = the period */
    uint64_t wcet_ns;         /* estimated CPU per cycle (MLF, MUF); 0 = unknown */
    int critical;             /* MUF: in the critical set */
    int priority;             /* the task's static priority */
    int miss_policy;          /* enum chm_servo_miss_policy */
    size_t n_params;          /* parameter overrides: names and values */
    const char* const* param_names;
    const double* param_values;
} chm_servo_spawn_t;

/* Defaults: no RTPU, priority 0, count misses, no overrides. */
void chm_servo_spawn_init(chm_servo_spawn_t* s);

typedef struct {
    char name[CHM_SERVO_NAME_MAX + 1];
    char module[CHM_SERVO_NAME_MAX + 1];  /* the descriptor's name */
    int state;                            /* enum chm_servo_state */
    uint64_t period_ns;
    uint64_t cycles;                      /* cycles run since created */
    uint64_t misses;                      /* deadlines missed */
    uint64_t worst_cycle_ns;              /* CPU of its worst cycle (framework included) */
    uint64_t switched_at_ns;              /* when its last on/off took effect, 0 never */
    char last_error[160];                 /* "" if none */
} chm_servo_status_t;

/* Take control of every RTPU in `rtpus` (bit n: RTPU n). Refused when a
 * live controller other than the caller holds one of them. Errors:
 * -EINVAL empty mask; -EBUSY held (the message names the RTPU and the
 * holder's slot); -EHOSTDOWN an RTPU is not running; express-mail errors
 * (chimera/rtpu.h). Nothing is taken on error. */
CHM_CHECK int chm_servo_take(uint32_t rtpus);

/* Give control of those RTPUs back (their modules run on). Every RTPU in
 * the mask is asked, even after one fails. Errors: the first RTPU's
 * failure: -EPERM the caller did not hold it; -EHOSTDOWN not running;
 * express-mail errors (chimera/rtpu.h). */
CHM_CHECK int chm_servo_release(uint32_t rtpus);

/* Load the module `s->path` on RTPU `s->rtpu` as instance `s->name`, check
 * its descriptor, set its parameters, open its state variables and run its
 * init: it is then OFF. Errors: -EINVAL bad request (period 0 or below
 * 100 us, the fastest an RTPU runs a module; deadline above the period;
 * NULL path or name); -ENAMETOOLONG; -EPERM the caller
 * does not control that RTPU; -EACCES the path is not trusted (see
 * chimera/program.h); -ENOEXEC not a loadable module, no descriptor,
 * another ABI, a missing entry point; -ENOENT a state variable it names is
 * not declared; -ERANGE a parameter out of its range; -ESRCH a parameter
 * override names no parameter; -EEXIST the instance name is taken there;
 * -ENOSPC CHM_SERVO_MODULES_MAX modules there; -ECANCELED init failed or
 * faulted (the module is not created; the message says why); express-mail
 * errors. */
CHM_CHECK int chm_servo_spawn(const chm_servo_spawn_t* s, chm_servo_module_t* out);

/* Find the instance `name` on RTPU `rtpu` (-1: every controlled RTPU, and
 * others' too). Errors: -ENOENT; -EINVAL NULL. */
CHM_CHECK int chm_servo_find(int rtpu, const char* name, chm_servo_module_t* out);

/* Switch modules: every module of `off` (n_off) goes OFF and every module
 * of `on` (n_on) goes ON at one instant T (see above); *at_ns (may be
 * NULL) receives T. flags: 0, or CHM_SERVO_BEST_EFFORT (switch what can
 * be, leave the rest, return -EAGAIN if any was left out).
 * Errors: -EINVAL a module listed twice or in both lists; -EPERM an RTPU
 * not controlled by the caller; -ESTALE a module that no longer exists;
 * -EALREADY a module going on is ON, or going off is not ON; -EBUSY a
 * variable would have two writers (the message names it and both
 * modules); -ETIME T came before every RTPU had its commit and the
 * decision was made (nothing switched on any RTPU: the switch is all or
 * nothing); -EBUSY also when every decision cell of the state-variable
 * table is taken (switches whose controllers died before finishing);
 * -EHOSTDOWN an RTPU is gone. Whatever fails, nothing has switched,
 * except with CHM_SERVO_BEST_EFFORT for the parts left out at prepare. */
#define CHM_SERVO_BEST_EFFORT 0x1u
CHM_CHECK int chm_servo_switch(const chm_servo_module_t* off, size_t n_off, const chm_servo_module_t* on, size_t n_on,
                     unsigned flags, uint64_t* at_ns);

/* One module on, or off: chm_servo_switch of one. Errors: as
 * chm_servo_switch. */
CHM_CHECK int chm_servo_on(chm_servo_module_t m);
CHM_CHECK int chm_servo_off(chm_servo_module_t m);

/* Set parameter `param` of module m to `value`, effective before its next
 * cycle. Errors: -ESRCH no such parameter; -ERANGE outside its range;
 * -ESTALE; -EPERM; express-mail errors. */
CHM_CHECK int chm_servo_control(chm_servo_module_t m, const char* param, double value);

/* ERROR -> OFF through the module's clear (if it has one). Errors:
 * -EALREADY not in ERROR; -ECANCELED clear failed (still ERROR); -ESTALE;
 * -EPERM. */
CHM_CHECK int chm_servo_clear(chm_servo_module_t m);

/* Remove the module from any state: off (when ON) and kill run, its
 * claims end, its code is unloaded. Errors: -ESTALE; -EPERM;
 * express-mail errors. The module is gone even when kill fails (the
 * message says so). */
CHM_CHECK int chm_servo_kill(chm_servo_module_t m);

/* Status of module m; a module of an RTPU that died or left is DEAD.
 * Errors: -ESTALE no such module (killed, or the index reused); -EINVAL
 * NULL out; express-mail errors but -EHOSTDOWN (reported as DEAD). */
CHM_CHECK int chm_servo_status(chm_servo_module_t m, chm_servo_status_t* out);

/* Why the calling thread's last servo call failed.
 * chm_err_last() (err.h) gives the same text per task, whatever the
 * subsystem: use it; this call is kept for one release (CHANGELOG.md). */
const char* chm_servo_last_error(void);

/* ------------------------------------------------------------- systems
 *
 * A system's layout in a configuration file (TOML, chimera/config.h): the
 * state variables to declare and the modules to spawn. Unknown keys are
 * refused; every error names file:line:column.
 *
 *     [[svar]]
 *     name = "q"              # 1..31 characters
 *     type = "double"         # double, float, int32, uint32, bool
 *     rows = 3                # default 1; cols likewise (3 x 1: a vector)
 *     unit = "rad"            # optional
 *
 *     [[module]]
 *     name = "joint_pd"       # instance name, unique on its RTPU
 *     path = "libjoint_pd.so" # relative: to the configuration file's directory
 *     rtpu = 1
 *     rate_hz = 500           # 0.01 .. 10000; the period is 1/rate, in whole ns
 *     deadline_ms = 2         # optional: relative deadline (default the period)
 *     wcet_us = 300           # optional: estimated CPU per cycle (MLF, MUF)
 *     critical = true         # optional: MUF critical set (default false)
 *     priority = 5            # optional (default 0)
 *     on_miss = "count"       # or "error" (default "count")
 *     on = true               # switched on by chm_servo_system_start
 *     params = { kp = 100.0, kd = 8.0 }   # overrides of the module's defaults
 */
typedef struct chm_servo_system chm_servo_system_t;

/* Read and check the configuration file `path`. Nothing is declared or
 * spawned. Errors: -EINVAL NULL; -ENOENT no such file, or a required key
 * absent; -EBADMSG the file is wrong (the message gives file:line:column:
 * a syntax error, an unknown key, a value of the wrong type or out of
 * range, a variable declared twice, a module named twice on one RTPU);
 * -ENOMEM. chm_err_last() says what failed. */
CHM_CHECK int chm_servo_system_open(const char* path, chm_servo_system_t** out);

/* Declare every state variable of the file (chm_svar_declare). Errors:
 * those of chm_svar_declare (the message names the file and variable). */
CHM_CHECK int chm_servo_system_declare(chm_servo_system_t* sys);

/* Take control of every RTPU the file names and spawn every module there,
 * OFF. On error the modules spawned so far are killed. Errors: those of
 * chm_servo_take and chm_servo_spawn, the message naming the module. */
CHM_CHECK int chm_servo_system_spawn(chm_servo_system_t* sys);

/* Switch on, in one switch (chm_servo_switch), every module whose `on` is
 * true; *at_ns (may be NULL) receives the instant. Errors: -ESRCH a module
 * is not spawned; those of chm_servo_switch. */
CHM_CHECK int chm_servo_system_start(chm_servo_system_t* sys, uint64_t* at_ns);

/* One module of the file, in file order. */
typedef struct {
    const char* name;
    const char* path;        /* resolved */
    int rtpu;
    uint64_t period_ns;
    int on;                  /* switched on at start */
    int spawned;
    chm_servo_module_t id;   /* valid once spawned */
    int critical;            /* in MUF's critical set */
    int priority;
    uint64_t deadline_ns;    /* relative; 0 = the period */
    uint64_t wcet_ns;        /* estimated CPU per cycle; 0 = unknown */
} chm_servo_system_entry_t;
size_t chm_servo_system_modules(const chm_servo_system_t* sys);
/* Errors: -EINVAL NULL or no such index. */
CHM_CHECK int chm_servo_system_module_at(const chm_servo_system_t* sys, size_t i, chm_servo_system_entry_t* out);
/* The module called `name` (spawned). Errors: -EINVAL NULL; -ENOENT no
 * such module in the file; -ESRCH not spawned. */
CHM_CHECK int chm_servo_system_find(const chm_servo_system_t* sys, const char* name, chm_servo_module_t* out);
/* The file's state variables, in file order (the strings live as long as
 * the system). Errors: -EINVAL NULL or no such index. */
size_t chm_servo_system_svars(const chm_servo_system_t* sys);
CHM_CHECK int chm_servo_system_svar(const chm_servo_system_t* sys, size_t i, chm_svar_decl_t* out);

/* Free the description (modules run on; kill them with chm_servo_kill). */
void chm_servo_system_close(chm_servo_system_t* sys);

/* Why the calling thread's last chm_servo_system_ call failed.
 * chm_err_last() (err.h) gives the same text per task, whatever the
 * subsystem: use it; this call is kept for one release (CHANGELOG.md). */
const char* chm_servo_system_last_error(void);

#ifdef __cplusplus
}
#endif
#endif
