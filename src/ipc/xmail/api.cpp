// The public calls of chimera/rtpu.h: each builds one request (or, for the
// task list, one per page), sends it through express mail and unpacks the
// reply.
#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <cstring>

#include "chimera/rtpu.h"
#include "chimera/usig.h"
#include "ipc/xmail/xmail.hpp"
#include "port.hpp"

using namespace chm::xmail;

namespace {

// In µs, 32 bits: a 64-bit atomic is a libatomic call on m68k. Up to
// UINT32_MAX µs (71 minutes); longer settings are cut to that.
std::atomic<std::uint32_t> g_timeout_us{std::uint32_t(CHM_RTPU_TIMEOUT_DEFAULT_NS / 1000)};

// Replies are small and fixed (task lists come in pages sized to fit), so
// they go on the caller's stack: tasks of one RTPU share a thread, and so
// any thread_local buffer.
constexpr std::uint32_t kPage = 8;  // task entries per request
constexpr std::size_t kReplyMax = sizeof(TasksReply) + kPage * sizeof(TaskEntry);

int fail(int e, const char* what) {
    if (!chm_rtpu_last_error()[0]) set_error("%s", what);
    return e;
}

// The server's status names its own problem; say so when it failed.
int remote(int rtpu, Kind kind, const void* req, std::uint32_t len, char* reply, std::uint32_t* n,
           std::uint64_t timeout) {
    const int r = call(rtpu, kind, req, len, reply, kReplyMax, n, timeout);
    if (r < 0 && !chm_rtpu_last_error()[0])
        set_error("RTPU %d refused the request: %s", rtpu, std::strerror(-r));
    return r;
}

}  // namespace

