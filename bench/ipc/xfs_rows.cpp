// The host server (issue 19) with real processes in their default
// configuration: chimera-rtpu --host-server in slot 0 on a private
// backplane, the bench process RTPU 1 with a kernel, its task the client.
//  * xfs_read_64k: chm_xfs_read of 64 KiB, sequential through an 8 MiB file
//    in the page cache (rewound at its end), beside pread(2) of the same
//    64 KiB blocks of the same file by the same task (peer_pread_64k), run
//    in turn. Target: >= 0.5 x pread's throughput (time <= 2 x).
//  * host_call_rt: chm_host_getcwd, the smallest host procedure call: one
//    request to the host server and its reply, round trip (no target).
#include <fcntl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "../harness.hpp"
#include "chimera/host.h"
#include "chimera/rtpu.h"
#include "chimera/xfs.h"
#include "rtpu.hpp"

namespace chm::bench {
namespace {

constexpr std::size_t kBlock = 64 * 1024;
constexpr std::size_t kFile = 8 * 1024 * 1024;

// A directory with the file, removed on every path out.
struct Root {
    std::string dir, file;
    Root() {
        char buf[] = "/tmp/chimera-bench-xfs-XXXXXX";
        if (!mkdtemp(buf)) throw std::runtime_error("mkdtemp failed");
        dir = buf;
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

void xfs_rows(Session& s) {
    Session::pin(s.cpu(0));
    Root root;
    ipcb::BackplaneFile f("xfs");
    Server server(f.path, root.dir);
    ipcb::Joined me(f.path, 1);
    ipcb::wait_rtpus_running({0});
    ipcb::Kernel k(1, 0);
    Stats xfs, peer, call;
    std::function<void()> body = [&] {
        // The server answers once its express mail runs.
        for (int i = 0; chm_rtpu_ping(0, nullptr) != 0; ++i)
            if (i > 500) throw std::runtime_error("host server not answering");
        const int h = chm_xfs_open("data.bin", CHM_XFS_RDONLY, 0);
        if (h < 0) throw std::runtime_error(std::string("chm_xfs_open: ") + chm_xfs_last_error());
        const int fd = open(root.file.c_str(), O_RDONLY);
        std::vector<char> buf(kBlock);
        std::size_t xfs_off = 0, pread_off = 0;
        auto by_xfs = [&](std::uint64_t n) {
            const std::uint64_t t0 = mono_ns();
            for (std::uint64_t i = 0; i < n; ++i) {
                if (xfs_off == kFile) {
                    chm_xfs_lseek(h, 0, SEEK_SET);
                    xfs_off = 0;
                }
                const std::int64_t r = chm_xfs_read(h, buf.data(), kBlock);
                if (r != std::int64_t(kBlock)) throw std::runtime_error(std::string("chm_xfs_read: ") + chm_xfs_last_error());
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
        std::tie(xfs, peer) = s.measure_interleaved(by_xfs, by_pread);
        chm_xfs_close(h);
        close(fd);
        char cwd[64];
        call = s.measure([&](std::uint64_t n) {
            const std::uint64_t t0 = mono_ns();
            for (std::uint64_t i = 0; i < n; ++i)
                if (chm_host_getcwd(cwd, sizeof cwd) != 0) throw std::runtime_error(chm_xfs_last_error());
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

}  // namespace
}  // namespace chm::bench
