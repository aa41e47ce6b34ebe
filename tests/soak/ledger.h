/* The chaos soak's ledger (docs/backplane.md, "Chaos soak"): a file in the
 * soak's private directory that the driver and every worker map. It is not
 * backplane memory on purpose: it must outlive any process and any
 * backplane defect, so the driver can account for what a killed worker was
 * doing at the instant it died.
 *
 * Each worker has one record (written by that worker only, read by the
 * driver; the driver writes `inc`, `quit` and, between incarnations, the
 * in-flight states) and two bitmaps indexed by message sequence number:
 * `sent` (the worker's send of that sequence returned 0) and `recv` (some
 * receiver got it; set with an atomic OR, so a second receipt is seen). */
#ifndef CHM_SOAK_LEDGER_H
#define CHM_SOAK_LEDGER_H

#include <stdint.h>

#define SOAK_MAX_WORKERS 8
#define SOAK_SEQ_CAP (1u << 21)     /* sequence numbers per worker, 1..CAP-1 */
#define SOAK_QUEUES 3               /* soak.q0 .. soak.q2 in common memory */
#define SOAK_MSG_MAGIC 0x4B414F53u  /* "SOAK" */
#define SOAK_MSG_MAX 256            /* the queues' max_msg */
#define SOAK_PAD_MAX (SOAK_MSG_MAX - 24)
#define SOAK_OP_TIMEOUT_NS 200000000ull /* every blocking call: 200 ms */
#define SOAK_SHM_WORDS 8
/* State variables soak.v1 .. soak.vR (R = RTPUs): vectors of this many
 * doubles, each element the number of values written (a torn read shows as
 * unequal elements). The first task of RTPU r is the one writer of soak.vr;
 * every worker reads them all. */
#define SOAK_SVAR_ELEMS 8
#define SOAK_SVAR_MAX 4
/* Objects whose progress the driver watches: the queues, then these
 * (MAIL: some RTPU answered an express-mail ping). */
#define SOAK_OBJ_SEM SOAK_QUEUES
#define SOAK_OBJ_SHM (SOAK_QUEUES + 1)
#define SOAK_OBJ_MAIL (SOAK_QUEUES + 2)
#define SOAK_OBJ_SVAR (SOAK_QUEUES + 3) /* some writer wrote its state variable */
#define SOAK_OBJECTS (SOAK_QUEUES + 4)

/* What a worker was doing (op) and the in-flight states the driver reads
 * after a death. */
enum soak_op { SOAK_OP_IDLE, SOAK_OP_SEND, SOAK_OP_RECV, SOAK_OP_PV, SOAK_OP_SHM_WRITE, SOAK_OP_SHM_READ,
               SOAK_OP_PAUSE, SOAK_OP_PING, SOAK_OP_SVAR_WRITE, SOAK_OP_SVAR_READ, SOAK_OP_COUNT };
enum soak_send_state { SOAK_SEND_IDLE, SOAK_SEND_PENDING };   /* pending: seq last_seq in the call */
enum soak_sem_state { SOAK_SEM_IDLE, SOAK_SEM_P, SOAK_SEM_HELD, SOAK_SEM_V };
enum soak_shm_state { SOAK_SHM_IDLE, SOAK_SHM_LOCKING, SOAK_SHM_WRITING, SOAK_SHM_UNLOCKING };

typedef struct soak_msg {
    uint32_t magic, sender, seq, len; /* len: whole message, bytes */
    uint32_t sum;                     /* soak_msg_sum over the rest */
    uint32_t inc;                     /* sender's incarnation */
    uint8_t pad[SOAK_PAD_MAX];
} soak_msg_t;

