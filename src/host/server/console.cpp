// The host server's console side (server.hpp): a UNIX socket beside the
// backplane file (mode 0600, in the backplane's private directory) where
// `chimera console` processes connect. Each console owns some RTPUs: their
// tasks' output lines (kOut) go to it, and their stdin reads (kIn) wait for
// the input it sends. Output of an RTPU no console owns is refused
// (-ENOTCONN), and the RTPU writes it to its own log; a console that stops
// reading for a second is dropped, so no task ever waits on it.
#include <algorithm>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <deque>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <fcntl.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include "chimera/bp.h"
#include "host/server/server.hpp"
#include "ipc/backplane/backplane.hpp"

namespace chm::host::server {

namespace {

struct Console {
    int fd = -1;
    std::uint32_t owned = 0;     // slot mask
    int term[3] = {-1, -1, -1};  // its terminal, when it sent it
};

void close_terminal(Console& k) {
    for (int& t : k.term)
        if (t >= 0) ::close(t), t = -1;
}

struct ConsoleState {
    std::string path;
    int listen_fd = -1;
    int wake[2] = {-1, -1};  // wakes the console thread to stop
    std::thread thread;
    std::mutex mu;           // everything below; writes to a console's fd
    std::condition_variable cv;
    std::vector<Console> consoles;
    std::deque<char> input[CHM_BP_MAX_SLOTS];
    bool eof[CHM_BP_MAX_SLOTS] = {};
    bool stopping = false;
};
ConsoleState* c = nullptr;

// Write a whole frame within ~1 s, or give the console up. Under c->mu.
bool send_frame(Console& k, const Frame& f, const void* data) {
    struct iovec {
        const char* p;
        std::size_t n;
    } parts[2] = {{reinterpret_cast<const char*>(&f), sizeof f}, {static_cast<const char*>(data), f.len}};
    for (auto& part : parts) {
        while (part.n) {
            pollfd p{k.fd, POLLOUT, 0};
            if (::poll(&p, 1, 1000) <= 0) return false;
            const ssize_t w = ::send(k.fd, part.p, part.n, MSG_NOSIGNAL | MSG_DONTWAIT);
            if (w < 0 && (errno == EAGAIN || errno == EINTR)) continue;
            if (w <= 0) return false;
            part.p += w;
            part.n -= std::size_t(w);
        }
    }
    return true;
}

void drop(std::size_t i) {  // under c->mu
    ::close(c->consoles[i].fd);
    close_terminal(c->consoles[i]);
    c->consoles.erase(c->consoles.begin() + std::ptrdiff_t(i));
    c->cv.notify_all();
}

Console* owner_of(std::uint32_t slot) {
    for (Console& k : c->consoles)
        if (k.owned & (1u << slot)) return &k;
    return nullptr;
}


// A frame header, with the descriptors a kFrameTerminal carries.
bool read_header(int fd, Frame* f, int fds[3], int* nfds) {
    iovec io{f, sizeof *f};
    alignas(cmsghdr) char ctl[CMSG_SPACE(3 * sizeof(int))];
    msghdr m{};
    m.msg_iov = &io;
    m.msg_iovlen = 1;
    m.msg_control = ctl;
    m.msg_controllen = sizeof ctl;
    ssize_t r;
    do r = ::recvmsg(fd, &m, MSG_CMSG_CLOEXEC);
    while (r < 0 && errno == EINTR);
    if (r <= 0) return false;
    *nfds = 0;
    for (cmsghdr* h = CMSG_FIRSTHDR(&m); h; h = CMSG_NXTHDR(&m, h))
        if (h->cmsg_level == SOL_SOCKET && h->cmsg_type == SCM_RIGHTS) {
            const int n = int((h->cmsg_len - CMSG_LEN(0)) / sizeof(int));
            for (int j = 0; j < n; ++j) {
                int d;
                std::memcpy(&d, CMSG_DATA(h) + j * sizeof(int), sizeof d);
                if (*nfds < 3) fds[(*nfds)++] = d;
                else ::close(d);
            }
        }
    return std::size_t(r) == sizeof *f || recv_all(fd, reinterpret_cast<char*>(f) + r, sizeof *f - std::size_t(r));
}

// One frame from console i (its socket is readable). False: drop it.
bool on_frame(std::size_t i) {
    Frame f;
    const int fd = c->consoles[i].fd;
    int fds[3], nfds = 0;
    const bool whole = read_header(fd, &f, fds, &nfds);
    if (nfds && (!whole || f.type != kFrameTerminal || nfds != 3)) {
        for (int j = 0; j < nfds; ++j) ::close(fds[j]);
        nfds = 0;
    }
    if (!whole || f.len > kFrameMax) return false;
    if (f.type == kFrameTerminal) {
        if (nfds != 3) return false;
        std::lock_guard<std::mutex> l(c->mu);
        close_terminal(c->consoles[i]);
        for (int j = 0; j < 3; ++j) c->consoles[i].term[j] = fds[j];
        return true;
    }
    std::vector<char> data(f.len);
    if (f.len && !recv_all(fd, data.data(), f.len)) return false;
    std::lock_guard<std::mutex> l(c->mu);
    Console& k = c->consoles[i];
    switch (f.type) {
    case kFrameOwn: {
        std::uint32_t want = 0;
        if (f.len >= 4) std::memcpy(&want, data.data(), 4);
        if (!want) want = ~1u;  // every RTPU slot nobody owns (not 0, the server)
        std::uint32_t taken = 0;
        for (const Console& o : c->consoles)
            if (&o != &k) taken |= o.owned;
        k.owned = want & ~taken & ~1u;
        Frame r{kFrameOwned, 0, 0, 4};
        send_frame(k, r, &k.owned);
        c->cv.notify_all();  // readers waiting for an owner
        return true;
    }
    case kFrameInput:
        if (f.rtpu >= CHM_BP_MAX_SLOTS || !(k.owned & (1u << f.rtpu))) return true;  // not its RTPU: ignored
        if (f.len == 0)
            c->eof[f.rtpu] = true;
        else
            c->input[f.rtpu].insert(c->input[f.rtpu].end(), data.begin(), data.end());
        c->cv.notify_all();
        return true;
    default: return false;  // a console that speaks nonsense is dropped
    }
}

void console_main() {
    sigset_t all;
    sigfillset(&all);
    pthread_sigmask(SIG_BLOCK, &all, nullptr);
    for (;;) {
        std::vector<pollfd> fds;
        {
            std::lock_guard<std::mutex> l(c->mu);
            if (c->stopping) return;
            fds.push_back({c->wake[0], POLLIN, 0});
            fds.push_back({c->listen_fd, POLLIN, 0});
            for (const Console& k : c->consoles) fds.push_back({k.fd, POLLIN, 0});
        }
        if (::poll(fds.data(), fds.size(), 1000) < 0 && errno != EINTR) return;
        if (fds[0].revents) return;
        if (fds[1].revents & POLLIN) {
            const int fd = ::accept4(c->listen_fd, nullptr, nullptr, SOCK_CLOEXEC);
            if (fd >= 0) {
                // Only the user who runs the server (the socket's mode says
                // so too; this holds even if the directory were opened up).
                ucred who{};
                socklen_t n = sizeof who;
                if (::getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &who, &n) != 0 || who.uid != ::geteuid()) {
                    ::close(fd);
                } else {
                    std::lock_guard<std::mutex> l(c->mu);
                    c->consoles.push_back(Console{fd, 0});
                }
            }
        }
        for (std::size_t j = 2; j < fds.size(); ++j) {
            if (!fds[j].revents) continue;
            std::size_t i;
            {
                std::lock_guard<std::mutex> l(c->mu);
                for (i = 0; i < c->consoles.size() && c->consoles[i].fd != fds[j].fd; ++i) {
                }
                if (i == c->consoles.size()) continue;
            }
            if (!(fds[j].revents & POLLIN) || !on_frame(i)) {
                std::lock_guard<std::mutex> l(c->mu);
                for (i = 0; i < c->consoles.size() && c->consoles[i].fd != fds[j].fd; ++i) {
                }
                if (i < c->consoles.size()) drop(i);
            }
        }
    }
}

}  // namespace

