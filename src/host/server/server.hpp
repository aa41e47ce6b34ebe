// The host server (docs/architecture.md, "Host server"): the part of
// chimera-rtpu --host-server ROOT that serves kHost express mail. The
// server task hands each request to a pool of worker threads, which do the
// blocking work (file I/O, running a program) and answer with
// xmail::finish; the sender's task stays parked meanwhile, its RTPU runs on.
#pragma once

#include <cstdint>
#include <string>

#include "host/hostio.hpp"
#include "chimera/task.h"

namespace chm::host::server {

struct Options {
    const char* root = ".";     // every path is resolved beneath it
    bool allow_shell = false;   // chm_host_run may start a shell
    unsigned workers = 16;      // requests that may wait at once (stdin reads, FIFOs, programs)
    const char* console_socket = nullptr;  // where consoles connect (NULL: none)
};

// On the kernel thread of the process joined as slot 0, after
// xmail::server_start: open the root, start the workers and take kHost
// requests. Errors: -ENOTDIR/-ENOENT/-EACCES the root; -EBUSY started;
// -ENOTCONN not slot 0; -EAGAIN a thread could not be made.
int start(const Options& o);
// Stop the workers (requests being served are answered first) and close
// every handle. Kernel thread, after chm_kernel_run returned.
void stop();

// The request path without a backplane, for the fuzz harness: the state
// start() makes (the root, handles, clients) with `room` bytes of reply,
// no workers and no express mail. serve_local decodes one request of
// `len` bytes as the server task and workers do and returns its status,
// the reply's length in *n (at most room).
int start_local(const Options& o, std::uint32_t room);
int serve_local(const char* req, std::uint32_t len, std::uint32_t owner, char* rep, std::uint32_t* n);

// ------------------------------------------------------------ internals

// One client process, by backplane slot.
struct Client {
    std::uint32_t token = 0;    // the process it is for; another token resets it
    std::string cwd;            // beneath the root, "" = the root
    char* bulk = nullptr;       // its transfer segment, once attached
};

// Paths (fs.cpp). `rel` is relative to the root. Each returns an fd or
// -errno, with *why set to a message on refusal.
int fs_init(const char* root);
void fs_fini();
int fs_open(const std::string& rel, int oflags, unsigned mode, const char** why);
// The path of an open fd beneath the root ("" = the root), or -EXDEV.
int fs_relative(int fd, std::string* out);
const std::string& fs_root();
// Whether fd's file lies on a local disk or memory file system (ext2/3/4,
// xfs, btrfs, f2fs, tmpfs, overlay): a read of what its page cache holds
// never waits on a network, so a client may do it itself (kOpenDirect).
bool fs_local(int fd);

// Join a client's working directory and a path; -EXDEV for an absolute path.
int fs_join(const Client& c, const char* path, std::string* out, const char** why);

// Consoles (console.cpp). console_out passes the entries of a kOut request
// of slot `slot` to the console that owns it; -ENOTCONN none does; -EINVAL
// a malformed entry (nothing passed on). console_in waits for input for
// `slot` (a reading task `tid` of process `owner`): bytes (one line at
// most), 0 end of file, -ESRCH the reader's process died, -ESHUTDOWN.
int console_start(const char* socket_path);
void console_stop();
int console_out(std::uint32_t slot, const char* text, std::uint32_t len);
int console_in(std::uint32_t slot, chm_tid_t tid, std::uint32_t owner, char* out, std::uint32_t max);
// The terminal of the console that owns `slot` (dups into fds; the console
// is told to let go of it): 0, or -ENOTCONN no console, or none sent its
// terminal. console_terminal_back tells it the program ended.
int console_terminal(std::uint32_t slot, int fds[3]);
void console_terminal_back(std::uint32_t slot);

}  // namespace chm::host::server
