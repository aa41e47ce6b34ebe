// The host server (issue 19) with real processes in their default
// configuration: chimera-rtpu --host-server in slot 0 on a private
// backplane, the bench process RTPU 1 with a kernel, its task the client.
//  * xfs_read_64k: chm_xfs_read of 64 KiB, sequential through an 8 MiB file
//    in the page cache (rewound at its end), beside pread(2) of the same
//    64 KiB blocks of the same file by the same task (peer_pread_64k), run
//    in turn. Target: >= 0.5 x pread's throughput (time <= 2 x).
//  * host_call_rt: chm_host_getcwd, the smallest host procedure call: one
//    request to the host server and its reply, round trip (no target).
//  * console_line_latency: a task's printf of one line to its arrival on
//    the terminal of `chimera console` (a pseudo-terminal this process
//    reads): the stamp the line carries against the arrival; median and
//    range of 1,000 lines at 1 kHz (no target).
#include <fcntl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <sys/socket.h>
#include <sys/un.h>
#include <pty.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <thread>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "../harness.hpp"
#include "chimera/err.h"
#include "chimera/host.h"
#include "chimera/rtpu.h"
#include "chimera/xfs.h"
#include "host/console.hpp"
#include "rtpu.hpp"

namespace chm::bench {
namespace {

constexpr std::size_t kBlock = 64 * 1024;
constexpr std::size_t kFile = 8 * 1024 * 1024;

// A directory with the file, removed on every path out.
struct Root {
    std::string dir, file;
    // In /tmp (a disk file system here), or `base` (/dev/shm: tmpfs).
    explicit Root(const char* base = "/tmp") {
        std::string tmpl = std::string(base) + "/chimera-bench-xfs-XXXXXX";
        std::vector<char> buf(tmpl.begin(), tmpl.end());
        buf.push_back(0);
        if (!mkdtemp(buf.data())) throw std::runtime_error("mkdtemp failed");
        dir = buf.data();
        file = dir + "/data.bin";
        const int fd = open(file.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
        std::vector<char> block(kBlock);
        for (std::size_t i = 0; i < kBlock; ++i) block[i] = char(i * 13 + 7);
        for (std::size_t done = 0; fd >= 0 && done < kFile; done += kBlock)
            if (write(fd, block.data(), kBlock) != ssize_t(kBlock)) break;
        if (fd >= 0) close(fd);
    }
    ~Root() {
        unlink(file.c_str());
        rmdir(dir.c_str());
    }
};

// The host server, killed on every path out.
struct Server {
    pid_t pid = -1;
    Server(const std::string& bp, const std::string& root) {
        pid = fork();
        if (pid == 0) {
            const int null = open("/dev/null", O_WRONLY);
            if (null >= 0) dup2(null, 1), dup2(null, 2);
            execl(CHIMERA_RTPU_BIN, CHIMERA_RTPU_BIN, "--backplane", bp.c_str(), "--host-server", root.c_str(),
                  static_cast<char*>(nullptr));
            _exit(127);
        }
        if (pid < 0) throw std::runtime_error("fork failed");
    }
    ~Server() {
        kill(pid, SIGKILL);
        waitpid(pid, nullptr, 0);
    }
};

// A file in a root, a private backplane with the host server on it, this
// process joined as RTPU 1: what every row here starts from.
struct HostSystem {
    Root root;
    ipcb::BackplaneFile f;
    Server server;
    ipcb::Joined me;
    explicit HostSystem(const char* what, const char* base = "/tmp")
        : root(base), f(what), server(f.path, root.dir), me(f.path, 1) {
        ipcb::wait_rtpus_running({0});
    }
};

// In a task: sequential chm_xfs_read of 64 KiB blocks of `file` (opened by
// its name beneath the root, rewound at its end) interleaved with pread(2)
// of the same blocks of the same file: *xfs and *peer.
void measure_reads(Session& s, const std::string& file, Stats* xfs, Stats* peer) {
    // The server answers once its express mail runs.
    for (int i = 0; chm_rtpu_ping(0, nullptr) != 0; ++i)
        if (i > 500) throw std::runtime_error("host server not answering");
    const int h = chm_xfs_open("data.bin", CHM_XFS_RDONLY, 0);
    if (h < 0) throw std::runtime_error(std::string("chm_xfs_open: ") + chm_err_last());
    const int fd = open(file.c_str(), O_RDONLY);
    std::vector<char> buf(kBlock);
    std::size_t xfs_off = 0, pread_off = 0;
    auto by_xfs = [&](std::uint64_t n) {
        const std::uint64_t t0 = mono_ns();
        for (std::uint64_t i = 0; i < n; ++i) {
            if (xfs_off == kFile) {
                if (chm_xfs_lseek(h, 0, SEEK_SET) != 0) throw std::runtime_error(chm_err_last());
                xfs_off = 0;
            }
            if (chm_xfs_read(h, buf.data(), kBlock) != std::int64_t(kBlock))
                throw std::runtime_error(std::string("chm_xfs_read: ") + chm_err_last());
            xfs_off += kBlock;
        }
        return double(mono_ns() - t0);
    };
    auto by_pread = [&](std::uint64_t n) {
        const std::uint64_t t0 = mono_ns();
        for (std::uint64_t i = 0; i < n; ++i) {
            if (pread_off == kFile) pread_off = 0;
            if (pread(fd, buf.data(), kBlock, off_t(pread_off)) != ssize_t(kBlock))
                throw std::runtime_error("pread failed");
            pread_off += kBlock;
        }
        return double(mono_ns() - t0);
    };
    std::tie(*xfs, *peer) = s.measure_interleaved(by_xfs, by_pread);
    (void)chm_xfs_close(h);
    close(fd);
}

void xfs_rows(Session& s) {
    Session::pin(s.cpu(0));
    HostSystem sys("xfs");
    const Root& root = sys.root;
    ipcb::Kernel k(1, 0);
    Stats xfs, peer, call;
    std::function<void()> body = [&] {
        measure_reads(s, root.file, &xfs, &peer);
        char cwd[64];
        call = s.measure([&](std::uint64_t n) {
            const std::uint64_t t0 = mono_ns();
            for (std::uint64_t i = 0; i < n; ++i)
                if (chm_host_getcwd(cwd, sizeof cwd) != 0) throw std::runtime_error(chm_err_last());
            return double(mono_ns() - t0);
        });
    };
    k.spawn(&body, 10, "client");
    k.run();
    const std::string where = "pinned " + s.cpu_name(0) + "; a task on RTPU 1 (this process) and chimera-rtpu "
                              "--host-server (defaults, unpinned) in slot 0";
    s.emit("xfs_read_64k", where + "; 64 KiB blocks of an 8 MiB page-cached file, in turn with the peer",
           xfs.median, xfs.min, xfs.max);
    s.emit("peer_pread_64k", "the same task; pread(2) of the same 64 KiB blocks of the same file", peer.median,
           peer.min, peer.max);
    s.emit("host_call_rt", where + "; chm_host_getcwd round trip", call.median, call.min, call.max);
}
CHM_BENCH_MEASUREMENT(xfs_rows, "xfs_read_64k", "peer_pread_64k", "host_call_rt");

// The same reads where the direct way is refused (the root on tmpfs, which
// has no RWF_NOWAIT): every block through the host server, read ahead
// (stream.cpp). What a file the page cache does not hold costs.
void xfs_server_rows(Session& s) {
    Session::pin(s.cpu(0));
    HostSystem sys("xfs-server", "/dev/shm");
    ipcb::Kernel k(1, 0);
    Stats xfs, peer;
    std::function<void()> body = [&] { measure_reads(s, sys.root.file, &xfs, &peer); };
    k.spawn(&body, 10, "client");
    k.run();
    s.emit("xfs_read_64k_server", "pinned " + s.cpu_name(0) + "; as xfs_read_64k, the file on tmpfs (no RWF_NOWAIT): "
           "every block through the host server, read ahead; peer: pread of the tmpfs file",
           xfs.median, xfs.min, xfs.max);
    s.emit("peer_pread_64k_tmpfs", "pread(2) of the same 64 KiB blocks of the tmpfs file", peer.median, peer.min,
           peer.max);
}
CHM_BENCH_MEASUREMENT(xfs_server_rows, "xfs_read_64k_server", "peer_pread_64k_tmpfs");

// `chimera console --rtpus 1` on a pseudo-terminal, as an operator runs
// it: a thread reads the terminal and records, for every line "L <stamp>"
// it shows, the time from the stamp to its arrival on the terminal.
struct LineClock {
    int master = -1;
    pid_t pid = -1;
    std::string home;
    std::vector<double> ns;
    std::atomic<int> got{0};
    std::atomic<bool> ready{false};
    std::thread reader;
    explicit LineClock(const std::string& bp) {
        char tmpl[] = "/tmp/chimera-bench-home-XXXXXX";
        if (!mkdtemp(tmpl)) throw std::runtime_error("mkdtemp failed");
        home = tmpl;  // its history file goes there
        winsize ws{24, 80, 0, 0};
        pid = forkpty(&master, nullptr, nullptr, &ws);
        if (pid < 0) throw std::runtime_error("forkpty failed");
        if (pid == 0) {
            setenv("HOME", home.c_str(), 1);
            execl(CHIMERA_BIN, CHIMERA_BIN, "console", "--backplane", bp.c_str(), "--rtpus", "1",
                  static_cast<char*>(nullptr));
            _exit(127);
        }
        reader = std::thread([this] { run(); });
        for (int i = 0; !ready.load(std::memory_order_acquire); ++i) {
            if (i > 5000) throw std::runtime_error("chimera console did not start");
            usleep(2000);
        }
    }
    void run() {
        std::string pending;
        char buf[4096];
        for (;;) {
            const ssize_t k = ::read(master, buf, sizeof buf);
            if (k <= 0) return;
            const std::uint64_t now = mono_ns();
            pending.append(buf, std::size_t(k));
            if (pending.find("chimera> ") != std::string::npos) ready.store(true, std::memory_order_release);
            std::size_t nl;
            while ((nl = pending.find('\n')) != std::string::npos) {
                const std::size_t at = pending.find("L ");
                unsigned long long stamp = 0;
                if (at < nl && std::sscanf(pending.c_str() + at, "L %llu", &stamp) == 1) {
                    ns.push_back(double(now - stamp));
                    got.fetch_add(1, std::memory_order_release);
                }
                pending.erase(0, nl + 1);
            }
        }
    }
    ~LineClock() {
        if (pid > 0) {
            kill(pid, SIGTERM);
            for (int i = 0; i < 500 && waitpid(pid, nullptr, WNOHANG) == 0; ++i) usleep(2000);
            kill(pid, SIGKILL);
            waitpid(pid, nullptr, 0);
        }
        if (master >= 0) close(master);  // the reader's read ends
        if (reader.joinable()) reader.join();
        if (!home.empty()) {
            unlink((home + "/.chimera_history").c_str());
            rmdir(home.c_str());
        }
    }
};

void console_rows(Session& s) {
    Session::pin(s.cpu(0));
    HostSystem sys("console");
    LineClock clock(sys.f.path);
    ipcb::Kernel k(1, 0);
    if (const int r = chm::host::console::start(1)) throw std::runtime_error("console stdio: " + std::to_string(r));
    struct Stop {
        ~Stop() { chm::host::console::stop(); }
    } stop;
    const int lines = s.quick() ? 50 : 1000;
    std::function<void()> body = [&] {
        for (int i = 0; chm_rtpu_ping(0, nullptr) != 0; ++i)
            if (i > 500) throw std::runtime_error("host server not answering");
        for (int i = 0; i < lines; ++i) {
            std::printf("L %llu\n", static_cast<unsigned long long>(mono_ns()));
            chm_task_pause_until(chm_time_now() + 1'000'000);
        }
        for (int i = 0; clock.got.load(std::memory_order_acquire) < lines && i < 2000; ++i)
            chm_task_pause_until(chm_time_now() + 1'000'000);
    };
    k.spawn(&body, 10, "printer");
    k.run();
    if (clock.got.load() < lines)
        throw std::runtime_error("only " + std::to_string(clock.got.load()) + " of " + std::to_string(lines) +
                                 " lines reached the console");
    std::vector<double> v = clock.ns;
    std::sort(v.begin(), v.end());
    s.emit("console_line_latency",
           "pinned " + s.cpu_name(0) + "; a task on RTPU 1 (this process, kernel FIXED) printf of one line, "
           "through the stdio drainer (priority 1), chimera-rtpu --host-server (defaults) and chimera console "
           "--rtpus 1 to its terminal (a pseudo-terminal read here); median of " + std::to_string(v.size()) +
           " lines at 1 kHz, min .. max",
           v[v.size() / 2], v.front(), v.back());
}
CHM_BENCH_MEASUREMENT(console_rows, "console_line_latency");

}  // namespace
}  // namespace chm::bench