int console_start(const char* socket_path) {
    sockaddr_un addr{};
    if (std::strlen(socket_path) >= sizeof addr.sun_path) return -ENAMETOOLONG;
    c = new ConsoleState;
    c->path = socket_path;
    addr.sun_family = AF_UNIX;
    std::memcpy(addr.sun_path, socket_path, std::strlen(socket_path));
    ::unlink(socket_path);  // a dead server's (the slot is ours now)
    c->listen_fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    const mode_t old = ::umask(077);
    const int b = c->listen_fd < 0 ? -1 : ::bind(c->listen_fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr);
    ::umask(old);
    if (b != 0 || ::listen(c->listen_fd, 8) != 0 || ::pipe2(c->wake, O_CLOEXEC) != 0) {
        const int e = errno;
        console_stop();
        return -e;
    }
    c->thread = std::thread(console_main);
    return 0;
}

void console_stop() {
    if (!c) return;
    {
        std::lock_guard<std::mutex> l(c->mu);
        c->stopping = true;
        for (Console& k : c->consoles) ::close(k.fd), close_terminal(k);
        c->consoles.clear();
    }
    c->cv.notify_all();
    if (c->wake[1] >= 0) (void)!::write(c->wake[1], "x", 1);
    if (c->thread.joinable()) c->thread.join();
    if (c->listen_fd >= 0) ::close(c->listen_fd), ::unlink(c->path.c_str());
    for (int fd : c->wake)
        if (fd >= 0) ::close(fd);
    delete c;
    c = nullptr;
}

