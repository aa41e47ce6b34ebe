/* What the multi-RTPU demo's control programs share: one segment of
 * global shared memory (the servo's state and its set point, guarded by a
 * backplane spin-lock) and one remote semaphore (the servo's 10 Hz tick). */
#ifndef CHIMERA_EXAMPLE_MULTI_H
#define CHIMERA_EXAMPLE_MULTI_H

#include <stdint.h>

#include <chimera/spin.h>

#define SERVO_STATE "servo.state" /* global shared memory, in RTPU 1's window */
#define SERVO_TICK "servo.tick"   /* remote counting semaphore, common memory */
#define SERVO_SIG_SOFT 1          /* user signal: toggle soft / stiff gains */

typedef struct servo_state {
    chm_spin_t lock;
    /* Written by the servo (RTPU 1). */
    double position, velocity;
    uint64_t cycles;
    uint64_t worst_late_ns;   /* release lateness, worst so far */
    volatile uint64_t tick_ns; /* when the servo last V'd servo.tick */
    int32_t soft;             /* gains in use: 1 soft, 0 stiff */
    int32_t pad;
    /* Written by the supervisor (RTPU 2). */
    double setpoint;
} servo_state_t;

#endif