typedef struct soak_worker {
    /* driver -> worker */
    uint32_t inc;   /* incarnation the driver started last */
    uint32_t quit;  /* 1: finish the operation under way, then set done */
    /* worker -> driver */
    uint32_t started, done; /* the incarnation that started / finished after quit */
    uint64_t hb_ns;         /* CLOCK_MONOTONIC at the end of the last operation */
    uint32_t op;            /* enum soak_op under way */
    uint32_t last_seq;      /* highest sequence taken (kept across incarnations) */
    uint32_t send_state, sem_state, shm_state, recv_state;
    uint64_t op_count[SOAK_OP_COUNT]; /* completed, by kind */
    uint64_t sends_ok, send_timeouts, recvs_ok, recv_timeouts;
    uint64_t p_ok, p_timeouts, shm_writes, shm_reads, shm_busy;
    uint64_t v_busy;                  /* V refused with -EBUSY (lock held 10 ms by a live peer) and called again */
    uint64_t pings_ok, pings_down, pings_late; /* answered; -EHOSTDOWN; -ETIMEDOUT or -EBUSY */
    uint64_t owner_dead, repairs;     /* spin-lock taken from a dead holder; seqlock repaired */
    /* State variables: svar_writing is 1 around chm_svar_set_write (a
     * death there leaves that write in doubt); svar_claims counts the
     * incarnations that became soak.vr's writer (an RTPU's first task). */
    uint32_t svar_writing, svar_pad;
    uint64_t svar_writes, svar_reads, svar_retry, svar_claims;
    uint64_t svar_torn, svar_back;    /* defects: a mixed vector; a value older than one seen before */
    uint64_t dups, torn, bad_msgs;    /* defects seen by this worker */
    uint64_t errors;                  /* unexpected statuses */
    int32_t last_err;
    uint32_t last_err_op;
    char last_err_text[200];          /* chm_bp_last_error() after it */
    soak_msg_t rbuf;                  /* receive buffer: valid while magic is set */
} soak_worker_t;

/* The servo controller (servo_main.c): a host process that keeps modules
 * on RTPUs 1..3 and switches them (modlog.h). The chaos kills it and stops
 * it too; each incarnation carries on from this record, which outlives it. */
enum soak_servo_call { SOAK_SV_IDLE, SOAK_SV_TAKE, SOAK_SV_SPAWN, SOAK_SV_STATUS, SOAK_SV_SWITCH, SOAK_SV_KILL,
                       SOAK_SV_CALLS };
/* The switch a controller is in, or whose outcome it has not checked yet:
 * what a controller killed there leaves for the next one to verify (done
 * on every module it named, or on none). Written before the call with
 * phase set last; phase cleared once the outcome was checked. */
typedef struct soak_servo_pend {
    uint32_t phase;      /* 0 none; 1 chm_servo_switch under way; 2 it returned r, outcome unchecked */
    int32_t r;
    int32_t role[2];     /* going off, going on: role (modlog.h) or -1 */
    int32_t rtpu[2], index[2];
    uint32_t gen[2];
    int32_t state[2];    /* each module's state before the call */
    uint64_t switched_at[2]; /* and its switch instant */
    uint64_t t_call, at_ns;  /* CLOCK_MONOTONIC before the call; T when it returned 0 */
} soak_servo_pend_t;
typedef struct soak_servo {
    uint32_t quit, done, call; /* call: enum soak_servo_call under way */
    uint32_t inc;              /* driver -> controller: the incarnation started last (1, 2, ...) */
    uint32_t started;          /* the incarnation that is up (attached, its modules found) */
    uint32_t switched_inc;     /* the last incarnation with a switch that returned 0 */
    uint32_t noting;           /* 1 while a defect or an unexpected status is being written down */
    uint32_t pad0;
    soak_servo_pend_t pend;
    /* A restarted controller: modules found by name, RTPUs taken again,
     * takes refused (a dead controller's control not given up), and the
     * switches its predecessor left: found done everywhere, nowhere, or
     * not to be judged (a module gone or unreadable). */
    uint64_t adopted, takes_after_restart, take_refused;
    uint64_t inherited_done, inherited_nothing, inherited_unverifiable;
    uint64_t hb_ns;                     /* the end of its last call */
    uint64_t takes, spawns, kills;
    uint64_t handovers, solo_switches, first_on;  /* switches that returned 0, by kind */
    uint64_t refused_late, refused_busy, refused_gone; /* -ETIME; -EALREADY/-EBUSY; RTPU or module gone */
    uint64_t checked_done, checked_nothing, unverifiable; /* after a switch: everywhere / nowhere / could not tell */
    uint64_t dead_seen, dead_seen_worst_ns; /* modules found DEAD or gone; the longest call that said so */
    uint64_t errors_cleared;            /* modules found in ERROR and cleared */
    uint64_t both_on_settled;           /* A and B both ON by their statuses, then the handed-over one OFF */
    uint64_t calls, worst_call_ns;
    uint32_t worst_call;                /* enum soak_servo_call of worst_call_ns */
    uint32_t hand_reads, hand_torn;     /* chm_svar_get of soak.hand: whole values? */
    uint64_t defects;                   /* a switch half done, two modules writing one variable... */
    uint64_t errors;                    /* unexpected statuses */
    int32_t last_err;
    uint32_t pad;
    char last_err_text[240];
    char last_defect[240];
} soak_servo_t;

