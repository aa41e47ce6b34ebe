/* One chaos-soak worker (docs/backplane.md, "Chaos soak"): a loop of
 * random backplane operations, every blocking call bounded by
 * SOAK_OP_TIMEOUT_NS, each one bracketed by ledger stores that say what
 * was in flight, so the driver can account for an instant of death.
 * Runs as a task of an RTPU (worker_prog.c) or in a host process
 * (host_main.c); it calls only the public API. */
#define _GNU_SOURCE /* clock_gettime, nanosleep, O_CLOEXEC under -std=c11 */
#include "worker.h"

#include <chimera/bp.h>
#include <chimera/msgq.h>
#include <chimera/rtpu.h>
#include <chimera/rsem.h>
#include <chimera/shm.h>
#include <chimera/spin.h>
#include <chimera/svar.h>
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#define ST(field, v) __atomic_store_n(&(field), (v), __ATOMIC_SEQ_CST)
#define LD(field) __atomic_load_n(&(field), __ATOMIC_SEQ_CST)

typedef struct ctx {
    soak_ledger_t* l;
    soak_worker_t* me;
    unsigned id;
    uint64_t rng;
    chm_msgq_t* q[SOAK_QUEUES];
    chm_rsem_t* sem;
    soak_shm_t* shm;
    chm_svar_set_t* vars;  /* inputs: every soak.vr but its own; output: its own (writers) */
    int writes_var;        /* 1..R: the variable it writes, 0 none */
    unsigned n_vars;
    double seen[SOAK_SVAR_MAX + 1]; /* per variable: the newest value this incarnation saw */
} ctx_t;

volatile sig_atomic_t soak_worker_stop = 0;

static uint64_t now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000ull + (uint64_t)ts.tv_nsec;
}

static uint64_t rnd(ctx_t* c) { /* xorshift64* */
    c->rng ^= c->rng >> 12;
    c->rng ^= c->rng << 25;
    c->rng ^= c->rng >> 27;
    return c->rng * 2685821657736338717ull;
}

/* A bound for one blocking call: a quarter no wait, half 1..20 ms, a
 * quarter the longest, SOAK_OP_TIMEOUT_NS. Short ones keep traffic high;
 * long ones park waiters for a peer to wake. */
static uint64_t timeout(ctx_t* c) {
    const uint64_t k = rnd(c) % 4;
    return k == 0 ? CHM_NO_WAIT : k == 3 ? SOAK_OP_TIMEOUT_NS : (1 + rnd(c) % 20) * 1000000ull;
}

/* Not done within its bound: the outcome a bounded call may have. So is
 * -EINTR once SIGTERM asked a host worker to stop (its handler interrupts
 * the wait; the call did nothing, as a timeout); at no other time. */
static int expired(int r) { return r == -ETIMEDOUT || r == -EAGAIN || (r == -EINTR && soak_worker_stop); }

static void nap_us(uint64_t us) {
    struct timespec ts = {(time_t)(us / 1000000u), (long)(us % 1000000u) * 1000};
    nanosleep(&ts, NULL); /* a task: the kernel's pause (libchimera interposes it) */
}

/* Object k (SOAK_OBJ_*, or a queue's index) just did its job. */
static void progress(ctx_t* c, unsigned k) { ST(c->l->ok_ns[k], now_ns()); }

static void fail(ctx_t* c, int status, unsigned op) {
    ++c->me->errors;
    c->me->last_err = status;
    c->me->last_err_op = op;
    snprintf(c->me->last_err_text, sizeof c->me->last_err_text, "%s", chm_bp_last_error());
}

