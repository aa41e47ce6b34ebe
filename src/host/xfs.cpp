// The extended file system's calls (chimera/xfs.h): each builds HostRequests
// (client.hpp); reads and writes beyond one record go through a lent
// buffer of the transfer segment, 256 KiB per request (kBulkSize).
#include <algorithm>
#include <cerrno>
#include <climits>
#include <cstring>

#include "chimera/xfs.h"
#include "host/client.hpp"
#include "host/direct.hpp"
#include "host/stream.hpp"

using namespace chm::host;

namespace {

constexpr int kFlagsKnown = CHM_XFS_WRONLY | CHM_XFS_RDWR | CHM_XFS_CREAT | CHM_XFS_TRUNC | CHM_XFS_APPEND |
                            CHM_XFS_EXCL;

HostRequest make(Op op, int fd = -1, std::uint64_t a = 0, std::uint64_t b = 0) {
    HostRequest h{};
    h.op = op;
    h.fd = fd;
    h.a = a;
    h.b = b;
    return h;
}

int path_request(Op op, const char* path, void* reply, std::uint32_t cap, std::uint32_t* n, std::uint64_t a = 0,
                 std::uint64_t b = 0) {
    if (!path || !*path) return set_error("%s: empty or NULL path", op == kOpen ? "open" : "stat"), -EINVAL;
    char what[160];
    std::snprintf(what, sizeof what, "%s %s", op == kOpen ? "open" : "stat", path);
    return request(make(op, -1, a, b), path, std::uint32_t(std::strlen(path) + 1), reply, cap, n, what);
}

void to_stat(const StatReply& s, chm_xfs_stat_t* out) {
    out->size = s.size;
    out->mtime_ns = s.mtime_ns;
    out->mode = s.mode;
}

// One part of a read (at most kBulkSize, or what fits inline).
// *asked: how many bytes this part asked for (a reply of fewer is short).
std::int64_t read_part(int fd, char* dst, std::uint32_t n, std::int64_t offset, std::uint32_t* asked) {
    char what[64];
    std::snprintf(what, sizeof what, "read of handle %d", fd);
    HostRequest h = make(kRead, fd, std::uint64_t(offset), 0);
    Bulk bulk = n > inline_room() ? bulk_take() : Bulk{};
    if (bulk.index) {
        h.b = *asked = std::min(n, kBulkSize);
        h.bulk = bulk.index;
        const int r = request(h, nullptr, 0, nullptr, 0, nullptr, what);
        if (r > 0) std::memcpy(dst, bulk.data, std::size_t(r));
        bulk_give(bulk);
        return r;
    }
    char reply[2048];
    h.b = *asked = std::min<std::uint32_t>({n, inline_room(), std::uint32_t(sizeof reply)});
    std::uint32_t got = 0;
    const int r = request(h, nullptr, 0, reply, sizeof reply, &got, what);
    if (r > 0) std::memcpy(dst, reply, std::min<std::size_t>(std::size_t(r), got));
    return r;
}

std::int64_t write_part(int fd, const char* src, std::uint32_t n, std::int64_t offset, std::uint32_t* asked) {
    char what[64];
    std::snprintf(what, sizeof what, "write to handle %d", fd);
    HostRequest h = make(kWrite, fd, std::uint64_t(offset), 0);
    Bulk bulk = n > inline_room() ? bulk_take() : Bulk{};
    if (bulk.index) {
        h.b = *asked = std::min(n, kBulkSize);
        h.bulk = bulk.index;
        std::memcpy(bulk.data, src, std::size_t(h.b));
        const int r = request(h, nullptr, 0, nullptr, 0, nullptr, what);
        bulk_give(bulk);
        return r;
    }
    const std::uint32_t k = *asked = std::min(n, inline_room());
    h.b = k;
    return request(h, src, k, nullptr, 0, nullptr, what);
}

// Reads and writes: parts until done, a short part or an error. offset -1:
// the handle's position.
template <class Part, class Ptr>
std::int64_t transfer(int fd, Ptr buf, std::size_t n, std::int64_t offset, Part part) {
    clear_error();
    if (n && !buf) return set_error("handle %d: NULL buffer", fd), -EFAULT;
    if (n > std::size_t(INT32_MAX)) return set_error("handle %d: more than 2 GiB in one call", fd), -EINVAL;
    std::int64_t done = 0;
    while (std::size_t(done) < n) {
        const std::uint32_t want = std::uint32_t(std::min<std::size_t>(n - std::size_t(done), kBulkSize));
        std::uint32_t asked = 0;
        const std::int64_t r = part(fd, buf + done, want, offset < 0 ? -1 : offset + done, &asked);
        if (r < 0) return done ? done : r;
        done += r;
        if (std::uint32_t(r) < asked || r == 0) break;  // end of file, a full pipe...
    }
    return done;
}

}  // namespace

