// Read-ahead for sequential reads of a regular host file (stream.hpp).
//
// A request costs two cross-process wake-ups and ~12 us of work on each
// side here, far more than pread of a 64 KiB page-cached block (~4 us).
// So a read of a regular file keeps up to kDepth preads of kBulkSize
// (256 KiB: the per-request work spread over 4 such blocks; 64 KiB blocks
// ran at 4.5 x pread's time, 256 KiB at 2.7 x, 512 KiB at 2.3 x) in
// flight, each into its own lent
// buffer of the transfer segment, posted ahead of the reader: while the
// task copies one block out, the host server is already reading the next,
// and by the time the task asks, the reply is usually in (no park, no
// wake-up). The file position is the client's while a stream runs (the
// blocks are preads at explicit offsets); any other call on the handle
// first ends the stream: the blocks in flight are waited for (a buffer is
// never lent again while the server may still write into it) and the
// server's position is set to the client's.
#include "host/stream.hpp"

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>

#include "chimera/kernel.h"
#include "chimera/task.h"
#include "chimera/xfs.h"
#include "host/client.hpp"
#include "host/direct.hpp"
#include "ipc/backplane/backplane.hpp"

namespace chm::host::stream {

namespace {

constexpr int kDepth = int(kBulkBuffers) - 1;  // one buffer stays for other transfers
constexpr int kStreams = 4;
constexpr int kHandles = kHandleMax;  // the server's handle numbers

struct Block {
    xmail::Pending p;
    Bulk buf;
    std::uint64_t off = 0;
    std::int64_t got = -1;   // the reply's status once awaited (-1 not yet)
    std::uint32_t used = 0;  // bytes of it the reader took
};

struct Stream {
    std::atomic<int> fd{-1};      // the handle streamed, -1: free
    std::uint32_t attach = 0;     // bp::attach_count() it began in
    std::atomic<int> busy{0};     // a task is in it
    std::uint64_t pos = 0;        // the reader's position (next byte it reads)
    std::uint64_t ahead = 0;      // offset of the next block to post
    bool eof = false;             // a block came back short: post no more
    Block q[kDepth];
    int head = 0, n = 0;
};

Stream g_streams[kStreams];
std::atomic<std::uint8_t> g_regular[kHandles];  // what open said, per handle

const char* what_of(int fd) {
    static thread_local char w[48];
    std::snprintf(w, sizeof w, "read of handle %d", fd);
    return w;
}

// Take stream `s` for this task: false after ~5 s of another task in it.
bool enter(Stream& s) {
    for (int tries = 0; tries < 5000; ++tries) {
        int idle = 0;
        if (s.busy.compare_exchange_strong(idle, 1, std::memory_order_acquire)) return true;
        chm_task_pause_until(chm_time_now() + 1'000'000);
    }
    return false;
}
void leave(Stream& s) { s.busy.store(0, std::memory_order_release); }

Stream* find(int fd) {
    for (Stream& s : g_streams) {
        if (s.fd.load(std::memory_order_acquire) != fd) continue;
        if (s.attach == bp::attach_count()) return &s;
        // Begun on an earlier attachment: its records were in a mapping
        // that is gone, and its handle was another server's.
        s.n = s.head = 0;
        s.busy.store(0);
        s.fd.store(-1);
    }
    return nullptr;
}

// Post the next block while a buffer and a place are free.
void fill(Stream& s, int fd) {
    while (!s.eof && s.n < kDepth) {
        Bulk b = bulk_take();
        if (!b.index) return;
        Block& k = s.q[(s.head + s.n) % kDepth];
        k = Block{};
        k.buf = b;
        k.off = s.ahead;
        HostRequest h{};
        h.op = kRead;
        h.fd = fd;
        h.a = s.ahead;
        h.b = kBulkSize;
        h.bulk = b.index;
        if (post_request(h, nullptr, 0, &k.p, what_of(fd)) != 0) {
            bulk_give(b);
            return;  // the reader meets the error when it reads synchronously
        }
        s.ahead += kBulkSize;
        ++s.n;
    }
}

std::int64_t await_head(Stream& s, int fd) {
    Block& k = s.q[s.head];
    if (k.got < 0 && k.p.r) {
        const int r = await_request(&k.p, nullptr, 0, nullptr, what_of(fd));
        k.got = r;
        if (r < 0) return r;
        if (std::uint32_t(r) < kBulkSize) s.eof = true;
    }
    return k.got;
}

void pop(Stream& s) {
    bulk_give(s.q[s.head].buf);
    s.q[s.head] = Block{};
    s.head = (s.head + 1) % kDepth;
    --s.n;
}

// lseek of handle fd on the server: the new position into *at.
int seek(int fd, std::uint64_t off, int whence, std::uint64_t* at) {
    char what[48];
    std::snprintf(what, sizeof what, "lseek of handle %d", fd);
    HostRequest h{};
    h.op = kSeek;
    h.fd = fd;
    h.a = off;
    h.b = std::uint64_t(whence);
    std::uint32_t got = 0;
    const int r = request(h, nullptr, 0, at, sizeof *at, &got, what);
    return r < 0 ? r : got == sizeof *at ? 0 : -EPROTO;
}

// Wait for every block in flight, give the buffers back, free the stream
// and set the server's position to the reader's. Inside the stream.
int finish(Stream& s, int fd) {
    while (s.n) {
        Block& k = s.q[s.head];
        if (k.p.r) await_request(&k.p, nullptr, 0, nullptr, what_of(fd));
        pop(s);
    }
    const std::uint64_t pos = s.pos;
    s.fd.store(-1, std::memory_order_release);
    std::uint64_t at = 0;
    return seek(fd, pos, SEEK_SET, &at);
}

}  // namespace

void opened(int fd, bool regular) {
    if (fd >= 0 && fd < kHandles) g_regular[fd].store(regular, std::memory_order_relaxed);
}

int end(int fd) {
    if (fd < 0 || fd >= kHandles) return 0;
    Stream* s = find(fd);
    if (!s) return 0;
    if (!enter(*s)) return set_error("handle %d: another task is reading it", fd), -EBUSY;
    int r = 0;
    if (s->fd.load() == fd) r = finish(*s, fd);
    leave(*s);
    return r;
}

void closed(int fd) {
    end(fd);
    if (fd >= 0 && fd < kHandles) g_regular[fd].store(0, std::memory_order_relaxed);
}

std::int64_t read(int fd, char* buf, std::size_t n, bool* used) {
    *used = false;
    if (fd < 0 || fd >= kHandles || !g_regular[fd].load(std::memory_order_relaxed) || n < kMinRead) return 0;
    Stream* s = find(fd);
    if (!s) {  // a new stream, if one is free
        for (Stream& t : g_streams) {
            int idle = -1;
            if (t.fd.load() == -1 && t.busy.load() == 0 && t.fd.compare_exchange_strong(idle, fd)) {
                s = &t;
                break;
            }
        }
        if (!s) return 0;
        if (!enter(*s)) return 0;
        // Where the reader is: the server's position, once.
        std::uint64_t at = 0;
        if (seek(fd, 0, SEEK_CUR, &at) != 0) {
            s->fd.store(-1);
            leave(*s);
            return 0;  // the ordinary path says what is wrong
        }
        s->pos = s->ahead = at;
        s->attach = bp::attach_count();
        s->eof = false;
        s->head = s->n = 0;
    } else if (!enter(*s)) {
        return set_error("handle %d: another task is reading it", fd), -EBUSY;
    }
    if (s->fd.load() != fd) {  // ended by another task meanwhile
        leave(*s);
        return 0;
    }
    *used = true;
    std::size_t done = 0;
    std::int64_t err = 0;
    while (done < n) {
        if (!s->n && !s->eof && direct::has(fd)) {
            // Nothing in flight: what the page cache holds is read here
            // (direct.cpp), the rest read ahead by the server.
            const std::int64_t d = direct::read(fd, buf + done, n - done, s->pos);
            if (d == 0) {
                s->eof = true;  // at the end of the file
                break;
            }
            if (d > 0) {
                done += std::size_t(d);
                s->pos += std::uint64_t(d);
                s->ahead = s->pos;
                continue;  // a short one: the next says whether the rest is cached
            }
        }
        fill(*s, fd);
        if (!s->n) break;  // end of file reached, or no buffer: the caller reads on
        const std::int64_t got = await_head(*s, fd);
        if (got < 0) {
            err = got;
            break;
        }
        Block& k = s->q[s->head];
        const std::uint32_t left = std::uint32_t(got) - k.used;
        const std::size_t take = std::min<std::size_t>(left, n - done);
        std::memcpy(buf + done, k.buf.data + k.used, take);
        k.used += std::uint32_t(take);
        done += take;
        s->pos += take;
        if (k.used == std::uint32_t(got)) {
            const bool short_block = std::uint32_t(got) < kBulkSize;
            pop(*s);
            if (short_block) break;  // end of file (for now)
        }
    }
    if (done == 0 && err == 0 && !s->eof) {
        // No buffer to read ahead into: the ordinary path reads, from the
        // position the server is given back here.
        *used = false;
        err = finish(*s, fd);
        leave(*s);
        return err;
    }
    if (err < 0 || (s->eof && !s->n)) {
        // An error, or everything up to the end of file was read: the next
        // read starts over from the server (a file that grows is seen).
        const int r = finish(*s, fd);
        if (err == 0 && r < 0) err = r;
    }
    leave(*s);
    if (done) return std::int64_t(done);
    return err;
}

}  // namespace chm::host::stream
