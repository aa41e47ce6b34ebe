// chimera load / kill / stop --rtpu: acting on one RTPU of a running
// system through its express mail (chimera/rtpu.h).
#include <cerrno>
#include <csignal>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include <sys/stat.h>
#include <unistd.h>

#include "chimera/bp.h"
#include "chimera/rtpu.h"
#include "cmd.hpp"
#include "ipc/backplane/backplane.hpp"
#include "../parse_num.hpp"

namespace chimera_cmd {

namespace {

const char* slot_state_word(chm_bp_slot_state s) {
    switch (s) {
    case CHM_BP_FREE: return "free";
    case CHM_BP_JOINING: return "joining";
    case CHM_BP_RUNNING: return "running";
    case CHM_BP_LEAVING: return "leaving";
    case CHM_BP_DEAD: return "dead";
    case CHM_BP_RECOVERING: return "being recovered";
    }
    return "in an unknown state";
}

// Attach after checking the file whole; false when either failed (said).
bool open_backplane(const Options& o) {
    struct stat ls{};
    if (lstat(o.backplane.c_str(), &ls) != 0) {
        say("no backplane at %s (chimera start creates one)", o.backplane.c_str());
        return false;
    }
    return file_fit_to_use(o.backplane) && attach(o) == 0;
}

// The reason an express-mail call failed, for a message.
std::string why(int r) {
    const char* e = chm_rtpu_last_error();
    return e[0] ? e : std::strerror(-r);
}

}  // namespace

int resolve_rtpu(const char* word) {
    chm_bp_status_t st;
    if (chm_bp_status(&st) != 0) {
        say("not attached to a backplane");
        return -1;
    }
    long n = -1;
    if (!chimera_tools::parse_num(word, 0, 1000000, &n)) {
        for (std::uint32_t s = 0; s < st.slots; ++s)
            if (st.slot[s].kind == CHM_BP_KIND_RTPU && st.slot[s].state != CHM_BP_FREE &&
                std::strcmp(st.slot[s].name, word) == 0)
                n = long(s);
        if (n < 0) {
            say("no RTPU named \"%s\" (an RTPU is given by its number or its name in chimera status)", word);
            return -1;
        }
    }
    if (n < 1 || n >= long(st.slots)) {
        say("no RTPU %s: this backplane has RTPUs 1..%u", word, st.slots - 1);
        return -1;
    }
    const chm_bp_slot_info_t& i = st.slot[n];
    if (i.kind == CHM_BP_KIND_HOST && i.state != CHM_BP_FREE) {
        say("slot %ld is a host program (%s), not an RTPU", n, i.name);
        return -1;
    }
    if (i.state != CHM_BP_RUNNING || i.kind != CHM_BP_KIND_RTPU) {
        say("RTPU %ld is not running (its slot is %s; chimera status shows the table)", n, slot_state_word(i.state));
        return -1;
    }
    return int(n);
}

int cmd_load(const Options& o, const std::vector<const char*>& args) {
    // The program is checked here first, so that a name that is not a
    // file says so in our words, not the RTPU's.
    const char* prog = args[1];
    char real[PATH_MAX];
    struct stat st{};
    if (!realpath(prog, real) || stat(real, &st) != 0) {
        say("load: program %s: %s", prog, std::strerror(errno));
        return 1;
    }
    if (!S_ISREG(st.st_mode)) {
        say("load: program %s is not a file (a control program is a shared object with a main)", prog);
        return 1;
    }
    if (!open_backplane(o)) return 1;
    const int rtpu = resolve_rtpu(args[0]);
    int status = 1;
    if (rtpu > 0) {
        std::vector<const char*> argv = {real};  // argv[0]: its path, as chimera-rtpu gives it
        argv.insert(argv.end(), args.begin() + 2, args.end());
        chm_tid_t tid = CHM_TID_NONE;
        const int r = chm_rtpu_spawn(rtpu, real, int(argv.size()), argv.data(), &tid);
        if (r < 0) {
            say("load: %s", why(r).c_str());
        } else {
            std::printf("loaded %s on RTPU %d: task %lld\n", real, rtpu, (long long)tid);
            status = 0;
        }
    }
    std::fflush(stdout);
    (void)chm_bp_leave();
    return status;
}

int cmd_kill(const Options& o, const std::vector<const char*>& args) {
    if (!open_backplane(o)) return 1;
    const int rtpu = resolve_rtpu(args[0]);
    int status = 1;
    if (rtpu > 0) {
        // A number is a task id; anything else a task's name.
        const char* task = args[1];
        long long id = 0;
        chm_tid_t tid = CHM_TID_NONE;
        int r = 0;
        if (chimera_tools::parse_tid(task, &id)) {
            tid = chm_tid_t(id);
        } else if ((r = chm_rtpu_find(rtpu, task, &tid)) == -ESRCH) {
            say("kill: RTPU %d has no task named \"%s\" (chimera status lists them)", rtpu, task);
        } else if (r < 0) {
            say("kill: %s", why(r).c_str());
        }
        if (r == 0) {
            // Its name, for the report.
            std::string name;
            static chm_rtpu_task_t list[512];
            const int n = chm_rtpu_tasks(rtpu, list, 512, nullptr);
            for (int i = 0; i < n; ++i)
                if (list[i].id == tid) name = list[i].name;
            r = chm_rtpu_destroy(rtpu, tid);
            if (r == 0) {
                std::printf("RTPU %d: task %lld%s%s%s destroyed\n", rtpu, (long long)tid, name.empty() ? "" : " (",
                            name.c_str(), name.empty() ? "" : ")");
                status = 0;
            } else if (r == -ESRCH) {
                say("kill: RTPU %d has no task %lld (chimera status lists them)", rtpu, (long long)tid);
            } else if (r == -EPERM) {
                say("kill: task %lld is RTPU %d's express-mail server: not destroyed (chimera stop --rtpu %d stops "
                    "the RTPU)", (long long)tid, rtpu, rtpu);
            } else {
                say("kill: %s", why(r).c_str());
            }
        }
    }
    std::fflush(stdout);
    (void)chm_bp_leave();
    return status;
}

int cmd_stop_one(const Options& o) {
    if (!open_backplane(o)) return 1;
    char word[16];
    std::snprintf(word, sizeof word, "%d", o.rtpu);
    const int rtpu = resolve_rtpu(word);
    if (rtpu < 0) {
        (void)chm_bp_leave();
        return 1;
    }
    chm_bp_status_t st;
    (void)chm_bp_status(&st);
    const std::uint32_t gen = st.slot[rtpu].generation;
    const int pid = st.slot[rtpu].pid;
    const std::uint64_t start = chm::bp::proc_start_time(pid);  // pid reuse is not "alive"
    const double limit = o.timeout_s < 0 ? 5.0 : o.timeout_s;
    // Gracefully first: the RTPU replies, runs its shutdown hooks, leaves.
    const int r = chm_rtpu_stop(rtpu, 0);
    bool gone = false;
    if (r == 0) {
        const std::uint64_t end = mono_ms() + std::uint64_t(limit * 1000);
        while (!gone && mono_ms() < end) {
            (void)chm_bp_status(&st);
            const chm_bp_slot_info_t& i = st.slot[rtpu];
            gone = i.generation != gen || i.pid != pid || i.state == CHM_BP_FREE || i.state == CHM_BP_DEAD;
            if (!gone) nap_ms(10);
        }
        // The slot is left just before the process exits.
        const std::uint64_t pend = mono_ms() + 2000;
        while (gone && chm::bp::proc_alive(pid, start) && mono_ms() < pend) nap_ms(5);
    } else {
        say("RTPU %d did not take the stop request (%s): stopping it with signals", rtpu, why(r).c_str());
    }
    int status = 0;
    if (gone) {
        std::printf("RTPU %d (pid %d): stopped\n", rtpu, pid);
    } else {
        int refused = 0;
        stop_attached(r == 0 ? 1.0 : limit, false, &refused, rtpu);
        status = refused ? 1 : 0;
    }
    std::fflush(stdout);
    (void)chm_bp_leave();
    return status;
}

}  // namespace chimera_cmd
