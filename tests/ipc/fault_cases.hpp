// The fault-injection cases (docs/backplane.md, "Named points and fault
// injection"): for each named point inside a backplane call, how to bring
// the object to the state the point needs, the call that meets the fault,
// what the call must have done, one call of the next user and what the
// object must then hold. Shared by the in-task matrix (test_ipc_fault.cpp)
// and the kill matrix (test_ipc_fault_kill.cpp), two test programs of one
// translation unit each: everything here is theirs alone (an anonymous
// namespace).
#pragma once

#include <atomic>
#include <cstdarg>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "chimera/err.h"
#include "chimera/rsem.h"
#include "chimera/rtpu.h"
#include "chimera/shm.h"
#include "chimera/svar.h"
#include "ipc/xmail/xmail.hpp"
#include "fault_fixture.hpp"

namespace chm::test {
namespace {

enum Action { kAbort, kFault, kDestroy, kAbortCycle, kActions };
const char* const kActionName[kActions] = {"abort", "fault", "destroy", "abort_cycle"};
// Destroy and abort-cycle wait for the call to return or reach its wait;
// an abort and an exception end the task where it is.
bool deferred(Action a) { return a == kDestroy || a == kAbortCycle; }

// What the child tells the parent (shared memory, set up before the fork).
struct Board {
    std::atomic<int> phase{0};   // child: 1 = quiescent, check the file; parent: 2 = go on
    std::atomic<int> failed{0};
    char failure[600] = {};
    std::uint64_t worst_ns = 0, sum_ns = 0, runs = 0;
    std::uint64_t lat[8192] = {};  // next-user latencies, for the median
};
Board* g_board;

void fail(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
void fail(const char* fmt, ...) {
    if (g_board->failed.exchange(1)) return;
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(g_board->failure, sizeof g_board->failure, fmt, ap);
    va_end(ap);
}

// ------------------------------------------------------------ the cases

chm_msgq_t* g_q;
std::uint32_t g_serial = 1;
std::vector<std::uint32_t> g_expect;  // what the queue must hold, in order

int put(std::uint32_t v) { return chm_msgq_try_send(g_q, 0, 0, &v, sizeof v); }

struct Case {
    const char* point;
    void (*prepare)();        // driver: bring the object to the state the point needs
    void (*victim)();         // the call that meets the fault
    void (*settle)(Action);   // driver: what the victim's call must have done
    int (*next_user)();       // driver: one call that needs the object's lock (0 = ok)
    // driver: nobody waits, the object holds exactly what it must; then
    // it is emptied for the next run. "" or what was wrong.
    std::string (*verify)();
};

std::string verify_queue();
std::string verify_sem();
std::string verify_shm();
std::string verify_vseg();
std::string verify_vq();
std::string verify_vs();
std::string verify_fv();
std::string verify_ring();
// The RTPU whose server the express-mail cases ask: the driver's own in
// the in-task matrix, another RTPU child (2) in the kill matrix.
int g_xmail_target = 1;
void victim_ping() {
    chm_rtpu_info_t info;
    (void)chm_rtpu_ping(g_xmail_target, &info);
}
int next_ping() {
    chm_rtpu_info_t info;
    return chm_rtpu_ping(g_xmail_target, &info);
}
void* g_victim_addr;
std::uint32_t g_refs;  // this process's attaches of "fseg"
bool g_vseg;           // "vseg" must exist
bool g_vq;             // "vq" must exist
bool g_vs;             // "vs" must exist
chm_rsem_t* g_victim_s;
chm_svar_set_t* g_victim_set;  // set by the victim's create once it returned
bool g_fv_made;                // the victim's create completed
chm_msgq_t* g_victim_q;

void fill(std::uint32_t n) {
    for (std::uint32_t i = 0; i < n; ++i) {
        const std::uint32_t v = g_serial++;
        if (put(v) != 0) fail("prefill: try_send failed: %s", chm_bp_last_error());
        g_expect.push_back(v);
    }
}

std::uint32_t g_victim_serial;
void victim_send() {
    g_victim_serial = g_serial++;
    (void)chm_msgq_send(g_q, 0, 0, &g_victim_serial, sizeof g_victim_serial);
}
// Into a global: a destroyed victim ends when the call returns, before
// its caller could store what it received.
std::uint32_t g_victim_buf;
void victim_receive() { (void)chm_msgq_receive(g_q, &g_victim_buf, sizeof g_victim_buf, nullptr); }

chm_rsem_t* g_s;
std::uint32_t g_units;  // what the semaphore's count must be
void victim_p() { (void)chm_rsem_p(g_s); }  // never granted: nobody Vs meanwhile
int next_v() {
    ++g_units;
    return chm_rsem_v(g_s);
}

// rsem.v.granted: one waiter parked in P when the victim's V grants it. A
// task of the driver's RTPU in the in-task matrix, a thread of this host
// process in the kill matrix (g_host_waiter). Its P is bounded (10 s): a
// grant left half done shows as -ETIMEDOUT, the unit lost.
bool g_host_waiter;
std::atomic<int> g_waiter_result{0};
chm_tid_t g_waiter_task = CHM_TID_NONE;
constexpr int kWaiting = 1;  // g_waiter_result while the P has not returned
constexpr std::uint64_t kWaiterTimeoutNs = 10'000'000'000ull;

void waiter_entry(void*) {
    g_waiter_result = chm_rsem_p_timed(g_s, kWaiterTimeoutNs);
}
void pause_ms(unsigned ms) {
    if (g_host_waiter)
        sleep_us(ms * 1000);
    else
        chm_task_pause_until(chm_time_now() + std::uint64_t(ms) * 1'000'000);
}
void start_waiter() {
    g_waiter_result = kWaiting;
    if (g_host_waiter) {
        std::thread([] { g_waiter_result = chm_rsem_p_timed(g_s, kWaiterTimeoutNs); }).detach();
    } else {
        chm_task_attr_t at;
        chm_task_attr_init(&at);
        at.name = "waiter";
        at.priority = 15;  // between the driver and the victim
        at.joinable = 1;
        if (chm_task_spawn(&g_waiter_task, waiter_entry, nullptr, &at) != 0) fail("spawn of the waiter failed");
    }
    for (int i = 0; i < 10000 && chm_rsem_waiting(g_s) != 1; ++i) pause_ms(1);
    if (chm_rsem_waiting(g_s) != 1) fail("the waiter did not come to wait in P within 10 s");
}
// The waiter got the victim's unit: its P returned 0 (within its bound).
std::string verify_granted_sem() {
    for (int i = 0; i < 15000 && g_waiter_result.load() == kWaiting; ++i) pause_ms(1);
    const int r = g_waiter_result.load();
    if (!g_host_waiter && g_waiter_task != CHM_TID_NONE) {
        chm_task_status_t st;
        (void)chm_task_join(g_waiter_task, 20'000'000'000ull, &st);
        g_waiter_task = CHM_TID_NONE;
    }
    if (r != 0)
        return "the waiter granted by the victim's V: its P returned " + std::to_string(r) +
               (r == -ETIMEDOUT ? " (never woken: the unit was lost)" : "");
    return verify_sem();
}

const Case kCases[] = {
    {"msgq.send.copy", [] { fill(1); }, victim_send,
     [](Action a) {
         if (deferred(a)) g_expect.push_back(g_victim_serial);  // the send completed first
     },
     [] {
         const std::uint32_t v = g_serial++;
         g_expect.push_back(v);
         return put(v);
     },
     verify_queue},
    {"msgq.receive.copy", [] { fill(2); }, victim_receive,
     [](Action a) {
         if (!deferred(a)) return;  // the message it was taking stays queued
         // The receive completed before the task ended: the first message
         // is in the victim's buffer, and only there.
         if (g_victim_buf != g_expect.front()) fail("the victim received %u, not %u", g_victim_buf, g_expect.front());
         g_expect.erase(g_expect.begin());
     },
     [] {
         const std::uint32_t v = g_serial++;
         g_expect.push_back(v);
         return put(v);
     },
     verify_queue},
    {"msgq.send.wait", [] { fill(kDepth); }, victim_send, [](Action) {},
     [] {  // full: the next user receives
         std::uint32_t v = 0;
         const int r = chm_msgq_try_receive(g_q, &v, sizeof v, nullptr);
         if (r != int(sizeof v) || v != g_expect.front()) return -1;
         g_expect.erase(g_expect.begin());
         return 0;
     },
     verify_queue},
    {"msgq.receive.wait", [] {}, victim_receive, [](Action) {},
     [] {
         const std::uint32_t v = g_serial++;
         g_expect.push_back(v);
         return put(v);
     },
     verify_queue},
    // Remote semaphore "fs", counting, at 0 before each run: P waits.
    {"rsem.p.locked", [] {}, victim_p, [](Action) {}, next_v, verify_sem},
    {"rsem.p.wait", [] {}, victim_p, [](Action) {}, next_v, verify_sem},
    {"rsem.v.locked", [] {}, [] { (void)chm_rsem_v(g_s); },
     [](Action a) {
         if (deferred(a)) ++g_units;  // the V completed first
     },
     next_v, verify_sem},
    // The victim's V between marking the waiter's record GRANTED and
    // storing its grant word; whoever repairs the lock finishes the grant.
    {"rsem.v.granted", start_waiter, [] { (void)chm_rsem_v(g_s); }, [](Action) {}, next_v, verify_granted_sem},
    // Segment "fseg" (made by the parent): the victim attaches it.
    {"shm.attach.locked", [] {}, [] { (void)chm_shm_attach("fseg", &g_victim_addr, nullptr); },
     [](Action a) {
         if (deferred(a)) ++g_refs;  // the attach completed first: the process holds one more
     },
     [] {
         void* p = nullptr;
         if (chm_shm_attach("fseg", &p, nullptr) != 0) return -1;
         return chm_shm_detach(p);
     },
     verify_shm},
    // A new segment "vseg": the registry entry half written.
    {"registry.create.locked", [] {}, [] { (void)chm_shm_create("vseg", 64, CHM_SHM_COMMON, &g_victim_addr); },
     [](Action a) { g_vseg = deferred(a); },
     [] {
         void* p = nullptr;
         if (chm_shm_create("next", 64, CHM_SHM_COMMON, &p) != 0) return -1;
         if (chm_shm_destroy("next") != 0) return -2;
         return chm_shm_detach(p);
     },
     verify_vseg},
    // A new queue "vq" (create is a call scope too: a destroy or
    // abort-cycle there waits for the queue to be made).
    {"registry.create.locked", [] {}, [] { (void)chm_msgq_create("vq", nullptr, CHM_SHM_COMMON, &g_victim_q); },
     [](Action a) { g_vq = deferred(a); },
     [] {
         chm_msgq_t* q = nullptr;
         if (chm_msgq_create("nextq", nullptr, CHM_SHM_COMMON, &q) != 0) return -1;
         if (chm_msgq_close(q) != 0) return -2;
         return chm_msgq_destroy("nextq");
     },
     verify_vq},
    // A new remote semaphore "vs", the same way.
    {"registry.create.locked", [] {}, [] { (void)chm_rsem_create("vs", CHM_SEM_COUNTING, 1, CHM_SHM_COMMON, &g_victim_s); },
     [](Action a) { g_vs = deferred(a); },
     [] {
         chm_rsem_t* s = nullptr;
         if (chm_rsem_create("nexts", CHM_SEM_COUNTING, 0, CHM_SHM_COMMON, &s) != 0) return -1;
         if (chm_rsem_close(s) != 0) return -2;
         return chm_rsem_destroy("nexts");
     },
     verify_vs},
    // A state-variable set claiming "fv": the entry half claimed.
    {"svar.claim.locked", [] { g_victim_set = nullptr; },
     [] {
         const char* out[] = {"fv"};
         (void)chm_svar_set_create("victim", nullptr, 0, out, 1, &g_victim_set);
     },
     [](Action a) { g_fv_made = deferred(a); },
     [] {  // another variable's claim: the table's lock at once
         const char* out[] = {"fw"};
         chm_svar_set_t* s = nullptr;
         if (chm_svar_set_create("next", nullptr, 0, out, 1, &s) != 0) return -1;
         return chm_svar_set_destroy(s);
     },
     verify_fv},
    // Express mail to this RTPU (its server runs below the victim, so the
    // victim reaches its wait): the record claimed, then in flight.
    {"xmail.claim.locked", [] {}, victim_ping, [](Action) {}, next_ping, verify_ring},
    {"xmail.post.before_write", [] {}, victim_ping, [](Action) {}, next_ping, verify_ring},
    {"xmail.request.posted", [] {}, victim_ping, [](Action) {}, next_ping, verify_ring},
    {"xmail.request.wait", [] {}, victim_ping, [](Action) {}, next_ping, verify_ring},
};

std::string verify_queue() {
    chm_msgq_info_t in{};
    if (chm_msgq_info(g_q, &in) != 0) return "chm_msgq_info failed";
    if (in.receivers_waiting || in.senders_waiting || in.broken)
        return std::to_string(in.receivers_waiting) + " receivers and " + std::to_string(in.senders_waiting) +
               " senders wait, broken " + std::to_string(in.broken);
    std::vector<std::uint32_t> got;
    for (std::uint32_t x; chm_msgq_try_receive(g_q, &x, sizeof x, nullptr) == int(sizeof x);) got.push_back(x);
    if (got != g_expect) {
        std::string gs, es;
        for (auto x : got) gs += " " + std::to_string(x);
        for (auto x : g_expect) es += " " + std::to_string(x);
        return "the queue held [" + gs + " ], expected [" + es + " ]";
    }
    g_expect.clear();
    return "";
}

std::string verify_sem() {
    const int value = chm_rsem_value(g_s), waiting = chm_rsem_waiting(g_s);
    if (value != int(g_units) || waiting != 0)
        return "the semaphore's count is " + std::to_string(value) + " (expected " + std::to_string(g_units) +
               "), " + std::to_string(waiting) + " waiting";
    for (; g_units; --g_units)
        if (chm_rsem_try_p(g_s) != 0) return "a unit the count showed could not be taken";
    if (chm_rsem_try_p(g_s) != -EAGAIN) return "a unit more than the count showed";
    return "";
}

std::uint32_t refs_of(const char* name) {
    bp::Attachment* a = bp::current();
    bp::EntryInfo info{};
    return bp::registry_lookup(*a, name, bp::kKindShm, &info) == 0 ? a->local_refs[info.index] : ~0u;
}

std::string verify_shm() {
    const std::uint32_t refs = refs_of("fseg");
    if (refs != g_refs) return "this process attached fseg " + std::to_string(refs) + " times, not " + std::to_string(g_refs);
    void* p = nullptr;
    if (chm_shm_attach("fseg", &p, nullptr) != 0) return "fseg cannot be attached";
    for (++g_refs; g_refs; --g_refs)  // ours and the victim's
        if (chm_shm_detach(p) != 0) return "an attach it counted cannot be detached";
    return "";
}

std::string verify_vseg() {
    void* p = nullptr;
    const int r = chm_shm_attach("vseg", &p, nullptr);
    if ((r == 0) != g_vseg) return std::string("vseg ") + (r == 0 ? "exists" : "does not exist");
    if (r != 0) return "";
    // The victim's attach (its create) and ours; then the name.
    if (chm_shm_destroy("vseg") != 0 || chm_shm_detach(p) != 0 || chm_shm_detach(p) != 0)
        return "vseg cannot be destroyed";
    return "";
}

std::string verify_vq() {
    chm_msgq_t* q = nullptr;
    const int r = chm_msgq_open("vq", &q);
    if ((r == 0) != g_vq) return std::string("vq ") + (r == 0 ? "exists" : "does not exist");
    if (r != 0) return "";
    const std::uint32_t v = 7;
    std::uint32_t got = 0;
    if (chm_msgq_try_send(q, 0, 0, &v, sizeof v) != 0 || chm_msgq_try_receive(q, &got, sizeof got, nullptr) != int(sizeof got) ||
        got != v)
        return "vq does not carry a message";
    // Ours and the victim's open; then the name.
    if (chm_msgq_close(q) != 0 || chm_msgq_close(q) != 0 || chm_msgq_destroy("vq") != 0) return "vq cannot be destroyed";
    return "";
}

std::string verify_vs() {
    chm_rsem_t* s = nullptr;
    const int r = chm_rsem_open("vs", &s);
    if ((r == 0) != g_vs) return std::string("vs ") + (r == 0 ? "exists" : "does not exist");
    if (r != 0) return "";
    if (chm_rsem_try_p(s) != 0 || chm_rsem_try_p(s) != -EAGAIN || chm_rsem_v(s) != 0)
        return "vs does not hold exactly its one unit";
    // Ours and the victim's open; then the name.
    if (chm_rsem_close(s) != 0 || chm_rsem_close(s) != 0 || chm_rsem_destroy("vs") != 0) return "vs cannot be destroyed";
    return "";
}

std::string verify_fv() {
    // The create returned its set only when it completed; however the
    // victim ended, its claim ended with it, so "fv" has no writer and a
    // new set claims it at once.
    if ((g_victim_set != nullptr) != g_fv_made)
        return std::string("the victim's create ") + (g_victim_set ? "returned a set" : "returned no set");
    if (g_victim_set && chm_svar_set_destroy(g_victim_set) != 0) return "the victim's set cannot be destroyed";
    g_victim_set = nullptr;
    chm_svar_info_t in;
    if (chm_svar_info("fv", &in) != 0) return "fv is gone";
    if (in.has_writer) return std::string("fv is still written by ") + in.writer;
    const char* out[] = {"fv"};
    chm_svar_set_t* s = nullptr;
    if (chm_svar_set_create("check", nullptr, 0, out, 1, &s) != 0) return std::string("fv cannot be claimed: ") + chm_err_last();
    if (chm_svar_set_destroy(s) != 0) return "the check's set cannot be destroyed";
    return "";
}

// The variables the cases use, declared by the test before the RTPUs start.
inline void declare_fault_vars() {
    for (const char* n : {"fv", "fw"}) {
        chm_svar_decl_t d{n, CHM_SVAR_DOUBLE, 1, 1, ""};
        ASSERT_EQ(chm_svar_declare(&d), 0) << chm_err_last();
    }
}

// The target's ring records that are not FREE: "" when none.
std::string ring_held() {
    bp::Attachment* a = bp::current();
    bp::RingHeader* ring = a->ring(std::uint32_t(g_xmail_target));
    std::string held;
    for (std::uint32_t i = 0; i < a->geo().ring_records; ++i) {
        const std::uint32_t st = xmail::record_at(*a, ring, i)->state.load();
        if (xmail::phase_of(st) != xmail::kFree) held += " " + std::to_string(i) + ":phase " + std::to_string(st & 0xF);
    }
    return held;
}

std::string verify_ring() {
    // The server serves what is still posted while we pause (in the RTPU:
    // its priority 5 is below the driver's).
    pause_ms(2);
    const std::string held = ring_held();
    return held.empty() ? "" : "ring records not free:" + held;
}

const Case* g_case;  // the case being run

// CHM_FAULT_POINT=<name> runs one point (to look into a failure).
bool selected(const Case& c) {
    const char* p = std::getenv("CHM_FAULT_POINT");
    return !p || std::strcmp(p, c.point) == 0;
}

}  // namespace
}  // namespace chm::test