extern "C" {

void chm_rtpu_timeout_set(uint64_t timeout_ns) {
    const std::uint64_t ns = timeout_ns ? timeout_ns : CHM_RTPU_TIMEOUT_DEFAULT_NS;
    const std::uint64_t us = ns / 1000 ? ns / 1000 : 1;
    g_timeout_us.store(us > UINT32_MAX ? UINT32_MAX : std::uint32_t(us), std::memory_order_relaxed);
}

uint64_t chm_rtpu_timeout(void) {
    return std::uint64_t(g_timeout_us.load(std::memory_order_relaxed)) * 1000u;
}

int chm_rtpu_ping(int rtpu, chm_rtpu_info_t* info) {
    set_error("%s", "");
    char reply[kReplyMax];
    std::uint32_t n = 0;
    const int r = remote(rtpu, kPing, nullptr, 0, reply, &n, chm_rtpu_timeout());
    if (r < 0) return r;
    if (n < sizeof(PingReply)) return fail(-EPROTO, "short ping reply");
    PingReply p;
    std::memcpy(&p, reply, sizeof p);
    if (info) {
        info->pid = p.pid;
        info->tasks = p.tasks;
        info->policy = chm_sched_policy(p.policy);
        info->served = p.served;
        info->uptime_ns = p.uptime_ns;
    }
    return 0;
}

int chm_rtpu_spawn(int rtpu, const char* path, int argc, const char* const* argv, chm_tid_t* tid) {
    set_error("%s", "");
    if (!path || !*path || argc < 0 || (argc > 0 && !argv)) return fail(-EINVAL, "bad spawn arguments");
    // The request: header, path NUL, each argument NUL (heap: it may be
    // larger than a task's stack should carry).
    std::size_t size = sizeof(SpawnRequest) + std::strlen(path) + 1;
    for (int i = 0; i < argc; ++i) size += std::strlen(argv[i] ? argv[i] : "") + 1;
    if (size > 65536) return fail(-EMSGSIZE, "spawn request longer than 64 KiB");
    char* req = static_cast<char*>(std::malloc(size));
    if (!req) return fail(-ENOMEM, "no memory for the spawn request");
    std::size_t off = sizeof(SpawnRequest);
    auto put = [&](const char* s) {
        const std::size_t k = std::strlen(s ? s : "") + 1;
        std::memcpy(req + off, s ? s : "", k);
        off += k;
    };
    put(path);
    for (int i = 0; i < argc; ++i) put(argv[i]);
    const SpawnRequest h{argc, std::uint32_t(off - sizeof h)};
    std::memcpy(req, &h, sizeof h);
    char reply[1024];  // a record's payload at most (1 KiB records): the loader's whole message
    std::uint32_t n = 0;
    const int r = call(rtpu, kSpawn, req, std::uint32_t(off), reply, sizeof reply - 1, &n, chm_rtpu_timeout());
    std::free(req);
    SpawnReply rep{CHM_TID_NONE, -1, 0};
    if (n >= sizeof rep) std::memcpy(&rep, reply, sizeof rep);
    if (r < 0) {
        if (!chm_rtpu_last_error()[0]) {
            reply[n < sizeof reply - 1 ? n : sizeof reply - 1] = 0;
            // The loader's message names the file and the cause once.
            const char* why = n > sizeof rep ? reply + sizeof rep : "";
            if (*why) set_error("RTPU %d cannot load %s", rtpu, why);
            else set_error("RTPU %d cannot load %s: %s", rtpu, path, std::strerror(-r));
        }
        return r;
    }
    if (n < sizeof rep) return fail(-EPROTO, "short spawn reply");
    if (tid) *tid = rep.tid;
    return 0;
}

int chm_rtpu_signal(int rtpu, chm_tid_t task, int signo) {
    set_error("%s", "");
    if (signo < 1 || signo > CHM_USIG_MAX) return fail(-EINVAL, "signal number outside 1..31");
    TaskRequest q{task, signo, 0};
    char reply[kReplyMax];
    std::uint32_t n = 0;
    return remote(rtpu, kSignal, &q, sizeof q, reply, &n, chm_rtpu_timeout());
}

int chm_rtpu_destroy(int rtpu, chm_tid_t task) {
    set_error("%s", "");
    TaskRequest q{task, 0, 0};
    char reply[kReplyMax];
    std::uint32_t n = 0;
    return remote(rtpu, kDestroy, &q, sizeof q, reply, &n, chm_rtpu_timeout());
}

int chm_rtpu_find(int rtpu, const char* name, chm_tid_t* tid) {
    set_error("%s", "");
    if (!name || !tid) return fail(-EINVAL, "NULL name or tid");
    if (std::strlen(name) > CHM_TASK_NAME_MAX) return fail(-EINVAL, "task name longer than 31");
    FindRequest q{};
    std::memcpy(q.name, name, std::strlen(name));
    char reply[kReplyMax];
    std::uint32_t n = 0;
    const int r = remote(rtpu, kFind, &q, sizeof q, reply, &n, chm_rtpu_timeout());
    if (r < 0) return r;
    if (n < sizeof(std::int64_t)) return fail(-EPROTO, "short find reply");
    std::int64_t id;
    std::memcpy(&id, reply, sizeof id);
    *tid = id;
    return 0;
}

int chm_rtpu_tasks(int rtpu, chm_rtpu_task_t* out, int max, int* total) {
    set_error("%s", "");
    if (max < 0 || (max > 0 && !out)) return fail(-EINVAL, "bad output array");
    const std::uint64_t timeout = chm_rtpu_timeout();
    const std::uint64_t deadline = chm::port::now_ns() + timeout;
    int filled = 0;
    TasksRequest q{0, kPage};
    char reply[kReplyMax];
    for (;;) {
        const std::uint64_t now = chm::port::now_ns();
        if (now >= deadline) return fail(-ETIMEDOUT, "task list not complete within the timeout");
        std::uint32_t n = 0;
        const int r = remote(rtpu, kTasks, &q, sizeof q, reply, &n, deadline - now);
        if (r < 0) return r;
        TasksReply h;
        if (n < sizeof h) return fail(-EPROTO, "short task list reply");
        std::memcpy(&h, reply, sizeof h);
        if (h.entry_size != sizeof(TaskEntry)) {
            set_error("RTPU %d lists tasks in %u-byte entries, this library reads %zu-byte ones: chimera-rtpu and "
                      "this program come from different Chimera versions", rtpu, h.entry_size, sizeof(TaskEntry));
            return -EPROTO;
        }
        if (sizeof h + std::size_t(h.count) * sizeof(TaskEntry) > n) return fail(-EPROTO, "bad task list reply");
        if (total) *total = int(h.total);
        for (std::uint32_t i = 0; i < h.count && filled < max; ++i) {
            TaskEntry e;
            std::memcpy(&e, reply + sizeof h + std::size_t(i) * sizeof e, sizeof e);
            chm_rtpu_task_t& o = out[filled++];
            std::memset(&o, 0, sizeof o);
            o.id = e.id;
            std::memcpy(o.name, e.name, sizeof o.name);
            o.name[CHM_TASK_NAME_MAX] = 0;
            o.state = chm_task_state(e.state);
            o.priority = e.priority;
            o.critical = int(e.critical);
            o.period_ns = e.period_ns;
            o.cpu_ns = e.cpu_ns;
            o.cycles = e.cycles;
            o.misses = e.misses;
            o.deadline_ns = e.deadline_ns;
            o.wcet_ns = e.wcet_ns;
            o.worst_lateness_ns = e.worst_lateness_ns;
            o.worst_cycle_cpu_ns = e.worst_cycle_cpu_ns;
            o.stack_size = e.stack_size;
            o.stack_high_water = e.stack_high_water;
        }
        if (h.next == kTasksEnd || filled >= max) return filled;
        q.start = h.next;
    }
}

int chm_rtpu_stop(int rtpu, int code) {
    set_error("%s", "");
    StopRequest q{code};
    char reply[kReplyMax];
    std::uint32_t n = 0;
    return remote(rtpu, kStop, &q, sizeof q, reply, &n, chm_rtpu_timeout());
}

}  // extern "C"