static void do_send(ctx_t* c) {
    soak_worker_t* me = c->me;
    if (me->last_seq + 1 >= SOAK_SEQ_CAP) return; /* ledger full: no more sends */
    soak_msg_t m;
    const uint32_t seq = me->last_seq + 1;
    const uint32_t pad = (uint32_t)(rnd(c) % (SOAK_PAD_MAX - 4));
    m.magic = SOAK_MSG_MAGIC;
    m.sender = c->id;
    m.seq = seq;
    m.len = 24 + pad;
    m.inc = me->inc;
    for (uint32_t i = 0; i < pad; ++i) m.pad[i] = (uint8_t)(seq * 31u + i);
    m.sum = soak_msg_sum(&m);
    ST(me->last_seq, seq); /* taken before the call: a death from here on leaves it in doubt */
    ST(me->send_state, SOAK_SEND_PENDING);
    const unsigned qi = (unsigned)(rnd(c) % SOAK_QUEUES);
    const int r = chm_msgq_send_timed(c->q[qi], 1, (uint32_t)(rnd(c) % 4), &m, m.len,
                                      timeout(c));
    if (r == 0) {
        __atomic_fetch_or(&soak_sent_bits(c->l, c->id)[seq >> 3], (uint8_t)(1u << (seq & 7)), __ATOMIC_SEQ_CST);
        ++me->sends_ok;
        progress(c, qi);
    } else if (expired(r)) {
        ++me->send_timeouts; /* nothing was queued: it must never arrive */
    } else {
        fail(c, r, SOAK_OP_SEND);
    }
    ST(me->send_state, SOAK_SEND_IDLE);
}

static void do_recv(ctx_t* c) {
    soak_worker_t* me = c->me;
    ST(me->rbuf.magic, 0u);
    ST(me->recv_state, 1u);
    chm_msgq_msg_info_t info;
    const unsigned qi = (unsigned)(rnd(c) % SOAK_QUEUES);
    const int r = chm_msgq_receive_timed(c->q[qi], &me->rbuf, sizeof me->rbuf, &info,
                                         timeout(c));
    if (r >= 0) {
        if (!soak_msg_ok(&me->rbuf, r, c->l->workers)) {
            ++me->bad_msgs;
            fail(c, -EBADMSG, SOAK_OP_RECV);
        } else {
            const uint32_t seq = me->rbuf.seq;
            uint8_t* byte = &soak_recv_bits(c->l, me->rbuf.sender)[seq >> 3];
            const uint8_t was = __atomic_fetch_or(byte, (uint8_t)(1u << (seq & 7)), __ATOMIC_SEQ_CST);
            if (was & (1u << (seq & 7))) ++me->dups;
            ++me->recvs_ok;
            progress(c, qi);
        }
    } else if (expired(r)) {
        ++me->recv_timeouts;
    } else {
        fail(c, r, SOAK_OP_RECV);
    }
    ST(me->recv_state, 0u);
    ST(me->rbuf.magic, 0u);
}

static void do_pv(ctx_t* c) {
    soak_worker_t* me = c->me;
    ST(me->sem_state, SOAK_SEM_P);
    int r = chm_rsem_p_timed(c->sem, timeout(c));
    if (expired(r)) {
        ++me->p_timeouts;
        ST(me->sem_state, SOAK_SEM_IDLE);
        return;
    }
    if (r != 0) {
        fail(c, r, SOAK_OP_PV);
        ST(me->sem_state, SOAK_SEM_IDLE);
        return;
    }
    ST(me->sem_state, SOAK_SEM_HELD);
    ++me->p_ok;
    progress(c, SOAK_OBJ_SEM);
    nap_us(rnd(c) % 2000); /* hold the unit a while: others wait for it */
    ST(me->sem_state, SOAK_SEM_V);
    /* -EBUSY: a live peer (a stopped one) held the lock 10 ms and the unit
     * was not given; rsem.h says call again, and the unit is ours until a
     * V takes it. A stop lasts at most a second: 30 s is a defect. */
    const uint64_t until = now_ns() + 30000000000ull;
    while ((r = chm_rsem_v(c->sem)) == -EBUSY && now_ns() < until) ++me->v_busy;
    if (r != 0) fail(c, r, SOAK_OP_PV);
    ST(me->sem_state, SOAK_SEM_IDLE);
}

/* Finish a write a dead holder left half done: words are written first to
 * last, so word 0 has the value the write was making. */
static void repair(ctx_t* c) {
    soak_shm_t* s = c->shm;
    if (!(LD(s->seq) & 1u)) return;
    const uint64_t v = LD(s->word[0]);
    for (int i = 1; i < SOAK_SHM_WORDS; ++i) ST(s->word[i], v);
    ST(s->seq, LD(s->seq) + 1u);
    ++c->me->repairs;
}