typedef struct soak_ledger {
    uint32_t magic, workers;
    uint32_t sem_units; /* soak.sem's initial count */
    uint32_t rtpus;     /* RTPUs 1..rtpus, the targets of pings */
    uint32_t layout;    /* sizeof(soak_ledger_t) as the driver built it: a stale worker binary refuses */
    uint64_t ok_ns[SOAK_OBJECTS]; /* CLOCK_MONOTONIC of each object's last successful operation */
    soak_worker_t w[SOAK_MAX_WORKERS];
    soak_servo_t servo;
} soak_ledger_t;

#define SOAK_BITMAP_BYTES (SOAK_SEQ_CAP / 8)
/* Bitmaps follow the header, page-aligned: sent[w], then recv[w]. */
#define SOAK_LEDGER_HEAD ((sizeof(soak_ledger_t) + 4095u) & ~(size_t)4095u)
#define SOAK_LEDGER_SIZE (SOAK_LEDGER_HEAD + 2u * SOAK_MAX_WORKERS * SOAK_BITMAP_BYTES)

static inline uint8_t* soak_sent_bits(void* ledger, unsigned w) {
    return (uint8_t*)ledger + SOAK_LEDGER_HEAD + (size_t)w * SOAK_BITMAP_BYTES;
}
static inline uint8_t* soak_recv_bits(void* ledger, unsigned w) {
    return (uint8_t*)ledger + SOAK_LEDGER_HEAD + (size_t)(SOAK_MAX_WORKERS + w) * SOAK_BITMAP_BYTES;
}
static inline int soak_bit(const uint8_t* bits, uint32_t seq) { return (bits[seq >> 3] >> (seq & 7)) & 1; }

/* FNV-1a over the message after its first 20 bytes (inc and pad). */
static inline uint32_t soak_msg_sum(const soak_msg_t* m) {
    const uint8_t* p = (const uint8_t*)&m->inc;
    uint32_t n = m->len > 20 ? m->len - 20 : 0, h = 2166136261u ^ m->sender ^ (m->seq << 8);
    for (uint32_t i = 0; i < n; ++i) h = (h ^ p[i]) * 16777619u;
    return h;
}

/* A received message is well-formed: magic, length, sender, sequence, sum. */
static inline int soak_msg_ok(const soak_msg_t* m, int len, unsigned workers) {
    return len >= 24 && len <= SOAK_MSG_MAX && m->magic == SOAK_MSG_MAGIC && m->len == (uint32_t)len &&
           m->sender < workers && m->seq > 0 && m->seq < SOAK_SEQ_CAP && m->sum == soak_msg_sum(m);
}

#endif