int console_out(std::uint32_t slot, const char* text, std::uint32_t len) {
    // Every entry is checked before any is passed on.
    for (std::uint32_t off = 0; off < len;) {
        Entry e;
        if (len - off < sizeof e) return -EINVAL;
        std::memcpy(&e, text + off, sizeof e);
        if (e.len > len - off - sizeof e || (e.stream != 1 && e.stream != 2)) return -EINVAL;
        off += sizeof e + e.len;
    }
    if (c && slot < CHM_BP_MAX_SLOTS) {
        std::lock_guard<std::mutex> l(c->mu);
        if (Console* k = owner_of(slot)) {
            if (send_frame(*k, Frame{kFrameOut, slot, 0, len}, text)) return 0;
            drop(std::size_t(k - c->consoles.data()));
        }
    }
    // No console owns it: the sender keeps the lines in its own log.
    return -ENOTCONN;
}

int console_terminal(std::uint32_t slot, int fds[3]) {
    if (!c || slot >= CHM_BP_MAX_SLOTS) return -ENOTCONN;
    std::lock_guard<std::mutex> l(c->mu);
    Console* k = owner_of(slot);
    if (!k || k->term[0] < 0) return -ENOTCONN;
    for (int j = 0; j < 3; ++j) fds[j] = ::fcntl(k->term[j], F_DUPFD_CLOEXEC, 3);
    if (fds[0] < 0 || fds[1] < 0 || fds[2] < 0) {
        for (int j = 0; j < 3; ++j)
            if (fds[j] >= 0) ::close(fds[j]);
        return -EMFILE;
    }
    // The console lets go of the terminal while the program has it.
    if (!send_frame(*k, Frame{kFrameRun, slot, 1, 0}, nullptr)) drop(std::size_t(k - c->consoles.data()));
    return 0;
}

void console_terminal_back(std::uint32_t slot) {
    if (!c || slot >= CHM_BP_MAX_SLOTS) return;
    std::lock_guard<std::mutex> l(c->mu);
    if (Console* k = owner_of(slot))
        if (!send_frame(*k, Frame{kFrameRun, slot, 0, 0}, nullptr)) drop(std::size_t(k - c->consoles.data()));
}

int console_in(std::uint32_t slot, chm_tid_t tid, std::uint32_t owner, char* out, std::uint32_t max) {
    if (!c || slot >= CHM_BP_MAX_SLOTS) return -ENOTTY;
    std::unique_lock<std::mutex> l(c->mu);
    bool asked = false;
    const Console* asked_of = nullptr;
    for (;;) {
        if (!c->input[slot].empty()) {
            std::deque<char>& q = c->input[slot];
            std::uint32_t n = 0;
            while (n < max && !q.empty()) {  // up to one line at a time
                const char ch = q.front();
                q.pop_front();
                out[n++] = ch;
                if (ch == '\n') break;
            }
            return int(n);
        }
        if (c->eof[slot]) {
            c->eof[slot] = false;
            return 0;
        }
        if (c->stopping) return -ESHUTDOWN;
        Console* k = owner_of(slot);
        if (k && (!asked || asked_of != k)) {  // tell the console (again, if a new one took the RTPU)
            send_frame(*k, Frame{kFrameWant, slot, tid, 0}, nullptr);
            asked = true;
            asked_of = k;
        }
        c->cv.wait_for(l, std::chrono::milliseconds(500));
        // A reader whose process died is not waited for.
        bp::Attachment* a = bp::current();
        if (a && !bp::token_alive(*a, owner, false)) return -ESRCH;
    }
}

}  // namespace chm::host::server
