// The blocking UNIX calls a control program makes, interposed so that in a
// task they park only that task (chimera/io.h). Outside a task each call is
// libc's own, found with dlsym(RTLD_NEXT).
#undef _FORTIFY_SOURCE
#include <cerrno>
#include <climits>
#include <cstdint>
#include <ctime>
#include <dlfcn.h>
#include <fcntl.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/uio.h>
#include <unistd.h>

#include "chimera/io.h"
#include "chimera/task.h"
#include "kernel.hpp"

namespace chm::kernel {
namespace {

// libc's own functions, resolved once before main (a constructor: no
// thread-safe static guard, which a task preempted mid-initialisation
// would deadlock on) or, if a call comes earlier, on first use (a benign
// race: every thread stores the same pointer).
template <class F>
struct Next {
    const char* name;
    F fn = nullptr;
    F get() {
        F f = __atomic_load_n(&fn, __ATOMIC_ACQUIRE);
        if (!f) {
            f = reinterpret_cast<F>(dlsym(RTLD_NEXT, name));
            __atomic_store_n(&fn, f, __ATOMIC_RELEASE);
        }
        return f;
    }
};
// Types spelt out: decltype(&::read) would carry libc's attributes.
#define CHM_NEXT(fn, type) Next<type> next_##fn{#fn}
CHM_NEXT(sleep, unsigned (*)(unsigned));
CHM_NEXT(usleep, int (*)(useconds_t));
CHM_NEXT(nanosleep, int (*)(const timespec*, timespec*));
CHM_NEXT(clock_nanosleep, int (*)(clockid_t, int, const timespec*, timespec*));
CHM_NEXT(read, ssize_t (*)(int, void*, size_t));
CHM_NEXT(readv, ssize_t (*)(int, const iovec*, int));
CHM_NEXT(write, ssize_t (*)(int, const void*, size_t));
CHM_NEXT(writev, ssize_t (*)(int, const iovec*, int));
CHM_NEXT(recvfrom, ssize_t (*)(int, void*, size_t, int, sockaddr*, socklen_t*));
CHM_NEXT(sendto, ssize_t (*)(int, const void*, size_t, int, const sockaddr*, socklen_t));
CHM_NEXT(accept4, int (*)(int, sockaddr*, socklen_t*, int));
CHM_NEXT(poll, int (*)(pollfd*, nfds_t, int));

__attribute__((constructor)) void resolve_libc() {
    next_sleep.get(), next_usleep.get(), next_nanosleep.get(), next_clock_nanosleep.get();
    next_read.get(), next_readv.get(), next_write.get(), next_writev.get();
    next_recvfrom.get(), next_sendto.get(), next_accept4.get(), next_poll.get();
}
#define CHM_REAL(fn) const auto real_##fn = next_##fn.get()

// A task may park: on the kernel thread, in a task, not locked into the
// CPU, not inside the kernel. Only the kernel thread changes g_k.current,
// so reading it here without the mask is safe.
bool parkable() {
    if (!port::on_kernel_thread() || port::g_irq.nest != 0) return false;
    const Tcb* cur = g_k.current;
    return cur && !cur->lock_nest;
}

// Sleep the calling task for `ns`; 0 or -EINTR.
int park_for(std::uint64_t ns) {
    return ns ? chm_task_pause_until(chm_time_now() + ns) : 0;
}

// Wait (parked) until `fd` is ready for `events` or cannot be waited on.
// Returns false with errno = EINTR when a user signal ended the wait.
bool park_until_ready(int fd, short events) {
    pollfd p{fd, events, 0};
    for (;;) {
        const int r = chm_io_poll(&p, 1, 0);
        if (r != 0) return true;  // ready, or an error the real call reports
        const int fl = fcntl(fd, F_GETFL);
        if (fl < 0 || (fl & O_NONBLOCK)) return true;  // the caller wants EAGAIN
        const int w = chm_io_poll(&p, 1, CHM_FOREVER);
        if (w == -EINTR) {
            errno = EINTR;
            return false;
        }
        if (w != 0) return true;
    }
}

bool is_plain_file(int fd) {
    struct stat st;
    return fstat(fd, &st) == 0 && (S_ISREG(st.st_mode) || S_ISBLK(st.st_mode));
}

std::uint64_t ts_ns(const timespec* ts) {
    return std::uint64_t(ts->tv_sec) * 1000000000u + std::uint64_t(ts->tv_nsec);
}

}  // namespace
}  // namespace chm::kernel

using namespace chm::kernel;

