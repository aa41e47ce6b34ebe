/* The soak's servo controller (servo_main.c, servo_inherit.c): what its
 * two files share. */
#ifndef CHM_SOAK_SERVO_CTL_H
#define CHM_SOAK_SERVO_CTL_H

#include <chimera/servo.h>
#include <stdint.h>

#include "ledger.h"
#include "modlog.h"

#define ST(field, v) __atomic_store_n(&(field), (v), __ATOMIC_SEQ_CST)
#define LD(field) __atomic_load_n(&(field), __ATOMIC_SEQ_CST)

typedef struct role {
    const char* name; /* instance name */
    int rtpu;
    unsigned index;   /* A 0, B 1, S 2: the module's "role" parameter */
    const char* path;
    int have;         /* spawned (or found) and not seen gone */
    chm_servo_module_t id;
    chm_servo_status_t st; /* last status read (valid while have) */
} role_t;

/* How long a module may show a state a refused switch armed it for: a
 * switch refused with -ETIME whose resolve did not reach a module's RTPU
 * (stopped, its ring full of abandoned requests) leaves the module going
 * on ON, armed, until the instant T, when its task reads the decision cell
 * (aborted) and goes OFF without running a cycle; T lies up to 4 prepare
 * round trips ahead (a stopped RTPU's: up to the longest stop, 1 s). The
 * same bound holds for a switch whose controller was killed in the call:
 * by T every party has read the one outcome (committed, or aborted by the
 * first party to look). */
#define SETTLE_NS 10000000000ull

extern soak_servo_t* sv;
extern uint32_t inc; /* this incarnation: 1, 2, ... */

uint64_t now_ns(void);
void nap_ms(unsigned ms);
void begin(uint32_t call);
uint64_t end(void);
void unexpected(int r, const char* what, const char* name);
void defect(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
int transient(int r);
int refresh(role_t* m);

/* servo_inherit.c */
void adopt(role_t** all);
void pend_begin(const role_t* off, const role_t* on);
void pend_returned(int r, uint64_t at_ns);
void verify_inherited(void);

#endif
