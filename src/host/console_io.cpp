// Concurrent stdio of an RTPU's tasks (console.hpp): stdout and stderr
// become unbuffered fopencookie streams, so each printf reaches
// console_write once with its whole text; the text is cut into lines per
// task (a task preempted mid-line keeps its half line to itself), whole
// lines go into a process queue, and a low-priority drainer task sends
// them to the host server in batches (one express-mail request each), which
// passes them to the console that owns this RTPU. stdin becomes a stream
// whose reads ask the host server for a line of the console's input.
//
// A printing task never waits on the host: it waits only when the queue
// (32 KiB) is full, until the drainer has made room. Outside a task (the
// kernel thread before chm_kernel_run, other threads), when no host server
// answers and when no console owns this RTPU, text goes to the RTPU's log
// as before.
#include "host/console.hpp"

#include <cerrno>
#include <cstring>

#include <fcntl.h>
#include <unistd.h>

#include "chimera/kernel.h"
#include "chimera/sem.h"
#include "chimera/task.h"
#include "host/client.hpp"
#include "kernel.hpp"
#include "port.hpp"

namespace chm::host::console {

namespace {

constexpr std::uint32_t kQueueBytes = 32 * 1024;
constexpr std::uint32_t kLineMax = 480;  // longer lines go out in pieces
constexpr int kPartials = 32;            // tasks with a half-written line

struct Partial {
    chm_tid_t tid = CHM_TID_NONE;
    std::uint8_t stream = 0;
    std::uint16_t len = 0;
    char text[kLineMax];
};

struct State {
    bool started = false;
    int log_fd[3] = {-1, -1, -1};  // the process's own fds 0..2, kept
    FILE* saved[3] = {};           // stdin, stdout, stderr as they were
    Partial partial[kPartials];
    char queue[kQueueBytes];       // Entry + text, back to back, ring
    std::uint32_t head = 0, tail = 0;  // byte counters (mod kQueueBytes)
    chm_sem_t ready;               // V per entry queued
    chm_tid_t drainer = CHM_TID_NONE;
    std::uint32_t dropped = 0;     // lines written to the log (or dropped) instead
    bool drop_orphans = false;     // no console owns this RTPU: drop, not log
};
State g;

bool in_task() { return port::on_kernel_thread() && kernel::g_k.current && !kernel::g_k.in_irq; }

std::uint32_t used() { return g.head - g.tail; }

void ring_put(const void* src, std::uint32_t n) {
    const char* p = static_cast<const char*>(src);
    for (std::uint32_t i = 0; i < n; ++i) g.queue[(g.head + i) % kQueueBytes] = p[i];
    g.head += n;
}

// Copy n bytes from `at` bytes past the tail; nothing is taken out.
void ring_peek(std::uint32_t at, void* dst, std::uint32_t n) {
    char* p = static_cast<char*>(dst);
    for (std::uint32_t i = 0; i < n; ++i) p[i] = g.queue[(g.tail + at + i) % kQueueBytes];
}

void to_log(int stream, const char* text, std::size_t n) {
    const int fd = g.log_fd[stream] >= 0 ? g.log_fd[stream] : stream;
    while (n) {
        const ssize_t w = ::write(fd, text, n);
        if (w <= 0) return;
        text += w;
        n -= std::size_t(w);
    }
}

// Queue one line (or piece) of task `tid`; waits while the queue is full.
void enqueue(std::uint8_t stream, chm_tid_t tid, const char* text, std::uint16_t len) {
    const Entry e{stream, 0, len, std::int32_t(tid)};
    for (;;) {
        {
            kernel::IrqGuard guard;
            if (kQueueBytes - used() >= sizeof e + len) {
                ring_put(&e, sizeof e);
                ring_put(text, len);
                break;
            }
        }
        chm_task_pause_until(chm_time_now() + 1'000'000);  // the drainer makes room
    }
    (void)chm_sem_v(&g.ready);
}

// Append text of the running task to its half line; queue what completes.
void task_write(std::uint8_t stream, const char* buf, std::size_t n) {
    const chm_tid_t self = chm_task_self();
    while (n) {
        Partial* p = nullptr;
        {
            kernel::IrqGuard guard;
            Partial* free_one = nullptr;
            for (Partial& q : g.partial) {
                if (q.tid == self && q.stream == stream) p = &q;
                if (q.tid == CHM_TID_NONE && !free_one) free_one = &q;
            }
            if (!p && free_one) {
                p = free_one;
                p->tid = self;
                p->stream = stream;
                p->len = 0;
            }
        }
        if (!p) {  // more than kPartials tasks mid-line: this text goes as it is
            const std::uint16_t k = std::uint16_t(n < kLineMax ? n : kLineMax);
            enqueue(stream, self, buf, k);
            buf += k;
            n -= k;
            continue;
        }
        // Only this task touches its own entry.
        const char* nl = static_cast<const char*>(std::memchr(buf, '\n', n));
        const std::size_t take = nl ? std::size_t(nl - buf) + 1 : n;
        const std::size_t room = kLineMax - p->len;
        const std::size_t k = take < room ? take : room;
        std::memcpy(p->text + p->len, buf, k);
        p->len = std::uint16_t(p->len + k);
        buf += k;
        n -= k;
        if (p->len == kLineMax || p->text[p->len - 1] == '\n') {
            enqueue(stream, self, p->text, p->len);
            kernel::IrqGuard guard;
            p->tid = CHM_TID_NONE;
        }
    }
}

ssize_t cookie_write(void* c, const char* buf, size_t n) {
    const std::uint8_t stream = std::uint8_t(reinterpret_cast<std::intptr_t>(c));
    if (!g.started || !in_task()) {
        to_log(stream, buf, n);
        return ssize_t(n);
    }
    task_write(stream, buf, n);
    return ssize_t(n);
}

ssize_t cookie_read(void*, char* buf, size_t n) {
    if (!g.started || !in_task()) return ::read(g.log_fd[0] >= 0 ? g.log_fd[0] : 0, buf, n);
    const std::uint32_t room = inline_room() + std::uint32_t(sizeof(HostRequest));
    const std::uint32_t want = std::uint32_t(n < room ? n : room);
    HostRequest h{};
    h.op = kIn;
    h.a = std::uint64_t(chm_task_self());  // 64 bits: not in fd
    h.b = want;
    std::uint32_t got = 0;
    // However long the user takes to type: a dead host server is still
    // seen within one 20 ms slice.
    const int r = request(h, nullptr, 0, buf, want, &got, "stdin", UINT64_MAX / 4);
    if (r < 0) {
        errno = -r;
        return -1;
    }
    return ssize_t(r < int(got) ? r : int(got));
}

// The drainer: batches of whole entries, one request each, in order. A
// batch stays in the queue until its request has completed (delivered, or
// written to the log): an RTPU stopped while the request is under way
// still has the lines, and stop() writes them to the log.
void drain(void*) {
    char batch[2048];
    for (;;) {
        (void)chm_sem_p(&g.ready);
        while (chm_sem_try_p(&g.ready) == 0) {
        }
        for (;;) {
            const std::uint32_t room = inline_room() < sizeof batch ? inline_room() : sizeof batch;
            std::uint32_t n = 0;
            {
                kernel::IrqGuard guard;
                const std::uint32_t queued = used();
                while (queued - n >= sizeof(Entry)) {
                    Entry e;
                    ring_peek(n, &e, sizeof e);
                    const std::uint32_t k = sizeof e + e.len;
                    if (n + k > room) break;
                    ring_peek(n, batch + n, k);
                    n += k;
                }
            }
            if (!n) break;
            HostRequest h{};
            h.op = kOut;
            const int r = request(h, batch, n, nullptr, 0, nullptr, "console output", 0);
            if (r == -ENOTCONN && g.drop_orphans) {
                g.dropped += 1;  // no console owns this RTPU, and its output is not kept
            } else if (r < 0) {
                // No host server, or no console owns this RTPU: the lines
                // go to the log, none lost.
                for (std::uint32_t off = 0; off + sizeof(Entry) <= n;) {
                    Entry e;
                    std::memcpy(&e, batch + off, sizeof e);
                    to_log(e.stream, batch + off + sizeof e, e.len);
                    off += sizeof e + e.len;
                    ++g.dropped;
                }
            }
            kernel::IrqGuard guard;
            g.tail += n;  // only the drainer takes out, only here
        }
    }
}

}  // namespace

int start(int priority, bool drop_orphans) {
    if (g.started) return -EBUSY;
    g.drop_orphans = drop_orphans;
    if (inline_room() < sizeof(Entry) + kLineMax) return -EMSGSIZE;
    if (int e = chm_sem_init(&g.ready, CHM_SEM_COUNTING, 0, 0)) return e;
    for (int fd = 0; fd < 3; ++fd) g.log_fd[fd] = ::fcntl(fd, F_DUPFD_CLOEXEC, 10);
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "stdio";
    a.priority = priority;
    if (int e = chm_task_spawn(&g.drainer, drain, nullptr, &a)) {
        (void)chm_sem_destroy(&g.ready);
        return e;
    }
    std::fflush(nullptr);
    cookie_io_functions_t out{nullptr, cookie_write, nullptr, nullptr};
    cookie_io_functions_t in{cookie_read, nullptr, nullptr, nullptr};
    FILE* o = fopencookie(reinterpret_cast<void*>(std::intptr_t(1)), "w", out);
    FILE* e = fopencookie(reinterpret_cast<void*>(std::intptr_t(2)), "w", out);
    FILE* i = fopencookie(nullptr, "r", in);
    if (!o || !e || !i) return -ENOMEM;
    // Unbuffered: one printf is one write of its whole text (glibc formats
    // into a local buffer first), so lines are cut per task, not per FILE.
    setvbuf(o, nullptr, _IONBF, 0);
    setvbuf(e, nullptr, _IONBF, 0);
    g.saved[0] = stdin;
    g.saved[1] = stdout;
    g.saved[2] = stderr;
    stdin = i;
    stdout = o;
    stderr = e;
    g.started = true;
    return 0;
}

void stop() {
    if (!g.started) return;
    g.started = false;  // writes go to the log from here on
    // What is still queued goes to the log, in order. That includes a
    // batch whose request the stop interrupted: it may also have reached
    // the console, but a line is never lost.
    while (used() >= sizeof(Entry)) {
        Entry e;
        ring_peek(0, &e, sizeof e);
        char text[kLineMax];
        ring_peek(sizeof e, text, e.len);
        g.tail += sizeof e + e.len;
        to_log(e.stream, text, e.len);
    }
    for (Partial& p : g.partial)
        if (p.tid != CHM_TID_NONE) to_log(p.stream, p.text, p.len), p.tid = CHM_TID_NONE;
    stdin = g.saved[0];
    stdout = g.saved[1];
    stderr = g.saved[2];
}

}  // namespace chm::host::console
