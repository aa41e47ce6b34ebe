// chimera stop / rm, and what the subcommands share (cmd.hpp).
#include <cerrno>
#include <csignal>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <string>
#include <vector>

#include <dirent.h>
#include <sys/stat.h>
#include <unistd.h>

#include "chimera/bp.h"
#include "chimera/rtpu.h"
#include "cmd.hpp"
#include "ipc/backplane/backplane.hpp"

namespace chimera_cmd {

void say(const char* fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    std::fprintf(stderr, "chimera: ");
    std::vfprintf(stderr, fmt, ap);
    std::fprintf(stderr, "\n");
    va_end(ap);
}

std::uint64_t mono_ms() {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return std::uint64_t(ts.tv_sec) * 1000u + std::uint64_t(ts.tv_nsec) / 1000000u;
}

std::string log_path(const std::string& backplane, int n) {
    if (n == 0) return backplane + ".host.log";  // the host server's
    return backplane + ".rtpu" + std::to_string(n) + ".log";
}

namespace {

bool is_rtpu(const chm_bp_slot_info_t& s) {
    return s.kind == CHM_BP_KIND_RTPU &&
           (s.state == CHM_BP_RUNNING || s.state == CHM_BP_JOINING || s.state == CHM_BP_LEAVING);
}

// The live members of a mapped table (cmd.hpp, live_members).
std::string describe_live(const chm::bp::View& v, bool rtpus_only) {
    std::string live;
    for (std::uint32_t s = 0; s < v.slots(); ++s) {
        const chm::bp::RtpuEntry* e = v.rtpu(s);
        const auto state = chm::bp::status_state(e->status.load());
        if (state == chm::bp::SlotState::Free || state == chm::bp::SlotState::Dead) continue;
        const bool host = e->kind.load() == 2;
        if (rtpus_only && host) continue;
        const int pid = int(e->pid.load());
        if (!chm::bp::proc_alive(pid, e->pid_start.load())) continue;
        const std::string who = s == 0 && !host ? "the host server" : std::string(host ? "host " : "RTPU ") + std::to_string(s);
        live += (live.empty() ? "" : ", ") + who + " (pid " + std::to_string(pid) + ")";
    }
    return live;
}

}  // namespace

std::string live_members(const std::string& path, bool rtpus_only, std::string* error) {
    chm::bp::View v;
    int fd = -1;
    char why[768];
    if (chm::bp::map_file(path.c_str(), false, &v, &fd, why, sizeof why, true) != 0) {
        if (error) *error = why;
        return "";
    }
    const std::string live = describe_live(v, rtpus_only);
    chm::bp::unmap(&v);
    ::close(fd);
    return live;
}

// Attach to the backplane as a host for the length of one command.
int attach(const Options& o) {
    if (access(o.backplane.c_str(), F_OK) != 0) {
        say("no backplane at %s (chimera start creates one)", o.backplane.c_str());
        return -ENOENT;
    }
    if (int r = chm_bp_attach_host(o.backplane.c_str(), "chimera", nullptr)) {
        say("cannot attach to %s: %s", o.backplane.c_str(), chm_bp_last_error());
        return r;
    }
    return 0;
}

bool file_fit_to_use(const std::string& path) {
    // Who may attach it first (a file we must not trust is not even read),
    // then the whole table and every object in it, naming the field.
    if (chm_bp_check_file(path.c_str()) != 0) {
        say("%s", chm_bp_last_error());
        return false;
    }
    if (chm_bp_validate(path.c_str()) != 0) {
        say("refusing %s: %s", path.c_str(), chm_bp_last_error());
        return false;
    }
    return true;
}

int stop_attached(double timeout_s, bool quiet, int* refused_out, int only) {
    chm_bp_status_t st;
    (void)chm_bp_status(&st);
    struct Victim {
        int slot, pid;
        std::uint32_t gen, status;  // status: the word the signals are checked against
        bool done;
        std::uint64_t start;  // the process's start time: pid reuse is not "alive"
    };
    // Signals go only to processes the kernel confirms are this
    // backplane's members (bp::signal_member); a refused slot is reported
    // and left alone, never killed.
    std::vector<Victim> v;
    int refused = 0;
    for (std::uint32_t s = 0; s < st.slots; ++s)
        if (is_rtpu(st.slot[s]) && st.slot[s].pid > 0 && (only < 0 || int(s) == only)) {
            const std::uint32_t word = chm::bp::current()->rtpu(s)->status.load();
            const int r = chm::bp::signal_member(s, chm::bp::MemberTarget::Process, SIGTERM, word);
            if (r == -EPERM) {
                ++refused;
                if (!quiet) std::printf("RTPU %u: not stopped: %s\n", s, chm_bp_last_error());
                continue;
            }
            v.push_back({int(s), st.slot[s].pid, st.slot[s].generation, word, false,
                         chm::bp::proc_start_time(st.slot[s].pid)});
        }
    // Gone: the slot no longer holds that generation in a live state.
    auto gone = [](const Victim& x) {
        chm_bp_status_t now;
        (void)chm_bp_status(&now);
        const chm_bp_slot_info_t& i = now.slot[x.slot];
        return i.generation != x.gen || !(i.state == CHM_BP_RUNNING || i.state == CHM_BP_JOINING ||
                                          i.state == CHM_BP_LEAVING) ||
               i.pid != x.pid;
    };
    const std::uint64_t end = mono_ms() + std::uint64_t(timeout_s * 1000);
    for (;;) {
        bool all = true;
        for (Victim& x : v)
            if (!x.done) all = all && (x.done = gone(x));
        if (all || mono_ms() >= end) break;
        nap_ms(10);
    }
    // The slot is left just before the process exits: wait (bounded) for
    // the exit too, so that "stopped" means no such process runs.
    for (const Victim& x : v) {
        const std::uint64_t pend = mono_ms() + 2000;
        while (x.done && chm::bp::proc_alive(x.pid, x.start) && mono_ms() < pend) nap_ms(5);
    }
    int killed = 0;
    for (Victim& x : v) {
        if (x.done) {
            if (!quiet) std::printf("RTPU %d (pid %d): stopped\n", x.slot, x.pid);
            continue;
        }
        if (chm::bp::signal_member(std::uint32_t(x.slot), chm::bp::MemberTarget::Process, SIGKILL, x.status) == -EPERM) {
            if (!quiet) std::printf("RTPU %d: not killed: %s\n", x.slot, chm_bp_last_error());
            continue;
        }
        ++killed;
        // Our monitor thread recovers the slot once the process is gone.
        const std::uint64_t kend = mono_ms() + 3000;
        while (!gone(x) && mono_ms() < kend) nap_ms(10);
        if (!quiet)
            std::printf("RTPU %d (pid %d): killed (did not stop within %.1f s)\n", x.slot, x.pid, timeout_s);
    }
    if (!quiet && v.empty() && !refused) std::printf("no RTPU running\n");
    std::fflush(stdout);
    if (refused_out) *refused_out = refused;
    return killed;
}

int cmd_stop(const Options& o) {
    if (attach(o)) return 1;
    int refused = 0;
    stop_attached(o.timeout_s < 0 ? 5.0 : o.timeout_s, false, &refused);
    chm_bp_status_t st;
    (void)chm_bp_status(&st);
    int hosts = 0;
    for (std::uint32_t s = 0; s < st.slots; ++s)
        if (int(s) != st.self && st.slot[s].kind == CHM_BP_KIND_HOST && st.slot[s].state == CHM_BP_RUNNING) ++hosts;
    if (hosts) std::printf("%d host program%s still attached\n", hosts, hosts == 1 ? "" : "s");
    (void)chm_bp_leave();
    return refused ? 1 : 0;
}

int cmd_rm(const Options& o) {
    const char* path = o.backplane.c_str();
    if (access(path, F_OK) != 0) {
        say("no backplane at %s", path);
        return 1;
    }
    chm::bp::View v;
    int fd = -1;
    char why[768];
    const int r = chm::bp::map_file(path, false, &v, &fd, why, sizeof why, true);
    struct stat ls{};
    if (r == -EPERM || r == -ELOOP || (lstat(path, &ls) == 0 && !S_ISREG(ls.st_mode))) {
        // Not ours to judge, whatever --force says.
        say("%s: %s", path, why);
        return 1;
    }
    if (r && !o.force) {
        say("%s is not a usable backplane file (%s): not removed (rm --force removes it anyway)", path, why);
        return 1;
    }
    if (r == 0) {
        const std::string live = describe_live(v, false);
        chm::bp::unmap(&v);
        ::close(fd);
        if (!live.empty() && !o.force) {
            say("%s is in use by %s: run chimera stop first (or rm --force)", path, live.c_str());
            return 1;
        }
    }
    if (unlink(path) != 0) {
        say("cannot remove %s: %s", path, std::strerror(errno));
        return 1;
    }
    // Its RTPU logs (PATH.rtpuN.log): only files of ours (in a shared
    // directory such as /tmp, root could otherwise remove anyone's).
    const std::string p(path);
    const std::size_t cut = p.rfind('/');
    const std::string dir = cut == std::string::npos ? "." : p.substr(0, cut ? cut : 1);
    const std::string base = (cut == std::string::npos ? p : p.substr(cut + 1)) + ".rtpu";
    int logs = 0;
    if (DIR* d = opendir(dir.c_str())) {
        while (dirent* e = readdir(d)) {
            const std::string n = e->d_name;
            struct stat ls{};
            if (n.size() > base.size() + 4 && n.compare(0, base.size(), base) == 0 &&
                n.compare(n.size() - 4, 4, ".log") == 0 && lstat((dir + "/" + n).c_str(), &ls) == 0 &&
                ls.st_uid == geteuid() && unlink((dir + "/" + n).c_str()) == 0)
                ++logs;
        }
        closedir(d);
    }
    // The host server's log and a console socket a killed server left.
    for (const char* tail : {".host.log", ".console"}) {
        const std::string f = p + tail;
        struct stat ls{};
        if (lstat(f.c_str(), &ls) == 0 && ls.st_uid == geteuid() && (S_ISREG(ls.st_mode) || S_ISSOCK(ls.st_mode)) &&
            unlink(f.c_str()) == 0)
            ++logs;
    }
    std::printf("removed %s%s\n", path, logs ? " and its logs" : "");
    return 0;
}

}  // namespace chimera_cmd
