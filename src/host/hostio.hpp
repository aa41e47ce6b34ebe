// The host server's wire format (docs/architecture.md, "Host server"):
// requests of kind xmail::kHost in the ring of backplane slot 0, each a
// HostRequest then `text_len` bytes (a path, a name, inline data or an
// argument vector); the reply's payload is op-specific, its status the
// record's status (>= 0 or -errno).
//
// Bulk data (reads and writes beyond what one ring record carries) moves
// through the sender's transfer segment: a named shared segment in common
// memory, kBulkBuffers buffers of kBulkSize bytes, which the sender's
// process creates on first use; a request names the buffer it lent. The
// host server checks the segment's name, size and the buffer index before
// it touches anything.
#pragma once

#include <cerrno>
#include <cstdint>
#include <cstdio>

#include <sys/socket.h>

#include "chimera/xfs.h"

namespace chm::host {

enum Op : std::uint32_t {
    kOpen = 1,   // text: path; a = flags (CHM_XFS_*), b = mode -> status: handle, reply: OpenReply
    kClose,      // fd
    kRead,       // fd, b = bytes wanted, a = offset or -1 (current position), bulk
    kWrite,      // fd, text or bulk: the data, a = offset or -1
    kSeek,       // fd, a = offset, b = whence -> reply: uint64 position
    kStat,       // text: path -> reply: StatReply
    kFstat,      // fd -> reply: StatReply
    kIoctl,      // fd, b = request, text: argument bytes in -> reply: out
    kChdir,      // text: path beneath the root
    kGetcwd,     // -> reply: path beneath the root, "" at the root
    kGetenv,     // text: name -> reply: value (status -ENOENT: not set)
    kRun,        // text: argv strings; a = argc -> status: exit status
    kOut,        // text: Entry + text, back to back: lines of the sender's tasks
    kIn,         // fd = the reading task, b = bytes at most -> reply: console input
    kOpEnd
};

// What an open reply says of the file (OpenReply::what, bits).
inline constexpr std::uint32_t kOpenRegular = 1;  // a regular file: reads may be streamed ahead
// Readable, on a local file system: the client may read what the page
// cache holds itself, through its own descriptor of the file (the server's
// descriptor `fd` reopened by /proc; the file is the one with dev and ino).
inline constexpr std::uint32_t kOpenDirect = 2;

struct OpenReply {
    std::uint32_t what;     // kOpen* bits
    std::int32_t fd;        // the server's descriptor (kOpenDirect), else -1
    std::uint64_t dev;
    std::uint64_t ino;
};
static_assert(sizeof(OpenReply) == 24);

struct HostRequest {
    std::uint32_t op;
    std::int32_t fd;        // a handle from kOpen
    std::uint64_t a;
    std::uint64_t b;
    std::uint32_t bulk;     // 0: none; k: buffer k-1 of the sender's segment
    std::uint32_t text_len; // bytes after this header
};
static_assert(sizeof(HostRequest) == 32);

struct StatReply {
    std::uint64_t size;
    std::uint64_t mtime_ns;
    std::uint32_t mode;     // st_mode
    std::uint32_t pad;
};
static_assert(sizeof(StatReply) == 24);

// One piece of console output: a task's line (ending in '\n') or a piece
// of a longer one, `len` bytes of text following.
struct Entry {
    std::uint8_t stream;    // 1 stdout, 2 stderr
    std::uint8_t pad;
    std::uint16_t len;
    std::int32_t tid;       // the task id's low 32 bits: a diagnostic nobody reads
};
static_assert(sizeof(Entry) == 8);

// The console socket (<backplane>.console, the host server listens):
// frames of a Frame header then `len` bytes.
enum FrameType : std::uint32_t {
    kFrameOut = 1,    // server -> console: Entry + text, back to back, of RTPU `rtpu`
    kFrameWant,       // server -> console: task `tid` of RTPU `rtpu` reads stdin
    kFrameOwn,        // console -> server: data = uint32 mask of slots wanted (0: every free one)
    kFrameOwned,      // server -> console: data = uint32 mask of slots it now owns
    kFrameInput,      // console -> server: input for RTPU `rtpu` (len 0: end of file)
    kFrameTerminal,   // console -> server: its terminal (stdin, stdout, stderr) as SCM_RIGHTS
    kFrameRun,        // server -> console: a host program runs on its terminal (tid 1) or ended (tid 0)
};
struct Frame {
    std::uint32_t type;
    std::uint32_t rtpu;
    std::int64_t tid;       // chm_tid_t
    std::uint32_t len;
    std::uint32_t pad = 0;
};
static_assert(sizeof(Frame) == 24);
inline constexpr std::uint32_t kFrameMax = 64 * 1024;

// Read exactly n bytes of a console socket (frames are read whole): false
// at its end or on an error.
inline bool recv_all(int fd, void* buf, std::size_t n) {
    char* p = static_cast<char*>(buf);
    while (n) {
        const ssize_t r = ::recv(fd, p, n, 0);
        if (r < 0 && errno == EINTR) continue;
        if (r <= 0) return false;
        p += r;
        n -= std::size_t(r);
    }
    return true;
}

inline constexpr std::uint32_t kBulkSize = 256 * 1024;
inline constexpr std::uint32_t kBulkBuffers = 4;
inline constexpr int kServerSlot = 0;
// Handle numbers the host server gives: indexes of its table, 0..kHandleMax-1
// (CHM_XFS_OPEN_MAX per client process).
inline constexpr int kHandleMax = CHM_XFS_OPEN_MAX * 4;

// The transfer segment of the process in backplane slot `slot`.
inline void bulk_name(char* out, std::size_t n, std::uint32_t slot) {
    std::snprintf(out, n, "chimera.hostio.%u", unsigned(slot));
}

}  // namespace chm::host