static void do_shm_write(ctx_t* c) {
    soak_worker_t* me = c->me;
    soak_shm_t* s = c->shm;
    ST(me->shm_state, SOAK_SHM_LOCKING);
    const int r = chm_spin_lock(&s->lock, 20000, timeout(c));
    if (expired(r)) {
        ++me->shm_busy;
        ST(me->shm_state, SOAK_SHM_IDLE);
        return;
    }
    if (r != 0 && r != -EOWNERDEAD) {
        fail(c, r, SOAK_OP_SHM_WRITE);
        ST(me->shm_state, SOAK_SHM_IDLE);
        return;
    }
    ST(me->shm_state, SOAK_SHM_WRITING); /* from here a death leaves the write in doubt */
    if (r == -EOWNERDEAD) {
        ++me->owner_dead;
        repair(c);
    }
    const uint64_t v = LD(s->word[0]) + 1u;
    ST(s->seq, LD(s->seq) + 1u); /* odd: writing */
    const uint64_t linger = rnd(c) % 2 ? rnd(c) % 1000 : 0;
    for (int i = 0; i < SOAK_SHM_WORDS; ++i) {
        ST(s->word[i], v);
        /* Half the writes linger halfway (up to 1 ms), so deaths and stops
         * land inside the lock and mid-write, not only between calls. */
        if (i == SOAK_SHM_WORDS / 2 - 1 && linger) nap_us(linger);
    }
    ST(s->seq, LD(s->seq) + 1u);
    ++me->shm_writes;
    progress(c, SOAK_OBJ_SHM);
    ST(me->shm_state, SOAK_SHM_UNLOCKING);
    const int u = chm_spin_unlock(&s->lock);
    if (u != 0) fail(c, u, SOAK_OP_SHM_WRITE);
    ST(me->shm_state, SOAK_SHM_IDLE);
}

static void do_shm_read(ctx_t* c) {
    soak_shm_t* s = c->shm;
    const uint64_t end = now_ns() + SOAK_OP_TIMEOUT_NS;
    for (unsigned spins = 0; now_ns() < end; ++spins) {
        const uint32_t s1 = LD(s->seq);
        if (!(s1 & 1u)) {
            uint64_t w[SOAK_SHM_WORDS];
            for (int i = 0; i < SOAK_SHM_WORDS; ++i) w[i] = LD(s->word[i]);
            if (LD(s->seq) == s1) {
                for (int i = 1; i < SOAK_SHM_WORDS; ++i)
                    if (w[i] != w[0]) {
                        ++c->me->torn;
                        fail(c, -EBADMSG, SOAK_OP_SHM_READ);
                        break;
                    }
                ++c->me->shm_reads;
                return;
            }
        }
        if (spins > 64) nap_us(100); /* a writer is stopped or dead: let others run */
    }
    ++c->me->shm_busy; /* odd for the whole bound: its writer stopped or died */
}

/* Express mail: ping a random RTPU (perhaps its own). A dead or absent
 * target answers -EHOSTDOWN, a stopped one lets the call time out, and a
 * stopped target's ring may stay full of abandoned requests (-EBUSY). */
static void do_ping(ctx_t* c) {
    soak_worker_t* me = c->me;
    chm_rtpu_info_t info;
    const int target = 1 + (int)(rnd(c) % c->l->rtpus);
    const int r = chm_rtpu_ping(target, &info);
    if (r == 0) {
        ++me->pings_ok;
        progress(c, SOAK_OBJ_MAIL);
    } else if (r == -EHOSTDOWN) {
        ++me->pings_down;
    } else if (r == -ETIMEDOUT || r == -EBUSY || (r == -EINTR && soak_worker_stop)) {
        ++me->pings_late;
    } else {
        fail(c, r, SOAK_OP_PING);
    }
}

static void svar_name(char* out, size_t n, unsigned r) { snprintf(out, n, "soak.v%u", r); }

/* Write its variable: every element one more than the last value (the
 * local copy starts with the global value, so a new incarnation goes on
 * from the last complete write of the dead one). A reader that sees
 * elements differ saw a torn value. */
