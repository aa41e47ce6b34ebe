/* What the control-loop demo's three parts share (`make demo`):
 *   RTPU 1  sensor.so      a 1 kHz task samples a simulated plant, sends a
 *                          timestamped sample to the controller and applies
 *                          the force it answers with
 *   RTPU 2  controller.so  a task blocked on loop.sense computes the force
 *                          (PD control) and answers on loop.reply
 *   host    chimera-loop-monitor  prints the loop's figures once a second
 * Each queue lives in its receiver's local memory, as on Chimera II's VME
 * boards; the figures go to the host through loop.stats in common memory.
 * Timestamps are CLOCK_MONOTONIC ns (chm_time_now), the same in every
 * process of the machine. */
#ifndef CHIMERA_EXAMPLE_LOOP_H
#define CHIMERA_EXAMPLE_LOOP_H

#include <errno.h>
#include <stdint.h>
#include <stdio.h>

#include <chimera/bp.h>
#include <chimera/msgq.h>

#define LOOP_SENSE "loop.sense" /* sensor -> controller, RTPU 2's window */
#define LOOP_REPLY "loop.reply" /* controller -> sensor, RTPU 1's window */
#define LOOP_STATS "loop.stats" /* sensor -> host monitor, common memory */

#define LOOP_PERIOD_NS 1000000u   /* 1 kHz */
#define LOOP_REPLY_WAIT_NS 600000 /* an answer later than this is lost */
#define LOOP_STATS_CAPACITY 4096  /* four seconds of records */

/* loop.sense: one sample per cycle; 24 bytes, the paper's message size. */
typedef struct loop_sample {
    uint64_t seq;     /* 1, 2, 3, ... */
    uint64_t sent_ns; /* when the sensor sent it */
    float position, velocity;
} loop_sample_t;

/* loop.reply: the controller's answer to sample `seq`. */
typedef struct loop_reply {
    uint64_t seq;
    uint64_t sent_ns;     /* copied from the sample */
    uint64_t received_ns; /* when the controller's task had the sample */
    double force;
} loop_reply_t;

/* loop.stats: one record per sensor cycle. Counters are totals since the
 * sensor started, so a record the monitor misses loses no count. */
typedef struct loop_stat {
    uint64_t seq;            /* the cycle's sample */
    uint32_t one_way_ns;     /* sample sent -> controller had it; 0: no answer */
    uint32_t round_trip_ns;  /* sample sent -> sensor had the answer; 0: none */
    uint32_t release_late_ns;/* cycle release -> the task ran */
    uint32_t misses;         /* the sensor task's deadline misses */
    uint32_t lost;           /* answers that did not come in time */
    uint32_t unsent;         /* samples the controller's queue refused */
    float position, setpoint;
    uint32_t safe;           /* 1: the sensor holds its safe output (no controller) */
    int32_t controller;      /* RTPU the last answer came from; -1: none yet */
} loop_stat_t;

/* After this many cycles in a row without an answer the sensor stops
 * applying forces (its safe output, zero force) until answers come back:
 * a dead controller must not leave the plant under its last command. */
#define LOOP_SAFE_AFTER 20

/* Create the queue `name` (messages of `msg` bytes, `count` of them) in
 * `where`, or open it when an earlier run of this RTPU (restarted after a
 * crash) left it. `who` prefixes the line that says why it failed. */
static inline int loop_queue(const char *who, const char *name, uint32_t msg, uint32_t count, int where,
                             chm_msgq_t **out) {
    chm_msgq_attr_t a;
    chm_msgq_attr_init(&a);
    a.max_msg = msg;
    a.max_count = count;
    int r = chm_msgq_create(name, &a, where, out);
    if (r == -EEXIST) r = chm_msgq_open(name, out);
    if (r) printf("%s: cannot create %s: %s\n", who, name, chm_bp_last_error());
    return r;
}

/* The set point the controller steers to: a square wave, 2 s per level. */
static inline float loop_setpoint(uint64_t seq) { return (seq / 2000) % 2 ? 0.5f : -0.5f; }

#endif
