// Direct reads of page-cached host files (direct.hpp).
//
// A read through the host server costs a request, a pread into the
// transfer segment and a copy out of it: at best about twice the copy
// pread(2) does. When the file lies on a local file system and its pages
// are in the page cache, nothing can make the reader wait, so this process
// reads them itself, with preadv2(RWF_NOWAIT): the kernel copies what it
// holds and answers -EAGAIN rather than wait for the disk. What is not
// cached still goes through the host server, which does the waiting while
// only the calling task is parked.
//
// The descriptor is the host server's own, reopened through
// /proc/<pid>/fd after the server's identity is checked like a signal's
// target (bp::open_member_file), and then checked to be the file the
// server opened (device and inode in its reply): what the task reads is
// what the server confined beneath its root. One preadv2 copies at most
// kChunk bytes (~10 us), so a long read holds the RTPU's kernel thread no
// longer than that at a time: between chunks the task is preemptible.
#include "host/direct.hpp"

#include <atomic>
#include <cerrno>

#include <fcntl.h>
#include <sys/stat.h>
#include <sys/uio.h>
#include <unistd.h>

#include "chimera/xfs.h"
#include "ipc/backplane/backplane.hpp"

namespace chm::host::direct {

namespace {

constexpr std::size_t kChunk = 64 * 1024;
constexpr int kHandles = kHandleMax;  // the server's handle numbers

struct Direct {
    std::atomic<int> fd{-1};
    std::atomic<bool> off{false};  // the file system refused RWF_NOWAIT: kept open, unused
    std::uint32_t attach = 0;      // bp::attach_count() it was opened in
};
Direct g_direct[kHandles];
std::atomic<std::uint64_t> g_bytes{0}, g_misses{0};

// Closed only with its handle (or a new attachment): another task of the
// RTPU may be between loading the number and its preadv2, and a number
// closed under it could name another file by then.
void drop(Direct& d) {
    const int fd = d.fd.exchange(-1, std::memory_order_acq_rel);
    if (fd >= 0) ::close(fd);
    d.off.store(false, std::memory_order_relaxed);
}

}  // namespace

void opened(int fd, const OpenReply& r) {
    if (fd < 0 || fd >= kHandles) return;
    Direct& d = g_direct[fd];
    drop(d);  // a descriptor of an earlier open of the same handle number
    if (!(r.what & kOpenDirect)) return;
    int mine = -1;
    if (bp::open_member_file(kServerSlot, r.fd, &mine) != 0) return;  // reads go through the server
    struct stat st {};
    if (::fstat(mine, &st) != 0 || std::uint64_t(st.st_dev) != r.dev || std::uint64_t(st.st_ino) != r.ino ||
        !S_ISREG(st.st_mode)) {
        ::close(mine);
        return;
    }
    d.attach = bp::attach_count();
    d.fd.store(mine, std::memory_order_release);
}

void closed(int fd) {
    if (fd >= 0 && fd < kHandles) drop(g_direct[fd]);
}

bool has(int fd) {
    if (fd < 0 || fd >= kHandles) return false;
    Direct& d = g_direct[fd];
    if (d.fd.load(std::memory_order_acquire) < 0 || d.off.load(std::memory_order_relaxed)) return false;
    if (d.attach != bp::attach_count()) {  // opened on an earlier attachment: another server's handle
        drop(d);
        return false;
    }
    return true;
}

std::int64_t read(int fd, char* buf, std::size_t n, std::uint64_t off) {
    if (!has(fd)) return -ENOTSUP;
    const int mine = g_direct[fd].fd.load(std::memory_order_acquire);
    std::size_t done = 0;
    int stop = 0;  // why it stopped before n: 0 (the end, or what is cached), -EAGAIN, -ENOTSUP
    while (done < n) {
        const std::size_t want = n - done < kChunk ? n - done : kChunk;
        iovec v{buf + done, want};
        const ssize_t r = ::preadv2(mine, &v, 1, off_t(off + done), RWF_NOWAIT);
        if (r < 0) {
            if (errno == EINTR) continue;
            if (errno == EAGAIN) {
                stop = -EAGAIN;
                if (!done) g_misses.fetch_add(1, std::memory_order_relaxed);
            } else {  // no RWF_NOWAIT here (ENOSYS, EOPNOTSUPP...): the server reads from now on
                g_direct[fd].off.store(true, std::memory_order_relaxed);
                stop = -ENOTSUP;
            }
            break;
        }
        done += std::size_t(r);
        if (std::size_t(r) < want) break;  // the end of the file, or of what is cached
    }
    g_bytes.fetch_add(done, std::memory_order_relaxed);
    return done ? std::int64_t(done) : stop;
}

Counts counts() { return {g_bytes.load(std::memory_order_relaxed), g_misses.load(std::memory_order_relaxed)}; }

}  // namespace chm::host::direct
