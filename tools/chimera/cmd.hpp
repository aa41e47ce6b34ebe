// The `chimera` command's pieces: start (main.cpp), status, stop and rm
// (ops.cpp), and what they share.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace chimera_cmd {

// Every subcommand's options; each uses what concerns it.
struct Options {
    std::string backplane;      // resolved path
    double timeout_s = -1;      // < 0: the subcommand's default
    bool force = false;
};

// Print "chimera: <message>" on stderr.
void say(const char* fmt, ...) __attribute__((format(printf, 1, 2)));

// Monotonic milliseconds.
std::uint64_t mono_ms();
void nap_ms(unsigned ms);

// Log file of RTPU n of the system on `backplane`.
std::string log_path(const std::string& backplane, int n);

// An existing backplane file we may attach (chm_bp_check_file) and whose
// table and objects are sound (chm_bp_validate); says why not.
bool file_fit_to_use(const std::string& path);
int cmd_status(const Options& o);
int cmd_stop(const Options& o);
int cmd_rm(const Options& o);
// `chimera svar SUBCOMMAND ARGS...` (svar.cpp); `args` starts with the subcommand.
int cmd_svar(const Options& o, const std::vector<const char*>& args);
// `chimera svar plan CONFIG` (plan.cpp): needs no backplane.
int cmd_svar_plan(const char* config);

// Stop every RTPU of the attached backplane: SIGTERM, wait up to
// timeout_s, SIGKILL the rest. Prints one line per RTPU unless quiet.
// Returns the number that had to be killed; *refused_out (when given):
// slots whose pid failed the identity check, reported and not signalled.
int stop_attached(double timeout_s, bool quiet, int* refused_out = nullptr);

}  // namespace chimera_cmd
