/* The chaos soak's control modules (docs/backplane.md, "Chaos soak"): the
 * cycle log they keep in the segment soak.mlog (common memory, made by the
 * driver), so the driver can tell at the end which module ran which cycle.
 * Roles: A and B (soak_mod_hand.so on RTPUs 1 and 2) write soak.hand and
 * are handed it back and forth; S (soak_mod_solo.so on RTPU 3) writes
 * soak.solo and is switched on and off alone. A module of role r running
 * the cycle of index k (its release / period, on the grid every RTPU
 * shares) sets bit k - base_k of bits[r]; two roles' bits set for one k of
 * soak.hand would be two writers in one cycle. */
#ifndef CHM_SOAK_MODLOG_H
#define CHM_SOAK_MODLOG_H

#include <stdint.h>

#define SOAK_MOD_ROLES 3          /* A, B, S */
#define SOAK_MOD_PERIOD_NS 4000000ull /* every module: 4 ms */
#define SOAK_MOD_CAP_BITS (1u << 18) /* cycles logged per role: 17 minutes at 4 ms */
#define SOAK_HAND_ELEMS 4         /* soak.hand, soak.solo: 4 doubles, each k * 4 + role */

typedef struct soak_modlog {
    uint64_t base_k;                     /* the cycle index of bit 0 (when the driver made it) */
    uint64_t beyond[SOAK_MOD_ROLES];     /* cycles run outside [base_k, base_k + CAP) */
    uint64_t cycles[SOAK_MOD_ROLES];     /* cycles run, per role */
    uint8_t bits[SOAK_MOD_ROLES][SOAK_MOD_CAP_BITS / 8];
} soak_modlog_t;

#endif