extern "C" {

int chm_xfs_open(const char* path, int flags, unsigned mode) {
    clear_error();
    if (flags & ~kFlagsKnown || (flags & 3) == 3)
        return set_error("open %s: unknown flags 0x%x", path ? path : "(null)", unsigned(flags)), -EINVAL;
    OpenReply what{};
    std::uint32_t n = 0;
    const int fd = path_request(kOpen, path, &what, sizeof what, &n, std::uint64_t(flags), mode & 07777);
    if (fd >= 0) {
        if (n != sizeof what) what = OpenReply{0, -1, 0, 0};
        stream::opened(fd, what.what & kOpenRegular);
        direct::opened(fd, what);
    }
    return fd;
}

int chm_xfs_close(int fd) {
    clear_error();
    char what[48];
    std::snprintf(what, sizeof what, "close of handle %d", fd);
    stream::closed(fd);
    direct::closed(fd);
    return request(make(kClose, fd), nullptr, 0, nullptr, 0, nullptr, what);
}

int64_t chm_xfs_read(int fd, void* buf, size_t n) {
    clear_error();
    if (n && !buf) return set_error("handle %d: NULL buffer", fd), -EFAULT;
    bool streamed = false;
    const std::int64_t r = stream::read(fd, static_cast<char*>(buf), n, &streamed);
    if (streamed) return r;
    if (int e = stream::end(fd)) return e;
    return transfer(fd, static_cast<char*>(buf), n, -1, read_part);
}

int64_t chm_xfs_pread(int fd, void* buf, size_t n, int64_t offset) {
    clear_error();
    if (offset < 0) return set_error("pread of handle %d: negative offset", fd), -EINVAL;
    if (n && !buf) return set_error("handle %d: NULL buffer", fd), -EFAULT;
    // What the page cache holds, read here; the rest through the server.
    const std::int64_t d = n ? direct::read(fd, static_cast<char*>(buf), n, std::uint64_t(offset)) : 0;
    if (d == std::int64_t(n)) return d;
    const std::size_t done = d > 0 ? std::size_t(d) : 0;
    const std::int64_t r = transfer(fd, static_cast<char*>(buf) + done, n - done, offset + std::int64_t(done), read_part);
    if (r < 0) return done ? std::int64_t(done) : r;
    return std::int64_t(done) + r;
}

int64_t chm_xfs_write(int fd, const void* buf, size_t n) {
    if (int e = stream::end(fd)) return e;
    return transfer(fd, static_cast<const char*>(buf), n, -1, write_part);
}

int64_t chm_xfs_pwrite(int fd, const void* buf, size_t n, int64_t offset) {
    if (offset < 0) return set_error("pwrite of handle %d: negative offset", fd), -EINVAL;
    if (int e = stream::end(fd)) return e;  // what it read ahead may be overwritten
    return transfer(fd, static_cast<const char*>(buf), n, offset, write_part);
}

int64_t chm_xfs_lseek(int fd, int64_t offset, int whence) {
    clear_error();
    if (whence != SEEK_SET && whence != SEEK_CUR && whence != SEEK_END)
        return set_error("lseek of handle %d: whence %d", fd, whence), -EINVAL;
    if (int e = stream::end(fd)) return e;
    char what[48];
    std::snprintf(what, sizeof what, "lseek of handle %d", fd);
    std::uint64_t pos = 0;
    std::uint32_t n = 0;
    const int r = request(make(kSeek, fd, std::uint64_t(offset), std::uint64_t(whence)), nullptr, 0, &pos, sizeof pos,
                          &n, what);
    if (r < 0) return r;
    if (n != sizeof pos) return set_error("%s: short reply", what), -EPROTO;
    return std::int64_t(pos);
}

int chm_xfs_stat(const char* path, chm_xfs_stat_t* out) {
    clear_error();
    if (!out) return set_error("stat: NULL output"), -EFAULT;
    StatReply s{};
    std::uint32_t n = 0;
    const int r = path_request(kStat, path, &s, sizeof s, &n);
    if (r < 0) return r;
    if (n != sizeof s) return set_error("stat %s: short reply", path), -EPROTO;
    to_stat(s, out);
    return 0;
}

int chm_xfs_fstat(int fd, chm_xfs_stat_t* out) {
    clear_error();
    if (!out) return set_error("fstat: NULL output"), -EFAULT;
    char what[48];
    std::snprintf(what, sizeof what, "fstat of handle %d", fd);
    StatReply s{};
    std::uint32_t n = 0;
    const int r = request(make(kFstat, fd), nullptr, 0, &s, sizeof s, &n, what);
    if (r < 0) return r;
    if (n != sizeof s) return set_error("%s: short reply", what), -EPROTO;
    to_stat(s, out);
    return 0;
}

int chm_xfs_ioctl(int fd, unsigned long request_code, void* arg, size_t arg_size) {
    clear_error();
    if (arg_size > 256 || (arg_size && !arg))
        return set_error("ioctl of handle %d: argument of %zu bytes (at most 256, not NULL)", fd, arg_size), -EINVAL;
    if (int e = stream::end(fd)) return e;
    char what[64];
    std::snprintf(what, sizeof what, "ioctl 0x%lx of handle %d", request_code, fd);
    std::uint32_t n = 0;
    char out[256];
    const int r = request(make(kIoctl, fd, 0, request_code), arg, std::uint32_t(arg_size), out, sizeof out, &n, what);
    if (r >= 0 && arg_size) std::memcpy(arg, out, std::min<std::size_t>(arg_size, n));
    return r;
}

}  // extern "C"
