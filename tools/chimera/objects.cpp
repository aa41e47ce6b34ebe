// chimera objects: every named object of a backplane, from its registry
// (chm_bp_objects, which checks each entry before passing it on), with
// what its kind can tell: a queue's fill and waiters, a semaphore's value
// and waiters, a segment's size, the state variables (svar list). The
// details come through each subsystem's open call, which validates the
// object first; one that fails says so on its line.
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include <unistd.h>

#include "chimera/bp.h"
#include "chimera/msgq.h"
#include "chimera/rsem.h"
#include "cmd.hpp"

namespace chimera_cmd {

namespace {

const char* kind_name(std::uint32_t k) {
    switch (k) {
    case CHM_BP_OBJ_SHM: return "shm";
    case CHM_BP_OBJ_RSEM: return "semaphore";
    case CHM_BP_OBJ_MSGQ: return "queue";
    case CHM_BP_OBJ_SVARS: return "svar-table";
    }
    return "?";
}

const char* order_name(chm_msgq_order o) {
    return o == CHM_MSGQ_FIFO ? "fifo" : o == CHM_MSGQ_LIFO ? "lifo" : o == CHM_MSGQ_PRIORITY ? "priority" : "?";
}

std::string plural(unsigned n, const char* one, const char* many) {
    return std::to_string(n) + " " + (n == 1 ? one : many);
}

std::string queue_details(const char* name) {
    chm_msgq_t* q = nullptr;
    if (chm_msgq_open(name, &q)) return std::string("(cannot open: ") + chm_bp_last_error() + ")";
    chm_msgq_info_t i;
    std::string s;
    if (chm_msgq_info(q, &i) == 0) {
        char b[320];
        std::snprintf(b, sizeof b, "fill %u/%u messages, %u bytes%s; waiting: %s, %s; sent %u, received %u; %s, "
                      "messages up to %u bytes%s%s",
                      i.count, i.attr.max_count, i.bytes, i.attr.max_bytes ? (" of " + std::to_string(i.attr.max_bytes)).c_str() : "",
                      plural(i.receivers_waiting, "receiver", "receivers").c_str(),
                      plural(i.senders_waiting, "sender", "senders").c_str(), i.sent, i.received,
                      order_name(i.attr.order), i.attr.max_msg, i.broken ? "; BROKEN" : "",
                      i.destroyed ? "; destroyed" : "");
        s = b;
    } else {
        s = std::string("(no details: ") + chm_bp_last_error() + ")";
    }
    (void)chm_msgq_close(q);
    return s;
}

std::string semaphore_details(const char* name) {
    chm_rsem_t* sem = nullptr;
    if (chm_rsem_open(name, &sem)) return std::string("(cannot open: ") + chm_bp_last_error() + ")";
    const int value = chm_rsem_value(sem), waiting = chm_rsem_waiting(sem);
    (void)chm_rsem_close(sem);
    if (value < 0 || waiting < 0) return "(no details: not a semaphore handle)";
    return "value " + std::to_string(value) + ", " + plural(unsigned(waiting), "waiter", "waiters");
}

}  // namespace

int cmd_objects(const Options& o) {
    if (access(o.backplane.c_str(), F_OK) == 0 && !file_fit_to_use(o.backplane)) return 1;
    if (attach(o)) return 1;
    const int self = chm_bp_self();
    int total = 0;
    std::vector<chm_bp_object_t> objs(CHM_BP_MAX_SLOTS);
    int n = chm_bp_objects(objs.data(), int(objs.size()), &total);
    if (n >= 0 && total > n) {  // a larger registry
        objs.resize(std::size_t(total) + 16);
        n = chm_bp_objects(objs.data(), int(objs.size()), &total);
    }
    if (n < 0) {
        say("objects: %s", chm_bp_last_error());
        (void)chm_bp_leave();
        return 1;
    }
    if (n == 0) std::printf("no named objects on %s\n", o.backplane.c_str());
    else std::printf("%-24s %-10s %-8s %9s %-8s %-12s %s\n", "NAME", "KIND", "WHERE", "BYTES", "CREATOR", "OPEN BY",
                     "DETAILS");
    bool svars = false;
    for (int k = 0; k < n; ++k) {
        const chm_bp_object_t& b = objs[std::size_t(k)];
        // Who has it open, as the registry said before we opened anything
        // (this command itself left out).
        std::string open_by;
        for (int s = 0; s < 32; ++s)
            if ((b.attached >> s & 1u) && s != self) open_by += (open_by.empty() ? "" : ",") + std::to_string(s);
        const std::string where = b.where < 0 ? "common" : "rtpu" + std::to_string(b.where);
        std::string details;
        switch (b.kind) {
        case CHM_BP_OBJ_MSGQ: details = queue_details(b.name); break;
        case CHM_BP_OBJ_RSEM: details = semaphore_details(b.name); break;
        case CHM_BP_OBJ_SHM: details = "shared memory segment"; break;
        case CHM_BP_OBJ_SVARS: details = "the state-variable table (below)"; svars = true; break;
        default: details = "kind " + std::to_string(b.kind) + ", unknown to this version of chimera"; break;
        }
        std::printf("%-24s %-10s %-8s %9u %-8s %-12s %s\n", b.name, kind_name(b.kind), where.c_str(), b.size,
                    b.creator < 0 ? "-" : ("slot " + std::to_string(b.creator)).c_str(),
                    open_by.empty() ? "-" : open_by.c_str(), details.c_str());
    }
    int r = 0;
    if (svars) {
        std::printf("\nstate variables:\n");
        std::fflush(stdout);
        r = svar_list();
    }
    std::fflush(stdout);
    (void)chm_bp_leave();
    return r;
}

}  // namespace chimera_cmd
