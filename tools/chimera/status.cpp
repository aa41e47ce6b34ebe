// chimera status [--watch]: the RTPU table and, for every running RTPU, its
// tasks with their timing figures and the utilisation of its periodic
// tasks and of its MUF critical set (the anchors: RTEMS's rate-monotonic
// period report, Xenomai's /proc/xenomai/sched/stat). --watch redraws the
// page in place, like top, until q, Ctrl-C or --count frames.
#include <cerrno>
#include <csignal>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <map>
#include <string>
#include <utility>

#include <poll.h>
#include <sys/stat.h>
#include <termios.h>
#include <unistd.h>

#include "chimera/bp.h"
#include "chimera/rtpu.h"
#include "cmd.hpp"

namespace chimera_cmd {

const char* task_state(chm_task_state s) {
    static const char* const kNames[] = {"ready", "running", "blocked", "suspended", "waitperiod", "paused", "ended"};
    return unsigned(s) < 7 ? kNames[s] : "?";
}

namespace {

const char* state_name(chm_bp_slot_state s) {
    static const char* const kNames[] = {"FREE", "JOINING", "RUNNING", "LEAVING", "DEAD", "RECOVERING"};
    return unsigned(s) < 6 ? kNames[s] : "?";
}

const char* policy_name(chm_sched_policy p) {
    static const char* const kNames[] = {"MUF", "RM", "EDF", "MLF", "FIXED", "user"};
    return unsigned(p) < 6 ? kNames[p] : "?";
}

bool is_rtpu(const chm_bp_slot_info_t& s) {
    return s.kind == CHM_BP_KIND_RTPU &&
           (s.state == CHM_BP_RUNNING || s.state == CHM_BP_JOINING || s.state == CHM_BP_LEAVING);
}

// A page is built as text first, so --watch can draw it in one write.
struct Page {
    std::string text;
    void add(const char* fmt, ...) __attribute__((format(printf, 2, 3))) {
        va_list ap, again;
        va_start(ap, fmt);
        va_copy(again, ap);
        const int n = std::vsnprintf(nullptr, 0, fmt, ap);
        va_end(ap);
        if (n > 0) {
            const std::size_t at = text.size();
            text.resize(at + std::size_t(n) + 1);
            std::vsnprintf(&text[at], std::size_t(n) + 1, fmt, again);
            text.resize(at + std::size_t(n));
        }
        va_end(again);
    }
};

// A duration in the unit that keeps it short: 850ns, 12.3us, 4.56ms, 1.20s.
std::string dur(std::uint64_t ns) {
    char b[32];
    if (ns < 1000) std::snprintf(b, sizeof b, "%lluns", static_cast<unsigned long long>(ns));
    else if (ns < 1000000) std::snprintf(b, sizeof b, "%.3gus", double(ns) / 1e3);
    else if (ns < 1000000000) std::snprintf(b, sizeof b, "%.3gms", double(ns) / 1e6);
    else std::snprintf(b, sizeof b, "%.3gs", double(ns) / 1e9);
    return b;
}

// What the previous frame saw, for CPU shares over the refresh interval.
struct Seen {
    std::int32_t pid = 0;
    std::uint64_t uptime_ns = 0;
    std::map<chm_tid_t, std::uint64_t> cpu;
};
using History = std::map<int, Seen>;  // by slot

// Utilisation of a set of periodic tasks: sum of CPU per cycle / period,
// with the mean CPU per cycle (cpu / cycles), the worst cycle, and the
// declared estimate (wcet).
struct Util {
    int tasks = 0;
    double mean = 0, worst = 0, declared = 0;
    void add(const chm_rtpu_task_t& t) {
        if (!t.period_ns || t.state == CHM_TASK_ENDED) return;
        ++tasks;
        const double p = double(t.period_ns);
        if (t.cycles) mean += double(t.cpu_ns) / double(t.cycles) / p;
        worst += double(t.worst_cycle_cpu_ns) / p;
        declared += double(t.wcet_ns) / p;
    }
};

void tasks_of(Page& pg, int slot, History* hist, History* next) {
    chm_rtpu_info_t info;
    if (int r = chm_rtpu_ping(slot, &info)) {
        pg.add("    (no reply: %s)\n", chm_rtpu_last_error()[0] ? chm_rtpu_last_error() : std::strerror(-r));
        return;
    }
    static chm_rtpu_task_t tasks[512];
    int total = 0;
    const int n = chm_rtpu_tasks(slot, tasks, 512, &total);
    if (n < 0) {
        pg.add("    (no task list: %s)\n", chm_rtpu_last_error());
        return;
    }
    // The share of one CPU each task had: over the interval since the
    // previous frame of the same RTPU process, else since its start.
    const Seen* before = nullptr;
    if (hist) {
        auto it = hist->find(slot);
        if (it != hist->end() && it->second.pid == info.pid && it->second.uptime_ns < info.uptime_ns)
            before = &it->second;
    }
    const double span = double(info.uptime_ns - (before ? before->uptime_ns : 0));
    Seen now{info.pid, info.uptime_ns, {}};
    Util all, crit;
    pg.add("    %s, %d task%s, up %.1f s, %u requests served; CPU%% %s\n", policy_name(info.policy), total,
           total == 1 ? "" : "s", double(info.uptime_ns) / 1e9, info.served,
           before ? "over the last refresh" : "since the RTPU started");
    pg.add("    %-8s %-20s %-10s %6s %1s %8s %6s %9s %7s %9s %9s %12s\n", "TID", "NAME", "STATE", "PRIO", "C",
           "PERIOD", "CPU%", "CYCLES", "MISSES", "LATE MAX", "CPU/CYC", "STACK HW");
    for (int i = 0; i < n; ++i) {
        const chm_rtpu_task_t& t = tasks[i];
        now.cpu[t.id] = t.cpu_ns;
        std::uint64_t used = t.cpu_ns;
        if (before) {
            auto c = before->cpu.find(t.id);
            if (c != before->cpu.end() && c->second <= t.cpu_ns) used -= c->second;
        }
        const double share = span > 0 ? 100.0 * double(used) / span : 0;
        all.add(t);
        if (t.critical) crit.add(t);
        char stack[32];
        std::snprintf(stack, sizeof stack, "%.1fK %3.0f%%", double(t.stack_high_water) / 1024,
                      t.stack_size ? 100.0 * double(t.stack_high_water) / double(t.stack_size) : 0.0);
        pg.add("    %-8lld %-20s %-10s %6d %1s %8s %6.1f %9llu %7llu %9s %9s %12s\n", (long long)t.id, t.name,
               task_state(t.state), t.priority, t.critical ? "*" : "", t.period_ns ? dur(t.period_ns).c_str() : "-",
               share, static_cast<unsigned long long>(t.cycles), static_cast<unsigned long long>(t.misses),
               t.period_ns ? dur(t.worst_lateness_ns).c_str() : "-",
               t.period_ns ? dur(t.worst_cycle_cpu_ns).c_str() : "-", stack);
    }
    if (total > n) pg.add("    ... %d more\n", total - n);
    pg.add("    utilisation (CPU per cycle / period, mean | worst | declared): periodic tasks (%d) %.1f%% | %.1f%% | "
           "%.1f%%; MUF critical set (%d) %.1f%% | %.1f%% | %.1f%%\n",
           all.tasks, 100 * all.mean, 100 * all.worst, 100 * all.declared, crit.tasks, 100 * crit.mean,
           100 * crit.worst, 100 * crit.declared);
    if (next) (*next)[slot] = std::move(now);
}

// One page: the table, the dead, each running RTPU's tasks.
void render(Page& pg, const Options& o, History* hist, History* next) {
    chm_bp_status_t st;
    (void)chm_bp_status(&st);
    timespec now{};
    clock_gettime(CLOCK_REALTIME, &now);
    const double age =
        double(std::uint64_t(now.tv_sec) * 1000000000ull + std::uint64_t(now.tv_nsec) - st.created_ns) / 1e9;
    pg.add("backplane %s: %u slots, created %.0f s ago, %u/%u named objects, common memory %u of %u bytes free, "
           "%u recoveries\n",
           o.backplane.c_str(), st.slots, age, st.objects, st.registry_capacity, st.common_free, st.common_size,
           st.recoveries);
    pg.add("%-5s %-5s %-11s %-8s %-10s %s\n", "SLOT", "KIND", "STATE", "PID", "HEARTBEAT", "NAME");
    int rtpus = 0;
    for (std::uint32_t s = 0; s < st.slots; ++s) {
        const chm_bp_slot_info_t& i = st.slot[s];
        if (i.state == CHM_BP_FREE || int(s) == st.self) continue;
        char hb[32] = "-";
        if (i.pid) std::snprintf(hb, sizeof hb, "%u ms", i.heartbeat_age_ms);
        pg.add("%-5u %-5s %-11s %-8d %-10s %s\n", s,
               i.kind == CHM_BP_KIND_RTPU ? "rtpu" : i.kind == CHM_BP_KIND_HOST ? "host" : "-", state_name(i.state),
               int(i.pid), hb, i.name);
        if (is_rtpu(i)) ++rtpus;
    }
    if (rtpus == 0) pg.add("no RTPU running\n");
    // A dead RTPU is the one thing on this page that needs a person: say
    // which it was and how it ended, not just a state word in the table.
    for (std::uint32_t s = 0; s < st.slots; ++s) {
        const chm_bp_slot_info_t& i = st.slot[s];
        if (i.kind != CHM_BP_KIND_RTPU) continue;
        if (i.state == CHM_BP_DEAD)
            pg.add("RTPU %u (%s) died: its process ended without leaving the backplane (killed or crashed); "
                   "the backplane recovered its slot\n", s, i.name);
        else if (i.state == CHM_BP_RECOVERING)
            pg.add("RTPU %u (%s) died: its process ended without leaving the backplane; recovery in progress\n", s,
                   i.name);
    }
    for (std::uint32_t s = 0; s < st.slots; ++s) {
        const chm_bp_slot_info_t& i = st.slot[s];
        if (!is_rtpu(i) || i.state != CHM_BP_RUNNING) continue;
        pg.add("RTPU %u (%s, pid %d):\n", s, i.name, int(i.pid));
        tasks_of(pg, int(s), hist, next);
    }
}

volatile sig_atomic_t g_quit = 0;
void on_quit(int) { g_quit = 1; }

// Wait up to ms for q (stdin a terminal) or a stop signal; true: quit.
bool wait_key(bool tty_in, std::uint64_t ms) {
    const std::uint64_t end = mono_ms() + ms;
    while (!g_quit) {
        const std::uint64_t t = mono_ms();
        if (t >= end) return false;
        pollfd p{tty_in ? 0 : -1, POLLIN, 0};
        if (poll(&p, 1, int(end - t)) > 0 && (p.revents & POLLIN)) {
            char c = 0;
            if (read(0, &c, 1) == 1 && (c == 'q' || c == 'Q')) return true;
        }
    }
    return true;
}

int watch(const Options& o) {
    const bool tty_in = isatty(0), tty_out = isatty(1);
    termios saved{};
    if (tty_in && tcgetattr(0, &saved) == 0) {
        termios raw = saved;
        raw.c_lflag &= tcflag_t(~(ICANON | ECHO));
        raw.c_cc[VMIN] = 0;
        raw.c_cc[VTIME] = 0;
        tcsetattr(0, TCSANOW, &raw);
    }
    struct sigaction sa{};
    sa.sa_handler = on_quit;  // no SA_RESTART: the wait ends at once
    sigemptyset(&sa.sa_mask);
    for (int s : {SIGINT, SIGTERM, SIGHUP}) sigaction(s, &sa, nullptr);
    // Home, draw over the old page line by line (each line cleared to its
    // end), clear what is left below: no flicker, no scrolling.
    std::fputs(tty_out ? "\x1b[?25l\x1b[H\x1b[2J" : "\x1b[H\x1b[2J", stdout);
    History hist;
    for (long frame = 1;; ++frame) {
        Page pg;
        char clock[16];
        const std::time_t t = std::time(nullptr);
        std::tm tm{};
        localtime_r(&t, &tm);
        std::strftime(clock, sizeof clock, "%H:%M:%S", &tm);
        pg.add("chimera status --watch  %s  every %.1f s  (q or Ctrl-C quits)\n", clock, o.interval_s);
        History next;
        render(pg, o, &hist, &next);
        hist = std::move(next);
        std::string out = "\x1b[H";
        for (char c : pg.text) {
            if (c == '\n') out += "\x1b[K";
            out += c;
        }
        out += "\x1b[J";
        std::fwrite(out.data(), 1, out.size(), stdout);
        std::fflush(stdout);
        if (o.count && frame >= o.count) break;
        if (wait_key(tty_in, std::uint64_t(o.interval_s * 1000))) break;
    }
    if (tty_in) tcsetattr(0, TCSANOW, &saved);
    if (tty_out) std::fputs("\x1b[?25h", stdout);
    std::fflush(stdout);
    return 0;
}

}  // namespace

int cmd_status(const Options& o) {
    // Nothing is shown of a table that fails validation.
    struct stat ls{};
    if (lstat(o.backplane.c_str(), &ls) == 0 && !file_fit_to_use(o.backplane)) return 1;
    if (attach(o)) return 1;
    int r = 0;
    if (o.watch) {
        r = watch(o);
    } else {
        Page pg;
        render(pg, o, nullptr, nullptr);
        std::fwrite(pg.text.data(), 1, pg.text.size(), stdout);
        std::fflush(stdout);
    }
    (void)chm_bp_leave();
    return r;
}

}  // namespace chimera_cmd