extern "C" {

unsigned int sleep(unsigned int seconds) {
    CHM_REAL(sleep);
    if (!parkable()) return real_sleep(seconds);
    const std::uint64_t end = chm_time_now() + std::uint64_t(seconds) * 1000000000u;
    if (park_for(std::uint64_t(seconds) * 1000000000u) == -EINTR) {
        const std::uint64_t now = chm_time_now();
        return now < end ? unsigned((end - now + 999999999u) / 1000000000u) : 0;
    }
    return 0;
}

int usleep(useconds_t usec) {
    CHM_REAL(usleep);
    if (!parkable()) return real_usleep(usec);
    if (park_for(std::uint64_t(usec) * 1000u) == -EINTR) {
        errno = EINTR;
        return -1;
    }
    return 0;
}

int nanosleep(const timespec* req, timespec* rem) {
    CHM_REAL(nanosleep);
    if (!parkable()) return real_nanosleep(req, rem);
    if (!req || req->tv_nsec < 0 || req->tv_nsec >= 1000000000 || req->tv_sec < 0) {
        errno = req ? EINVAL : EFAULT;
        return -1;
    }
    const std::uint64_t start = chm_time_now();
    const std::uint64_t len = ts_ns(req);
    if (park_for(len) == -EINTR) {
        if (rem) {
            const std::uint64_t done = chm_time_now() - start;
            const std::uint64_t left = done < len ? len - done : 0;
            rem->tv_sec = time_t(left / 1000000000u);
            rem->tv_nsec = long(left % 1000000000u);
        }
        errno = EINTR;
        return -1;
    }
    return 0;
}

int clock_nanosleep(clockid_t clock, int flags, const timespec* req, timespec* rem) {
    CHM_REAL(clock_nanosleep);
    if (!parkable()) return real_clock_nanosleep(clock, flags, req, rem);
    if (!req) return EFAULT;
    if (req->tv_nsec < 0 || req->tv_nsec >= 1000000000 || req->tv_sec < 0) return EINVAL;
    std::uint64_t len = ts_ns(req);
    if (flags & TIMER_ABSTIME) {
        timespec now;
        if (clock_gettime(clock, &now) != 0) return errno;
        const std::uint64_t n = ts_ns(&now);
        len = len > n ? len - n : 0;
    }
    if (park_for(len) == -EINTR) return EINTR;  // rem: left unset, as allowed for ABSTIME
    return 0;
}

ssize_t read(int fd, void* buf, size_t n) {
    CHM_REAL(read);
    if (parkable() && !park_until_ready(fd, POLLIN)) return -1;
    return real_read(fd, buf, n);
}

ssize_t readv(int fd, const iovec* iov, int cnt) {
    CHM_REAL(readv);
    if (parkable() && !park_until_ready(fd, POLLIN)) return -1;
    return real_readv(fd, iov, cnt);
}

ssize_t write(int fd, const void* buf, size_t n) {
    CHM_REAL(write);
    if (!parkable()) return real_write(fd, buf, n);
    if (n <= PIPE_BUF || is_plain_file(fd)) {
        if (!park_until_ready(fd, POLLOUT)) return -1;
        return real_write(fd, buf, n);
    }
    // A pipe, socket or terminal may take less than a big write at once:
    // write what fits (PIPE_BUF is guaranteed once POLLOUT is reported) and
    // park between pieces, as a blocking write waits between them.
    const char* p = static_cast<const char*>(buf);
    size_t done = 0;
    while (done < n) {
        if (!park_until_ready(fd, POLLOUT)) return done ? ssize_t(done) : -1;
        const size_t piece = n - done < PIPE_BUF ? n - done : PIPE_BUF;
        const ssize_t w = real_write(fd, p + done, piece);
        if (w < 0) return done ? ssize_t(done) : -1;
        done += size_t(w);
    }
    return ssize_t(done);
}

ssize_t writev(int fd, const iovec* iov, int cnt) {
    CHM_REAL(writev);
    if (parkable() && !park_until_ready(fd, POLLOUT)) return -1;
    return real_writev(fd, iov, cnt);
}

ssize_t recvfrom(int fd, void* buf, size_t n, int flags, sockaddr* from, socklen_t* len) {
    CHM_REAL(recvfrom);
    if (!parkable() || (flags & MSG_DONTWAIT)) return real_recvfrom(fd, buf, n, flags, from, len);
    for (;;) {  // MSG_DONTWAIT: a socket tells us exactly when it would block
        const ssize_t r = real_recvfrom(fd, buf, n, flags | MSG_DONTWAIT, from, len);
        if (r >= 0 || (errno != EAGAIN && errno != EWOULDBLOCK)) return r;
        if (!park_until_ready(fd, POLLIN)) return -1;
    }
}

ssize_t recv(int fd, void* buf, size_t n, int flags) {
    return recvfrom(fd, buf, n, flags, nullptr, nullptr);
}

ssize_t sendto(int fd, const void* buf, size_t n, int flags, const sockaddr* to, socklen_t len) {
    CHM_REAL(sendto);
    if (!parkable() || (flags & MSG_DONTWAIT)) return real_sendto(fd, buf, n, flags, to, len);
    const char* p = static_cast<const char*>(buf);
    size_t done = 0;
    do {
        const ssize_t r = real_sendto(fd, p + done, n - done, flags | MSG_DONTWAIT, to, len);
        if (r >= 0) {
            done += size_t(r);
            continue;
        }
        if (errno != EAGAIN && errno != EWOULDBLOCK) return done ? ssize_t(done) : -1;
        if (!park_until_ready(fd, POLLOUT)) return done ? ssize_t(done) : -1;
    } while (done < n);
    return ssize_t(done);
}

ssize_t send(int fd, const void* buf, size_t n, int flags) {
    return sendto(fd, buf, n, flags, nullptr, 0);
}

int accept4(int fd, sockaddr* addr, socklen_t* len, int flags) {
    CHM_REAL(accept4);
    if (parkable() && !park_until_ready(fd, POLLIN)) return -1;
    return real_accept4(fd, addr, len, flags);
}

int accept(int fd, sockaddr* addr, socklen_t* len) {
    return accept4(fd, addr, len, 0);
}

int poll(pollfd* fds, nfds_t n, int timeout_ms) {
    CHM_REAL(poll);
    if (!parkable()) return real_poll(fds, n, timeout_ms);
    const int r = chm_io_poll(fds, n, timeout_ms < 0 ? CHM_FOREVER : std::uint64_t(timeout_ms) * 1000000);
    if (r < 0) {
        errno = -r;
        return -1;
    }
    return r;
}

}  // extern "C"
