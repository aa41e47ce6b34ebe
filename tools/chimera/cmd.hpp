// The `chimera` command's pieces: argument parsing and usage (main.cpp),
// start (start.cpp), status and its live view (status.cpp), stop and rm
// (ops.cpp), load / kill / stop --rtpu (tasks.cpp), objects (objects.cpp),
// svar (svar.cpp, plan.cpp), and what they share.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "chimera/task.h"
#include "lib/nap.hpp"

namespace chimera_cmd {

// Every subcommand's options; each uses what concerns it.
struct Options {
    std::string backplane;      // resolved path
    double timeout_s = -1;      // < 0: the subcommand's default
    bool force = false;
    int rtpu = -1;              // stop --rtpu N: that one only
    bool watch = false;         // status --watch
    double interval_s = 1.0;    // status --watch --interval S
    long count = 0;             // status --watch --count N (0: until q or Ctrl-C)
};

// What `chimera start` was asked for (main.cpp parses, start.cpp runs it).
struct StartPlan {
    int rtpus = 2;
    std::string policy;
    std::vector<std::string> rtpu_options;  // given to every chimera-rtpu
    bool pin = false;
    bool log_terminal = false;
    int group = -1;  // gid for a new backplane
    std::vector<std::vector<std::string>> programs;  // per RTPU: chimera-rtpu's program arguments
    bool host_server = true;   // slot 0: chimera-rtpu --host-server host_root
    std::string host_root;     // absolute; default the current directory
    bool allow_shell = false;  // --host-allow-shell
};

// Print "chimera: <message>" on stderr.
void say(const char* fmt, ...) __attribute__((format(printf, 1, 2)));

// Monotonic milliseconds.
std::uint64_t mono_ms();
using chm::nap_ms;  // lib/nap.hpp

// Log file of RTPU n of the system on `backplane`.
std::string log_path(const std::string& backplane, int n);

// An existing backplane file we may attach (chm_bp_check_file) and whose
// table and objects are sound (chm_bp_validate); says why not.
bool file_fit_to_use(const std::string& path);
// Attach to o.backplane as a host for one command: 0, or an error said.
int attach(const Options& o);
// The live members of the backplane at `path` (read-only map; state not
// FREE or DEAD and the process alive with the start time the table
// names), "RTPU 1 (pid 123), host 9 (pid 456)", RTPUs only if asked; ""
// when none. *error (may be NULL) receives why the file could not be read.
std::string live_members(const std::string& path, bool rtpus_only, std::string* error = nullptr);

int cmd_start(const Options& o, const StartPlan& p);
int cmd_status(const Options& o);
int cmd_stop(const Options& o);
int cmd_rm(const Options& o);
// `chimera load RTPU PROGRAM [ARG...]`, `chimera kill RTPU TASK`, `chimera
// stop --rtpu N` (tasks.cpp).
int cmd_load(const Options& o, const std::vector<const char*>& args);
int cmd_kill(const Options& o, const std::vector<const char*>& args);
int cmd_stop_one(const Options& o);
// A task state as status and the console print it (status.cpp).
const char* task_state(chm_task_state s);
// `chimera console [--rtpus LIST] [--script FILE]` (console.cpp).
int cmd_console(const Options& o, const std::vector<const char*>& args);
// `chimera objects` (objects.cpp).
int cmd_objects(const Options& o);
// `chimera svar SUBCOMMAND ARGS...` (svar.cpp); `args` starts with the subcommand.
int cmd_svar(const Options& o, const std::vector<const char*>& args);
// The `svar list` table of the attached backplane (objects shares it).
int svar_list();
// `chimera svar plan CONFIG` (plan.cpp): needs no backplane.
int cmd_svar_plan(const char* config);

// RTPU `word` (its number, or its name in the table) of the attached
// backplane, running: its slot, or -1 with the reason said.
int resolve_rtpu(const char* word);

// Stop the RTPUs of the attached backplane (only slot `only` when >= 0):
// SIGTERM, wait up to timeout_s, SIGKILL the rest. Prints one line per
// RTPU unless quiet. Returns the number that had to be killed;
// *refused_out (when given): slots whose pid failed the identity check,
// reported and not signalled.
int stop_attached(double timeout_s, bool quiet, int* refused_out = nullptr, int only = -1);

}  // namespace chimera_cmd