static void do_svar_write(ctx_t* c) {
    char name[16];
    svar_name(name, sizeof name, (unsigned)c->writes_var);
    double* v = chm_svar_set_local(c->vars, name);
    const double next = v[0] + 1.0;
    for (int i = 0; i < SOAK_SVAR_ELEMS; ++i) v[i] = next;
    ST(c->me->svar_writing, 1u); /* from here a death leaves this write in doubt */
    const int r = chm_svar_set_write(c->vars);
    if (r == 0) {
        ++c->me->svar_writes;
        progress(c, SOAK_OBJ_SVAR);
    } else {
        fail(c, r, SOAK_OP_SVAR_WRITE);
    }
    ST(c->me->svar_writing, 0u);
}

/* Copy every input in: each must be one whole value (all elements equal)
 * and never older than one this incarnation saw before. */
static void do_svar_read(ctx_t* c) {
    const int r = chm_svar_set_read(c->vars);
    if (r == -EAGAIN) { /* an input changed under 64 attempts: kept the old copy */
        ++c->me->svar_retry;
    } else if (r != 0) {
        fail(c, r, SOAK_OP_SVAR_READ);
        return;
    }
    char name[16];
    for (unsigned k = 1; k <= c->n_vars; ++k) {
        if ((int)k == c->writes_var) continue;
        svar_name(name, sizeof name, k);
        const double* v = chm_svar_set_local(c->vars, name);
        for (int i = 1; i < SOAK_SVAR_ELEMS; ++i)
            if (v[i] != v[0]) {
                ++c->me->svar_torn;
                fail(c, -EBADMSG, SOAK_OP_SVAR_READ);
                snprintf(c->me->last_err_text, sizeof c->me->last_err_text,
                         "%s torn: element 0 = %.0f, element %d = %.0f", name, v[0], i, v[i]);
                break;
            }
        if (v[0] < c->seen[k]) {
            ++c->me->svar_back;
            fail(c, -EBADMSG, SOAK_OP_SVAR_READ);
            snprintf(c->me->last_err_text, sizeof c->me->last_err_text, "%s went back from %.0f to %.0f", name,
                     c->seen[k], v[0]);
        }
        if (v[0] > c->seen[k]) c->seen[k] = v[0];
    }
    ++c->me->svar_reads;
}

/* The worker's state-variable set. The first task of RTPU r (worker id
 * r-1) is soak.vr's one writer: its set claims it at once, and a dead
 * predecessor's claim must not stand in the way (svar.h: a writer whose
 * process died no longer counts), so -EBUSY is an error here, not a wait. */
static int open_vars(ctx_t* c) {
    char names[SOAK_SVAR_MAX][16];
    const char* in[SOAK_SVAR_MAX];
    const char* out[1];
    size_t n_in = 0;
    c->n_vars = c->l->rtpus;
    c->writes_var = c->id < c->l->rtpus ? (int)c->id + 1 : 0;
    for (unsigned k = 1; k <= c->n_vars; ++k) {
        svar_name(names[k - 1], sizeof names[k - 1], k);
        if ((int)k == c->writes_var) out[0] = names[k - 1];
        else in[n_in++] = names[k - 1];
    }
    char owner[24];
    snprintf(owner, sizeof owner, "soak-worker%u", c->id);
    const int r = chm_svar_set_create(owner, in, n_in, out, c->writes_var ? 1 : 0, &c->vars);
    if (r) return fprintf(stderr, "soak worker %u: state-variable set: %d %s\n", c->id, r, chm_bp_last_error()), r;
    if (c->writes_var) ++c->me->svar_claims;
    for (unsigned k = 1; k <= c->n_vars; ++k) {
        const double* v = chm_svar_set_local(c->vars, names[k - 1]);
        c->seen[k] = v ? v[0] : 0;
    }
    return 0;
}

