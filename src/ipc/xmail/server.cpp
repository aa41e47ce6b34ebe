// Express mail, the server's side (xmail.hpp): one task per RTPU sleeps on
// a local semaphore that the express-mail interrupt's handler Vs, and on
// each wake serves every posted record of its ring, oldest first: it takes
// the record (POSTED -> SERVING), runs the request, writes the reply in
// place and grants the sender's reply word.
#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>

#include <unistd.h>

#include "chimera/irq.h"
#include "chimera/kernel.h"
#include "chimera/mem.h"
#include "chimera/program.h"
#include "chimera/sem.h"
#include "ipc/servo/servo.hpp"
#include "chimera/usig.h"
#include "ipc/wake/wake.hpp"
#include "ipc/xmail/xmail.hpp"
#include "kernel.hpp"

namespace chm::xmail {

namespace {

constexpr auto R = std::memory_order_relaxed;
constexpr auto Acq = std::memory_order_acquire;
constexpr auto Rel = std::memory_order_release;

struct Server {
    bool started = false;
    bool stopping = false;
    chm_sem_t wake;
    chm_tid_t task = CHM_TID_NONE;
    bp::RingHeader* ring = nullptr;
    std::uint32_t token = 0;
    std::uint64_t started_ns = 0;
    std::uint32_t served = 0;
    char* req = nullptr;    // a copy of the request being served
    char* rep = nullptr;    // its reply, built here
    std::uint32_t room = 0; // payload bytes of one record
    struct Posted {
        std::uint32_t seq, index;
    }* posted = nullptr;    // capacity entries
    int stop_code = 0;
    bool stop_after = false;
};
Server g_s;
DeferFn g_deferred[kKindEnd] = {};

void on_interrupt(int, void*) { (void)chm_sem_v(&g_s.wake); }

// ------------------------------------------------------------- requests

int do_ping(char* rep, std::uint32_t* n) {
    PingReply p{};
    p.pid = std::int32_t(::getpid());
    p.tasks = std::uint32_t(chm_task_count());
    p.policy = std::uint32_t(chm_kernel_policy());
    p.served = g_s.served;
    p.uptime_ns = port::now_ns() - g_s.started_ns;
    std::memcpy(rep, &p, sizeof p);
    *n = sizeof p;
    return 0;
}

int do_spawn(const char* req, std::uint32_t len, char* rep, std::uint32_t* n, std::uint32_t from) {
    SpawnArgs args;
    if (int e = decode_spawn(req, len, &args)) return e;
    chm_tid_t tid = CHM_TID_NONE;
    const int prog = chm_program_load(args.path, args.argc, args.argv, nullptr, &tid);
    SpawnReply out{tid, prog, 0};
    std::memcpy(rep, &out, sizeof out);
    *n = sizeof out;
    if (prog < 0) {
        const char* why = chm_program_error();
        // A refused path is an attempt someone may want to trace: the log
        // says which slot asked (its process is whoever holds that slot).
        if (prog == -EACCES) {
            const bp::Attachment* a = bp::current();
            std::fprintf(stderr, "chimera-rtpu: RTPU %d: refused a spawn request from slot %u: %s\n",
                         a ? int(a->slot) : -1, unsigned(from), why);
        }
        const std::uint32_t room = g_s.room - sizeof out;
        const std::uint32_t k = std::uint32_t(std::min<std::size_t>(std::strlen(why), room - 1));
        std::memcpy(rep + sizeof out, why, k);
        rep[sizeof out + k] = 0;
        *n += k + 1;
        return prog;
    }
    return 0;
}

int do_task(Kind kind, const char* req, std::uint32_t len) {
    TaskRequest t;
    if (len < sizeof t) return -EINVAL;
    std::memcpy(&t, req, sizeof t);
    if (kind == kSignal) return chm_usig_send(t.tid, t.signo);
    if (t.tid == g_s.task) return -EPERM;  // express mail would die with it
    return chm_task_destroy(t.tid);
}

int do_find(const char* req, std::uint32_t len, char* rep, std::uint32_t* n) {
    FindRequest f;
    if (len < sizeof f) return -EINVAL;
    std::memcpy(&f, req, sizeof f);
    f.name[CHM_TASK_NAME_MAX] = 0;
    chm_tid_t tid = CHM_TID_NONE;
    if (int e = chm_task_find(f.name, &tid)) return e;
    std::int64_t out = tid;
    std::memcpy(rep, &out, sizeof out);
    *n = sizeof out;
    return 0;
}

// One page of the task list, from TCB slot `start` on.
int do_tasks(const char* req, std::uint32_t len, char* rep, std::uint32_t* n) {
    TasksRequest q;
    if (len < sizeof q) return -EINVAL;
    std::memcpy(&q, req, sizeof q);
    const std::uint32_t fit = (g_s.room - sizeof(TasksReply)) / sizeof(TaskEntry);
    if (fit == 0) return -EMSGSIZE;
    chm_tid_t ids[64];
    const std::uint32_t want = std::min<std::uint32_t>(std::min<std::uint32_t>(fit, 64), q.max ? q.max : 1);
    std::uint32_t count = 0, total = 0, next = kTasksEnd;
    {
        kernel::IrqGuard guard;
        const kernel::Kernel& k = kernel::g_k;
        for (std::uint32_t i = 0; i < k.tcb_hw; ++i) {
            const kernel::Tcb& t = k.tcbs[i];
            if (!t.used || t.state == kernel::TaskState::Ended) continue;
            ++total;
            if (i < q.start || next != kTasksEnd) continue;
            if (count == want) {
                next = i;
                continue;
            }
            ids[count++] = kernel::tid_of(&t);
        }
    }
    TasksReply h{total, next, 0, sizeof(TaskEntry)};
    char* out = rep + sizeof h;
    for (std::uint32_t i = 0; i < count; ++i) {
        chm_task_status_t st;
        if (chm_task_status(ids[i], &st) != 0) continue;  // ended meanwhile
        TaskEntry e{};
        e.id = st.id;
        e.state = std::uint32_t(st.state);
        e.priority = st.priority;
        e.critical = std::uint32_t(st.critical);
        e.period_ns = st.period_ns;
        e.cpu_ns = st.cpu_ns;
        e.cycles = st.cycles;
        e.misses = st.misses;
        e.deadline_ns = st.deadline_ns;
        e.wcet_ns = st.wcet_ns;
        e.worst_lateness_ns = st.worst_lateness_ns;
        e.worst_cycle_cpu_ns = st.worst_cycle_cpu_ns;
        e.stack_size = st.stack_size;
        e.stack_high_water = st.stack_high_water;
        std::memcpy(e.name, st.name, sizeof e.name);
        e.name[CHM_TASK_NAME_MAX] = 0;
        std::memcpy(out + std::size_t(h.count) * sizeof e, &e, sizeof e);
        ++h.count;
    }
    std::memcpy(rep, &h, sizeof h);
    *n = std::uint32_t(sizeof h + std::size_t(h.count) * sizeof(TaskEntry));
    return 0;
}

int dispatch(Kind kind, const char* req, std::uint32_t len, char* rep, std::uint32_t* n, std::uint32_t owner) {
    *n = 0;
    const std::uint32_t from = bp::token_slot(owner);
    switch (kind) {
    case kServo: return servo::serve(req, len, rep, g_s.room, n, owner);
    case kPing: return do_ping(rep, n);
    case kSpawn: return do_spawn(req, len, rep, n, from);
    case kSignal:
    case kDestroy: return do_task(kind, req, len);
    case kFind: return do_find(req, len, rep, n);
    case kTasks: return do_tasks(req, len, rep, n);
    case kStop: {
        StopRequest s;
        if (len < sizeof s) return -EINVAL;
        std::memcpy(&s, req, sizeof s);
        g_s.stop_code = s.code;
        g_s.stop_after = true;  // after the reply is out
        return 0;
    }
    default: return -EPROTO;
    }
}

// ------------------------------------------------------------- serving

void serve(Record* r, std::uint32_t seq) {
    std::uint32_t st = make_state(seq, kPosted);
    if (!r->state.compare_exchange_strong(st, make_state(seq, kServing), Acq, R)) return;
    r->server = g_s.token;
    const std::uint32_t len = std::min(r->len, g_s.room);
    const Kind kind = Kind(r->kind);
    std::memcpy(g_s.req, payload_of(r), len);
    if (kind < kKindEnd && g_deferred[kind]) {
        ++g_s.served;
        g_s.ring->reserved[0] = g_s.served;
        const bp::Attachment* a = bp::current();
        const std::uint32_t index = std::uint32_t(
            (reinterpret_cast<char*>(r) - reinterpret_cast<char*>(g_s.ring + 1)) / ring_record_size(*a));
        g_deferred[kind](r, seq, index, g_s.req, len, r->owner.load(R));
        return;
    }
    std::uint32_t n = 0;
    const int status = dispatch(kind, g_s.req, len, g_s.rep, &n, r->owner.load(R));
    ++g_s.served;
    g_s.ring->reserved[0] = g_s.served;
    finish(r, seq, status, g_s.rep, n);
}

}  // namespace

void set_deferred(Kind kind, DeferFn fn) {
    if (kind < kKindEnd) g_deferred[kind] = fn;
}

void finish(Record* r, std::uint32_t seq, int status, const void* reply, std::uint32_t n) {
    r->status = status;
    r->len = n;
    if (n) std::memcpy(payload_of(r), reply, n);
    std::uint32_t st = make_state(seq, kServing);
    if (!r->state.compare_exchange_strong(st, make_state(seq, kReplied), Rel, R)) {
        r->state.store(make_state(seq, kFree), Rel);  // the sender gave up: the record is ours to free
        return;
    }
    const std::uint32_t owner = r->owner.load(R);
    ipc::grant_word(reinterpret_cast<std::uint32_t*>(&r->reply), 1, bp::token_slot(owner),
                    ipc::WaiterId{r->waiter_task.load(R), r->waiter_urgency.load(R)});
}

namespace {

// Serve every posted record, oldest first; free what dead senders left.
void serve_all() {
    bp::Attachment* a = bp::current();
    if (!a) return;
    bp::RingHeader* ring = g_s.ring;
    reclaim(*a, ring);
    std::uint32_t k = 0;
    for (std::uint32_t i = 0; i < ring_capacity(*a); ++i) {
        const std::uint32_t st = record_at(*a, ring, i)->state.load(Acq);
        if (phase_of(st) == kPosted) g_s.posted[k++] = {seq_of(st), i};
    }
    // Wrap-safe order of 28-bit sequence numbers.
    std::sort(g_s.posted, g_s.posted + k, [](const Server::Posted& x, const Server::Posted& y) {
        return std::int32_t((x.seq - y.seq) << 4) < 0;
    });
    for (std::uint32_t j = 0; j < k; ++j) {
        serve(record_at(*a, ring, g_s.posted[j].index), g_s.posted[j].seq);
        if (g_s.stop_after) {
            g_s.stop_after = false;
            chm_kernel_stop(g_s.stop_code);  // does not return
        }
    }
}

void server_main(void*) {
    for (;;) {
        serve_all();
        (void)chm_sem_p(&g_s.wake);
        while (chm_sem_try_p(&g_s.wake) == 0) {
        }  // one scan serves every ring that came meanwhile
    }
}

}  // namespace

int decode_spawn(const char* req, std::uint32_t len, SpawnArgs* out) {
    SpawnRequest h;
    if (len < sizeof h) return -EINVAL;
    std::memcpy(&h, req, sizeof h);
    if (h.argc < 0 || h.text_len > len - sizeof h || h.text_len == 0) return -EINVAL;
    const char* text = req + sizeof h;
    if (text[h.text_len - 1] != 0) return -EINVAL;  // so every strlen below stops inside
    if (h.argc > kSpawnArgsMax) return -E2BIG;
    // path, then argc strings, all inside the text.
    const char* p = text;
    const char* end = text + h.text_len;
    out->path = p;
    p += std::strlen(p) + 1;
    for (int i = 0; i < h.argc; ++i) {
        if (p >= end) return -EINVAL;
        out->argv[i] = p;
        p += std::strlen(p) + 1;
    }
    out->argc = h.argc;
    return 0;
}

int server_start(int priority) {
    bp::Attachment* a = bp::current();
    if (!a || a->kind != bp::SlotKind::Rtpu) return -ENOTCONN;
    if (g_s.started) return -EBUSY;
    bp::RingHeader* ring = a->ring(a->slot);
    if (ring_record_size(*a) < kRecordMin) return -EMSGSIZE;
    chm_free(g_s.req);  // a previous start's (a kernel started again)
    chm_free(g_s.rep);
    chm_free(g_s.posted);
    g_s = Server{};
    g_s.room = ring_record_size(*a) - sizeof(Record);
    g_s.req = static_cast<char*>(chm_malloc(g_s.room));
    g_s.rep = static_cast<char*>(chm_malloc(g_s.room));
    g_s.posted = static_cast<Server::Posted*>(chm_malloc(sizeof(Server::Posted) * ring_capacity(*a)));
    auto undo = [] {
        chm_free(g_s.req);
        chm_free(g_s.rep);
        chm_free(g_s.posted);
        g_s = Server{};
    };
    if (!g_s.req || !g_s.rep || !g_s.posted) return undo(), -ENOMEM;
    // Counting, not binary: a binary semaphore belongs to the task that
    // took it, and this one is only a wake-up.
    if (int e = chm_sem_init(&g_s.wake, CHM_SEM_COUNTING, 0, 0)) return undo(), e;

    // What a dead predecessor of this slot left: requests it took and
    // never answered, and requests abandoned to it. Posted requests of
    // live senders stay and are served.
    for (std::uint32_t i = 0; i < ring_capacity(*a); ++i) {
        Record* r = record_at(*a, ring, i);
        std::uint32_t st = r->state.load(Acq);
        const Phase p = phase_of(st);
        if (p == kServing || p == kAbandoned)
            r->state.compare_exchange_strong(st, make_state(seq_of(st), kFree), Rel, R);
    }
    reclaim(*a, ring);

    g_s.ring = ring;
    g_s.token = a->token;
    g_s.started_ns = port::now_ns();
    chm_task_attr_t attr;
    chm_task_attr_init(&attr);
    attr.name = "xmail";
    attr.priority = priority;
    attr.stack_size = 256 * 1024;  // dlopen of a program runs on it
    if (int e = chm_task_spawn(&g_s.task, server_main, nullptr, &attr)) {
        (void)chm_sem_destroy(&g_s.wake);
        return undo(), e;
    }
    if (int e = chm_irq_install(ipc::kVecExpressMail, on_interrupt, nullptr)) {
        (void)chm_task_destroy(g_s.task);
        (void)chm_sem_destroy(&g_s.wake);
        return undo(), e;
    }
    g_s.started = true;
    ring->tail.store(a->token, Rel);  // serving
    return 0;
}

// The server task and its semaphore are left to chm_kernel_fini (the
// kernel no longer runs tasks here); the task may be waiting on it.
void server_stop() {
    if (!g_s.started) return;
    if (g_s.ring) {
        std::uint32_t t = g_s.token;
        g_s.ring->tail.compare_exchange_strong(t, 0, Rel, R);
    }
    (void)chm_irq_remove(ipc::kVecExpressMail);
    g_s.started = false;
    g_s.ring = nullptr;
}

chm_tid_t server_task() { return g_s.task; }

}  // namespace chm::xmail
