// The host server's request path (server.hpp): the server task copies each
// kHost request into the job of its ring record and queues it; a worker
// thread decodes it (the request is untrusted: every length, handle and
// buffer index is checked), does the work and answers with xmail::finish.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cerrno>
#include <condition_variable>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <thread>
#include <vector>

#include <fcntl.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "chimera/bp.h"
#include "chimera/shm.h"
#include "chimera/xfs.h"
#include "host/server/server.hpp"
#include "ipc/backplane/backplane.hpp"
#include "ipc/xmail/xmail.hpp"

namespace chm::host::server {

int run_program(const Client& c, std::uint32_t slot, const char* text, std::uint32_t len, std::uint64_t argc,
                bool allow_shell, std::string* why);  // run.cpp
void run_stop_all();                      // run.cpp

namespace {

struct Job {
    xmail::Record* record = nullptr;
    std::uint32_t seq = 0, owner = 0, len = 0;
    std::vector<char> req;  // ring record payload room, allocated at start
};

struct Handle {
    int fd = -1;
    std::uint32_t owner = 0;  // token of the client process
    bool regular = false;     // a regular file: its I/O does not wait on anyone
};

struct State {
    Options opt;
    bool started = false;
    std::uint32_t room = 0;
    std::vector<Job> jobs;                // by ring record index
    std::vector<std::uint32_t> queue;     // record indices waiting, FIFO
    std::mutex mu;                        // jobs' queue, clients, handles
    std::condition_variable cv;
    bool stopping = false;
    std::vector<std::thread> workers;
    std::atomic<int> working{0};          // workers not yet returned
    std::vector<char> task_rep;           // the server task's reply buffer
    Client clients[CHM_BP_MAX_SLOTS];
    Handle handles[kHandleMax];
};
State* g = nullptr;

// ------------------------------------------------------------ clients

void close_handles_of(std::uint32_t token) {
    for (Handle& h : g->handles)
        if (h.fd >= 0 && h.owner == token) {
            ::close(h.fd);
            h = Handle{};
        }
}

// The client record of `owner`'s slot, reset when the slot changed hands.
// Under g->mu.
Client& client_of(std::uint32_t owner) {
    Client& c = g->clients[bp::token_slot(owner) % CHM_BP_MAX_SLOTS];
    if (c.token != owner) {
        if (c.token) close_handles_of(c.token);
        c.token = owner;
        c.cwd.clear();
        // The transfer segment stays attached: the name is the slot's, and
        // a new process in the slot attaches the same one.
    }
    return c;
}

int handle_fd(std::uint32_t owner, std::int32_t h) {
    std::lock_guard<std::mutex> l(g->mu);
    if (h < 0 || std::size_t(h) >= std::size(g->handles)) return -EBADF;
    const Handle& e = g->handles[h];
    return e.fd >= 0 && e.owner == owner ? e.fd : -EBADF;
}

int oflags_of(std::uint64_t f) {
    int o = (f & CHM_XFS_RDWR) ? O_RDWR : (f & CHM_XFS_WRONLY) ? O_WRONLY : O_RDONLY;
    if (f & CHM_XFS_CREAT) o |= O_CREAT;
    if (f & CHM_XFS_TRUNC) o |= O_TRUNC;
    if (f & CHM_XFS_APPEND) o |= O_APPEND;
    if (f & CHM_XFS_EXCL) o |= O_EXCL;
    return o;
}

void put_stat(const struct stat& st, char* rep, std::uint32_t* n) {
    StatReply s{};
    s.size = std::uint64_t(st.st_size);
    s.mtime_ns = std::uint64_t(st.st_mtim.tv_sec) * 1000000000u + std::uint64_t(st.st_mtim.tv_nsec);
    s.mode = st.st_mode;
    std::memcpy(rep, &s, sizeof s);
    *n = sizeof s;
}

// A NUL-terminated text of the request, or nullptr.
const char* text_of(const HostRequest& h, const char* body, std::uint32_t body_len) {
    if (h.text_len == 0 || h.text_len > body_len || body[h.text_len - 1] != 0) return nullptr;
    return body;
}

// ------------------------------------------------------------ the ops

// *why: what to tell the client beside a refusal's status (nullptr: the
// status says it all).
int serve(const HostRequest& h, const char* body, std::uint32_t body_len, std::uint32_t owner, char* rep,
          std::uint32_t* n, const char*& why) {
    *n = 0;
    switch (Op(h.op)) {
    case kOpen:
    case kStat:
    case kChdir: {
        const char* path = text_of(h, body, body_len);
        if (!path) return -EINVAL;
        std::string rel;
        {
            std::lock_guard<std::mutex> l(g->mu);
            if (int e = fs_join(client_of(owner), path, &rel, &why)) return e;
        }
        const int oflags = h.op == kOpen ? oflags_of(h.a) : O_PATH | (h.op == kChdir ? O_DIRECTORY : 0);
        const int fd = fs_open(rel, oflags, unsigned(h.b & 07777), &why);
        if (fd < 0) return fd;
        if (h.op == kStat) {
            struct stat st;
            const int e = ::fstat(fd, &st) == 0 ? 0 : -errno;
            ::close(fd);
            if (!e) put_stat(st, rep, n);
            return e;
        }
        std::lock_guard<std::mutex> l(g->mu);
        if (h.op == kChdir) {
            std::string cwd;
            const int e = fs_relative(fd, &cwd);
            ::close(fd);
            if (!e) client_of(owner).cwd = cwd;
            return e;
        }
        unsigned mine = 0;
        Handle* free_slot = nullptr;
        for (Handle& e : g->handles) {
            if (e.fd >= 0 && e.owner == owner) ++mine;
            if (e.fd < 0 && !free_slot) free_slot = &e;
        }
        if (mine >= CHM_XFS_OPEN_MAX || !free_slot) {
            ::close(fd);
            return -EMFILE;
        }
        struct stat st;
        *free_slot = Handle{fd, owner, ::fstat(fd, &st) == 0 && S_ISREG(st.st_mode)};
        OpenReply r{free_slot->regular ? kOpenRegular : 0, -1, 0, 0};
        if (free_slot->regular && (oflags & O_ACCMODE) != O_WRONLY && fs_local(fd)) {
            r.what |= kOpenDirect;
            r.fd = fd;
            r.dev = st.st_dev;
            r.ino = st.st_ino;
        }
        std::memcpy(rep, &r, sizeof r);
        *n = sizeof r;
        return int(free_slot - g->handles);
    }
    case kClose: {
        std::lock_guard<std::mutex> l(g->mu);
        if (h.fd < 0 || std::size_t(h.fd) >= std::size(g->handles)) return -EBADF;
        Handle& e = g->handles[h.fd];
        if (e.fd < 0 || e.owner != owner) return -EBADF;
        const int r = ::close(e.fd);
        e = Handle{};
        return r == 0 ? 0 : -errno;
    }
    case kRead:
    case kWrite: {
        const int fd = handle_fd(owner, h.fd);
        if (fd < 0) return fd;
        char* data;
        std::uint32_t max;
        if (h.bulk) {
            std::lock_guard<std::mutex> l(g->mu);
            const Client& c = client_of(owner);
            if (!c.bulk || h.bulk > kBulkBuffers) return -EINVAL;
            data = c.bulk + std::size_t(h.bulk - 1) * kBulkSize;
            max = kBulkSize;
        } else if (h.op == kRead) {
            data = rep;
            max = g->room;
        } else {
            data = const_cast<char*>(body);
            max = std::min(body_len, h.text_len);
        }
        if (h.b > max) return -EINVAL;
        const std::size_t k = std::size_t(h.b);
        const bool at = h.a != UINT64_MAX;
        ssize_t r;
        if (h.op == kRead)
            r = at ? ::pread(fd, data, k, off_t(h.a)) : ::read(fd, data, k);
        else
            r = at ? ::pwrite(fd, data, k, off_t(h.a)) : ::write(fd, data, k);
        if (r < 0) return -errno;
        if (h.op == kRead && !h.bulk) *n = std::uint32_t(r);
        return int(r);
    }
    case kSeek: {
        const int fd = handle_fd(owner, h.fd);
        if (fd < 0) return fd;
        const off_t pos = ::lseek(fd, off_t(std::int64_t(h.a)), int(h.b));
        if (pos < 0) return -errno;
        const std::uint64_t p = std::uint64_t(pos);
        std::memcpy(rep, &p, sizeof p);
        *n = sizeof p;
        return 0;
    }
    case kFstat: {
        const int fd = handle_fd(owner, h.fd);
        if (fd < 0) return fd;
        struct stat st;
        if (::fstat(fd, &st) != 0) return -errno;
        put_stat(st, rep, n);
        return 0;
    }
    case kIoctl: {
        const int fd = handle_fd(owner, h.fd);
        if (fd < 0) return fd;
        char arg[256] = {};
        const std::uint32_t k = std::min<std::uint32_t>(std::min(h.text_len, body_len), sizeof arg);
        std::memcpy(arg, body, k);
        const int r = ::ioctl(fd, static_cast<unsigned long>(h.b), arg);
        if (r < 0) return -errno;
        std::memcpy(rep, arg, k);
        *n = k;
        return r;
    }
    case kGetcwd: {
        std::lock_guard<std::mutex> l(g->mu);
        const std::string& cwd = client_of(owner).cwd;
        if (cwd.size() + 1 > g->room) return -ERANGE;
        std::memcpy(rep, cwd.c_str(), cwd.size() + 1);
        *n = std::uint32_t(cwd.size() + 1);
        return 0;
    }
    case kGetenv: {
        const char* name = text_of(h, body, body_len);
        if (!name || !*name || std::strchr(name, '=')) return -EINVAL;
        const char* v = ::getenv(name);
        if (!v) return -ENOENT;
        const std::size_t k = std::strlen(v) + 1;
        if (k > g->room) return -ERANGE;
        std::memcpy(rep, v, k);
        *n = std::uint32_t(k);
        return 0;
    }
    case kRun: {
        Client c;
        {
            std::lock_guard<std::mutex> l(g->mu);
            c = client_of(owner);
        }
        thread_local std::string msg;
        msg.clear();
        const int r = run_program(c, bp::token_slot(owner), body, std::min(body_len, h.text_len), h.a,
                                  g->opt.allow_shell, &msg);
        if (r < 0 && !msg.empty()) why = msg.c_str();
        return r;
    }
    case kOut:
        return console_out(bp::token_slot(owner), body, std::min(body_len, h.text_len));
    case kIn: {
        const std::uint32_t max = std::uint32_t(std::min<std::uint64_t>(h.b, g->room));
        const int r = console_in(bp::token_slot(owner), chm_tid_t(h.a), owner, rep, max);
        if (r > 0) *n = std::uint32_t(r);
        return r;
    }
    case kOpEnd: break;
    }
    return -EPROTO;
}

// Serve one request and answer it (on a worker, or on the server task for
// what cannot wait on anyone).
void answer(xmail::Record* record, std::uint32_t seq, std::uint32_t owner, const char* req, std::uint32_t len,
            char* rep) {
    std::uint32_t n = 0;
    int status = -EINVAL;
    const char* why = nullptr;
    if (len >= sizeof(HostRequest)) {
        HostRequest h;
        std::memcpy(&h, req, sizeof h);
        status = serve(h, req + sizeof h, len - std::uint32_t(sizeof h), owner, rep, &n, why);
    } else {
        why = "request shorter than its header";
    }
    if (status < 0 && why) {  // a refusal's reply is its reason
        const std::size_t k = std::min<std::size_t>(std::strlen(why), g->room - 1);
        std::memcpy(rep, why, k);
        rep[k] = 0;
        n = std::uint32_t(k + 1);
    }
    xmail::finish(record, seq, status, rep, std::min(n, g->room));
}

// Requests that never wait on anything but the page cache are served on
// the server task: a hand-over to a worker costs a thread wake-up, the
// largest part of a small request's round trip. What may wait on another
// party (an open, which waits for a FIFO's writer; I/O on a pipe, socket
// or terminal; a program run) goes to a worker.
bool quick(const HostRequest& h, std::uint32_t owner) {
    switch (Op(h.op)) {
    case kStat:
    case kClose:
    case kGetcwd:
    case kGetenv: return true;
    case kRead:
    case kWrite:
    case kSeek:
    case kFstat: {
        std::lock_guard<std::mutex> l(g->mu);
        if (h.fd < 0 || std::size_t(h.fd) >= std::size(g->handles)) return true;  // refused at once
        const Handle& e = g->handles[h.fd];
        return e.owner != owner || e.regular;
    }
    default: return false;
    }
}

void worker_main() {
    struct Done {
        ~Done() { g->working.fetch_sub(1); }
    } done;
    sigset_t all;
    sigfillset(&all);
    pthread_sigmask(SIG_BLOCK, &all, nullptr);  // signals are the kernel thread's
    std::vector<char> rep(g->room);
    std::vector<char> req(g->room);
    for (;;) {
        Job* job;
        std::uint32_t len;
        {
            std::unique_lock<std::mutex> l(g->mu);
            g->cv.wait(l, [] { return g->stopping || !g->queue.empty(); });
            if (g->queue.empty()) return;
            job = &g->jobs[g->queue.front()];
            g->queue.erase(g->queue.begin());
            len = job->len;
            std::memcpy(req.data(), job->req.data(), len);
        }
        answer(job->record, job->seq, job->owner, req.data(), len, rep.data());
    }
}

// On the server task: attach what the request needs from the backplane
// (only this thread may use the registry), then queue it.
void take(xmail::Record* r, std::uint32_t seq, std::uint32_t index, const char* req, std::uint32_t len,
          std::uint32_t owner) {
    if (index >= g->jobs.size() || len > g->room) {
        xmail::finish(r, seq, -EPROTO, nullptr, 0);
        return;
    }
    HostRequest h{};
    if (len >= sizeof h) std::memcpy(&h, req, sizeof h);
    if (h.bulk) {
        Client* c;
        {
            std::lock_guard<std::mutex> l(g->mu);
            c = &client_of(owner);
        }
        if (!c->bulk) {
            char name[CHM_BP_NAME_MAX + 1];
            bulk_name(name, sizeof name, bp::token_slot(owner));
            void* addr = nullptr;
            std::size_t size = 0;
            if (chm_shm_attach(name, &addr, &size) != 0 || size < std::size_t(kBulkSize) * kBulkBuffers) {
                if (addr) (void)chm_shm_detach(addr);
                xmail::finish(r, seq, -EINVAL, nullptr, 0);
                return;
            }
            std::lock_guard<std::mutex> l(g->mu);
            c->bulk = static_cast<char*>(addr);
        }
    }
    if (len >= sizeof h && quick(h, owner)) {
        answer(r, seq, owner, req, len, g->task_rep.data());
        return;
    }
    std::lock_guard<std::mutex> l(g->mu);
    Job& j = g->jobs[index];
    j.record = r;
    j.seq = seq;
    j.owner = owner;
    j.len = len;
    std::memcpy(j.req.data(), req, len);
    g->queue.push_back(index);
    g->cv.notify_one();
}

}  // namespace

int start(const Options& o) {
    bp::Attachment* a = bp::current();
    if (!a || a->slot != std::uint32_t(kServerSlot)) return -ENOTCONN;
    if (g) return -EBUSY;
    if (int e = fs_init(o.root)) return e;
    g = new State;
    g->opt = o;
    g->room = xmail::ring_record_size(*a) - std::uint32_t(sizeof(xmail::Record));
    g->jobs.resize(xmail::ring_capacity(*a));
    for (Job& j : g->jobs) j.req.resize(g->room);
    g->task_rep.resize(g->room);
    g->queue.reserve(g->jobs.size());
    for (unsigned i = 0; i < (o.workers ? o.workers : 1); ++i) {
        try {
            g->working.fetch_add(1);
            g->workers.emplace_back(worker_main);
        } catch (...) {
            stop();
            return -EAGAIN;
        }
    }
    if (o.console_socket) {
        if (int e = console_start(o.console_socket)) {
            stop();
            return e;
        }
    }
    xmail::set_deferred(xmail::kHost, take);
    g->started = true;
    return 0;
}

int start_local(const Options& o, std::uint32_t room) {
    if (g) return -EBUSY;
    if (int e = fs_init(o.root)) return e;
    g = new State;
    g->opt = o;
    g->room = room;
    g->task_rep.resize(room);
    return 0;
}

int serve_local(const char* req, std::uint32_t len, std::uint32_t owner, char* rep, std::uint32_t* n) {
    *n = 0;
    if (len < sizeof(HostRequest)) return -EINVAL;
    HostRequest h;
    std::memcpy(&h, req, sizeof h);
    const char* why = nullptr;
    const int r = serve(h, req + sizeof h, len - std::uint32_t(sizeof h), owner, rep, n, why);
    if (*n > g->room) std::abort();  // a reply longer than a record: the bug this exists to find
    return r;
}

void stop() {
    if (!g) return;
    xmail::set_deferred(xmail::kHost, nullptr);
    {
        std::lock_guard<std::mutex> l(g->mu);
        g->stopping = true;
    }
    run_stop_all();  // a worker waiting for a program would hold the stop
    console_stop();  // and one waiting for console input
    g->cv.notify_all();
    // A worker may be stuck in the host's own call (an open of a FIFO that
    // no one writes): after a second it is left behind with the state it
    // uses, and the process ends without it.
    // (Time read from the clock: the kernel's tick signal cuts sleeps short.)
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(1);
    while (g->working.load() > 0 && std::chrono::steady_clock::now() < until) ::usleep(10000);
    if (g->working.load() > 0) {
        std::fprintf(stderr, "chimera-rtpu: host server: %d request(s) still in the host's calls at stop: left\n",
                     g->working.load());
        for (std::thread& t : g->workers) t.detach();
        // g and the root stay, neither freed nor closed: those workers
        // still use them until the process ends (no request reaches them
        // any more). Closing the root under a worker would race with its
        // use (ThreadSanitizer saw it), and the number could be handed to
        // the next open, under which the worker's path would then resolve.
        return;
    }
    for (std::thread& t : g->workers) t.join();
    for (Handle& h : g->handles)
        if (h.fd >= 0) ::close(h.fd);
    delete g;
    g = nullptr;
    fs_fini();
}

}  // namespace chm::host::server