static int open_all(ctx_t* c) {
    char name[32];
    for (int i = 0; i < SOAK_QUEUES; ++i) {
        snprintf(name, sizeof name, "soak.q%d", i);
        const int r = chm_msgq_open(name, &c->q[i]);
        if (r) return fprintf(stderr, "soak worker %u: open %s: %d\n", c->id, name, r), r;
    }
    int r = chm_rsem_open("soak.sem", &c->sem);
    if (r) return fprintf(stderr, "soak worker %u: open soak.sem: %d\n", c->id, r), r;
    void* p = NULL;
    r = chm_shm_attach("soak.shm", &p, NULL);
    if (r) return fprintf(stderr, "soak worker %u: attach soak.shm: %d\n", c->id, r), r;
    c->shm = (soak_shm_t*)p;
    return open_vars(c);
}

int soak_worker_run(const char* ledger_path, unsigned id, uint32_t inc, uint64_t seed) {
    const int fd = open(ledger_path, O_RDWR | O_CLOEXEC);
    if (fd < 0) return fprintf(stderr, "soak worker %u: %s: %s\n", id, ledger_path, strerror(errno)), 1;
    void* map = mmap(NULL, SOAK_LEDGER_SIZE, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    close(fd);
    if (map == MAP_FAILED) return fprintf(stderr, "soak worker %u: mmap: %s\n", id, strerror(errno)), 1;
    ctx_t c;
    memset(&c, 0, sizeof c);
    c.l = (soak_ledger_t*)map;
    if (c.l->layout != sizeof(soak_ledger_t))
        return fprintf(stderr, "soak worker %u: ledger layout %u bytes, this build %zu: rebuild\n", id, c.l->layout,
                       sizeof(soak_ledger_t)), 1;
    if (id >= c.l->workers) return fprintf(stderr, "soak worker %u: only %u workers\n", id, c.l->workers), 1;
    c.me = &c.l->w[id];
    c.id = id;
    c.rng = (seed ^ (0x9E3779B97F4A7C15ull * (id + 1)) ^ ((uint64_t)inc << 32)) | 1u;
    if (LD(c.me->inc) != inc)
        return fprintf(stderr, "soak worker %u: incarnation %u, the ledger says %u\n", id, inc, c.me->inc), 1;
    if (open_all(&c)) return 1;
    chm_rtpu_timeout_set(SOAK_OP_TIMEOUT_NS); /* every express-mail call of this process */
    ST(c.me->hb_ns, now_ns());
    ST(c.me->started, inc);
    while (!LD(c.me->quit) && !soak_worker_stop) {
        nap_us(rnd(&c) % 200); /* a gap between operations: ~5,000 a second at most */
        const uint64_t k = rnd(&c) % 100;
        unsigned op = k < 25 ? SOAK_OP_SEND : k < 50 ? SOAK_OP_RECV : k < 63 ? SOAK_OP_PV
                    : k < 72 ? SOAK_OP_SHM_WRITE : k < 81 ? SOAK_OP_SHM_READ : k < 87 ? SOAK_OP_SVAR_WRITE
                    : k < 92 ? SOAK_OP_SVAR_READ : k < 97 ? SOAK_OP_PING : SOAK_OP_PAUSE;
        if (op == SOAK_OP_SVAR_WRITE && !c.writes_var) op = SOAK_OP_SVAR_READ;
        ST(c.me->op, op);
        switch (op) {
        case SOAK_OP_SEND: do_send(&c); break;
        case SOAK_OP_RECV: do_recv(&c); break;
        case SOAK_OP_PV: do_pv(&c); break;
        case SOAK_OP_SHM_WRITE: do_shm_write(&c); break;
        case SOAK_OP_SHM_READ: do_shm_read(&c); break;
        case SOAK_OP_PING: do_ping(&c); break;
        case SOAK_OP_SVAR_WRITE: do_svar_write(&c); break;
        case SOAK_OP_SVAR_READ: do_svar_read(&c); break;
        default: nap_us(rnd(&c) % 1000); break;
        }
        ++c.me->op_count[op];
        ST(c.me->op, (uint32_t)SOAK_OP_IDLE);
        ST(c.me->hb_ns, now_ns());
    }
    if (chm_svar_set_destroy(c.vars) != 0) fail(&c, -ETIMEDOUT, SOAK_OP_SVAR_WRITE); /* its claim ends now */
    ST(c.me->done, inc);
    return 0;
}
