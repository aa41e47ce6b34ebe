// The controller's side of servo task control (chimera/servo.h): requests
// to the RTPUs by express mail, and the two-phase switch at one instant.
#include <algorithm>
#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <vector>

#include "chimera/bp.h"
#include "chimera/kernel.h"
#include "chimera/rtpu.h"
#include "ipc/backplane/stop_point.hpp"
#include "ipc/err/report.hpp"
#include "kernel/err/last.hpp"
#include "ipc/servo/servo.hpp"
#include "ipc/svar/svar.hpp"
#include "ipc/xmail/xmail.hpp"

namespace chm::servo {

namespace svar = chm::ipc::svar;

namespace {

thread_local char t_error[400];
constexpr std::uint64_t kCallTimeoutNs = 15'000'000'000ull;  // entries run up to 5 s each
constexpr std::uint64_t kMinLeadNs = 2'000'000;
constexpr std::uint64_t kMaxCommonPeriodNs = 10'000'000'000ull;

void say(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
void say(const char* fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(t_error, sizeof t_error, fmt, ap);
    va_end(ap);
    kernel::err_last_set(t_error);  // chm_err_last
}

// The exit of every servo call: chm::ipc::leave, then this call's own
// message (t_error: the RTPU's text, the switch's reason) kept for
// chm_err_last whatever the status. ipc::leave keeps a message only for a
// status that raises; for an outcome (-EBUSY: the RTPU is held, naming the
// holder's slot; -ETIME; -EALREADY) it left "call: strerror", and the
// holder or the module the header promises was lost.
int leave(int r, const char* call) {
    r = chm::ipc::leave(r, call);
    if (r < 0 && t_error[0]) {
        kernel::err_last_set(t_error);
        kernel::err_last_failed(call, r, true);  // kept; no longer fresh, as after any exit
    }
    return r;
}

std::uint64_t now_ns() {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return std::uint64_t(ts.tv_sec) * 1'000'000'000ull + std::uint64_t(ts.tv_nsec);
}

// One request: op, body; the reply's fixed part into `reply` (cap bytes).
// On failure t_error says "RTPU n: why" with the RTPU's own text.
int call(int rtpu, Op op, const void* body, std::size_t len, void* reply = nullptr, std::uint32_t cap = 0,
         std::uint32_t* got = nullptr) {
    std::vector<char> req(8 + len);
    const std::uint32_t o = op;
    std::memcpy(req.data(), &o, 4);
    if (len) std::memcpy(req.data() + 8, body, len);
    char rep[1024];
    std::uint32_t n = 0;
    const int r = xmail::call(rtpu, xmail::kServo, req.data(), std::uint32_t(req.size()), rep, sizeof rep, &n,
                              kCallTimeoutNs);
    if (r < 0) {
        if (n > 0 && n <= sizeof rep && std::memchr(rep, 0, n)) say("RTPU %d: %s", rtpu, rep);
        else say("RTPU %d: %s", rtpu, chm_rtpu_last_error()[0] ? chm_rtpu_last_error() : std::strerror(-r));
        return r;
    }
    if (reply) std::memcpy(reply, rep, std::min(cap, n));
    if (got) *got = n;
    return r;
}

Ref ref_of(chm_servo_module_t m) { return Ref{m.index, m.gen}; }

bool same(chm_servo_module_t a, chm_servo_module_t b) {
    return a.rtpu == b.rtpu && a.index == b.index && a.gen == b.gen;
}

int status_of(chm_servo_module_t m, StatusReply* s) {
    const Ref r = ref_of(m);
    return call(m.rtpu, kStatus, &r, sizeof r, s, sizeof *s);
}

std::uint64_t gcd(std::uint64_t a, std::uint64_t b) {
    while (b) a %= b, std::swap(a, b);
    return a;
}

struct Part {  // one RTPU's share of a switch
    int rtpu;
    std::vector<SwitchItem> items;
};

int send_switch(Op op, const Part& p, std::uint64_t at, const std::vector<std::string>& names,
                svar::DecisionRef sw = {}, std::uint32_t outcome = 0) {
    std::vector<char> body(sizeof(SwitchReq) + p.items.size() * sizeof(SwitchItem) + names.size() * kNameLen);
    SwitchReq q{at, std::uint32_t(p.items.size()), std::uint32_t(names.size()), sw.cell, sw.seq, outcome, 0};
    std::memcpy(body.data(), &q, sizeof q);
    std::memcpy(body.data() + sizeof q, p.items.data(), p.items.size() * sizeof(SwitchItem));
    char* at_name = body.data() + sizeof q + p.items.size() * sizeof(SwitchItem);
    for (const std::string& s : names) {
        std::memset(at_name, 0, kNameLen);
        std::memcpy(at_name, s.c_str(), std::min<std::size_t>(s.size(), kNameLen - 1));
        at_name += kNameLen;
    }
    return call(p.rtpu, op, body.data(), body.size());
}

int switch_impl(const chm_servo_module_t* off, size_t n_off, const chm_servo_module_t* on, size_t n_on, unsigned flags,
                std::uint64_t* at_ns) {
    t_error[0] = 0;
    if ((n_off && !off) || (n_on && !on) || n_off + n_on == 0)
        return say("chm_servo_switch: no modules, or NULL list"), -EINVAL;
    std::vector<chm_servo_module_t> all(off, off + n_off);
    all.insert(all.end(), on, on + n_on);
    for (std::size_t i = 0; i < all.size(); ++i)
        for (std::size_t j = i + 1; j < all.size(); ++j)
            if (same(all[i], all[j]))
                return say("chm_servo_switch: module %d:%d listed twice", all[i].rtpu, all[i].index), -EINVAL;
    // Names, periods and outputs of everything involved.
    std::vector<StatusReply> st(all.size());
    std::uint64_t common = 1, pending = 0;
    for (std::size_t i = 0; i < all.size(); ++i) {
        if (int r = status_of(all[i], &st[i])) return r;
        pending = std::max(pending, st[i].pending_at);
        const std::uint64_t p = st[i].period_ns;
        common = common / gcd(common, p) * p;
        if (common > kMaxCommonPeriodNs)
            return say("chm_servo_switch: the periods have no common boundary within 10 s"), -EINVAL;
    }
    std::vector<std::vector<std::string>> outs(all.size());
    for (std::size_t i = 0; i < all.size(); ++i) {
        char rep[1024];
        std::uint32_t got = 0;
        const Ref r = ref_of(all[i]);
        if (int e = call(all[i].rtpu, kOutputs, &r, sizeof r, rep, sizeof rep, &got)) return e;
        OutputsReply h;
        std::memcpy(&h, rep, sizeof h);
        for (std::uint32_t k = 0; k < h.count && sizeof h + (k + 1) * kNameLen <= got; ++k)
            outs[i].emplace_back(std::string(rep + sizeof h + k * kNameLen, strnlen(rep + sizeof h + k * kNameLen, kNameLen)));
        for (std::size_t j = n_off; j < i && i >= n_off; ++j)
            for (const std::string& v : outs[i])
                if (std::find(outs[j].begin(), outs[j].end(), v) != outs[j].end())
                    return say("chm_servo_switch: state variable %s would be written by both %s and %s", v.c_str(),
                               st[j].name, st[i].name),
                           -EBUSY;
    }
    std::vector<std::string> off_names, on_names;
    for (std::size_t i = 0; i < all.size(); ++i) (i < n_off ? off_names : on_names).emplace_back(st[i].name);
    std::vector<Part> parts;
    for (std::size_t i = 0; i < all.size(); ++i) {
        auto it = std::find_if(parts.begin(), parts.end(), [&](const Part& p) { return p.rtpu == all[i].rtpu; });
        if (it == parts.end()) it = parts.insert(parts.end(), Part{all[i].rtpu, {}});
        if (it->items.size() == kSwitchMax)
            return say("chm_servo_switch: more than %u modules on RTPU %d", kSwitchMax, all[i].rtpu), -EINVAL;
        // A module going off whose output a module going on takes is
        // handed over: it stops when that happens, not on its own.
        std::uint32_t kind = i >= n_off ? 1u : 0u;
        for (std::size_t j = n_off; j < all.size() && kind == 0; ++j)
            for (const std::string& v : outs[i])
                if (std::find(outs[j].begin(), outs[j].end(), v) != outs[j].end()) kind = 2;
        it->items.push_back(SwitchItem{ref_of(all[i]), kind, 0});
    }
    // Commits that switch modules on go first: they decide every hand-over
    // (an RTPU too late for T refuses, and its variables keep their old
    // writer); the parts that only switch off follow.
    std::stable_sort(parts.begin(), parts.end(), [](const Part& a, const Part& b) {
        auto ons = [](const Part& p) {
            return std::count_if(p.items.begin(), p.items.end(), [](const SwitchItem& x) { return x.on == 1; });
        };
        return ons(a) > ons(b);
    });
    // Phase 1: every RTPU says whether it can (nothing changes yet).
    const std::uint64_t t0 = now_ns();
    bool left_out = false;
    for (std::size_t k = 0; k < parts.size();) {
        const int r = send_switch(kPrepare, parts[k], 0, off_names);
        if (r == 0) {
            ++k;
            continue;
        }
        if (!(flags & CHM_SERVO_BEST_EFFORT)) return r;
        left_out = true;
        parts.erase(parts.begin() + std::ptrdiff_t(k));
    }
    if (parts.empty()) return -EAGAIN;
    // Where a controller may die inside a switch (the chaos soak kills its
    // controller at each, CHIMERA_FAULT_AT=<name>:kill): prepared, nothing
    // armed; one part committed, the cell open; the cell committed, no
    // part told.
    CHM_STOP_POINT("servo.switch.prepared");
    // Phase 2 at T: the first common boundary far enough ahead for every
    // commit, and the decision, to land before it. The decision cell makes
    // it all or nothing: every part reads it at T and acts only if it was
    // committed by then; a part that finds it still open aborts it.
    svar::Table table;
    svar::DecisionRef sw;
    if (int r = svar::open_table(false, &table)) return say("chm_servo_switch: %s", chm_bp_last_error()), r;
    if (svar::decision_open(table, table.a->token, &sw) != 0)
        return say("chm_servo_switch: all %u decision cells of the state-variable table are taken (switches whose "
                   "controllers died before finishing): retry later",
                   svar::kDecisionCells),
               -EBUSY;
    const std::uint64_t prep = now_ns() - t0;
    const std::uint64_t lead = std::max(kMinLeadNs, 4 * prep);
    // Never before an instant an earlier switch armed one of these modules
    // for: a switch asked for later never takes effect first.
    const std::uint64_t now = now_ns();  // CLOCK_MONOTONIC: the RTPU kernels' clock
    const std::uint64_t at = (std::max(now + lead, pending) + common - 1) / common * common;
    // Tell every part the outcome; the cell is given back only when all
    // of them know it (a part that did not answer may still read it).
    auto resolve_all = [&](std::uint32_t outcome) {
        std::size_t told = 0;
        for (const Part& p : parts) told += send_switch(kResolve, p, at, on_names, sw, outcome) == 0;
        if (told == parts.size()) svar::decision_free(table, sw);
    };
    for (std::size_t k = 0; k < parts.size(); ++k) {
        const int r = send_switch(kCommit, parts[k], at, off_names, sw);
        if (r == 0) {
            CHM_STOP_POINT("servo.switch.committed_one");
            continue;
        }
        char why[sizeof t_error];
        std::snprintf(why, sizeof why, "%s", t_error);
        // Nothing acted yet: no part acts before T, and none will on an
        // aborted cell. The parts armed are undone now.
        const std::uint32_t outcome = svar::decision_settle(table, sw);
        resolve_all(svar::kCellAborted);
        say("chm_servo_switch: %s (nothing switched%s)", why,
            outcome == svar::kCellAborted ? "" : "; the decision cell was not the switch's");
        return r;
    }
    if (!svar::decision_commit(table, sw)) {
        resolve_all(svar::kCellAborted);
        say("chm_servo_switch: the switch instant passed before every RTPU had its commit (nothing switched)");
        return -ETIME;
    }
    CHM_STOP_POINT("servo.switch.decided");
    resolve_all(svar::kCellCommitted);
    if (at_ns) *at_ns = at;
    return left_out ? -EAGAIN : 0;
}

}  // namespace

}  // namespace chm::servo

using namespace chm::servo;

extern "C" {

void chm_servo_spawn_init(chm_servo_spawn_t* s) {
    if (!s) return;
    std::memset(s, 0, sizeof *s);
    s->rtpu = -1;
}

int chm_servo_take(uint32_t rtpus) {
    t_error[0] = 0;
    if (!rtpus) return leave((say("chm_servo_take: no RTPU in the mask"), -EINVAL), "chm_servo_take");
    for (int n = 0; n < 32; ++n) {
        if (!(rtpus >> n & 1)) continue;
        if (int r = call(n, kTake, nullptr, 0)) {
            for (int k = 0; k < n; ++k)
                if (rtpus >> k & 1) call(k, kRelease, nullptr, 0);
            return leave(r, "chm_servo_take");
        }
    }
    return 0;
}

int chm_servo_release(uint32_t rtpus) {
    t_error[0] = 0;
    int first = 0;
    for (int n = 0; n < 32; ++n)
        if (rtpus >> n & 1)
            if (int r = call(n, kRelease, nullptr, 0); r && !first) first = r;
    return leave(first, "chm_servo_release");
}

int chm_servo_spawn(const chm_servo_spawn_t* s, chm_servo_module_t* out) {
    t_error[0] = 0;
    auto fail = [](int r, const char* fmt, const char* what) {
        say(fmt, what);
        return leave(r, "chm_servo_spawn");
    };
    if (!s || !out || !s->path || !s->name || !s->name[0] || (s->n_params && (!s->param_names || !s->param_values)))
        return fail(-EINVAL, "chm_servo_spawn: NULL request, path, name or parameter list%s", "");
    if (std::strlen(s->name) > CHM_SERVO_NAME_MAX) return fail(-ENAMETOOLONG, "chm_servo_spawn: name %s too long", s->name);
    if (std::strlen(s->path) > CHM_SERVO_PATH_MAX) return fail(-ENAMETOOLONG, "chm_servo_spawn: path %s too long", s->path);
    if (s->n_params > CHM_MODULE_PARAMS_MAX) return fail(-EINVAL, "chm_servo_spawn %s: more than 16 parameters", s->name);
    SpawnReq q{};
    q.period_ns = s->period_ns;
    q.deadline_ns = s->deadline_ns;
    q.wcet_ns = s->wcet_ns;
    q.critical = s->critical;
    q.priority = s->priority;
    q.miss_policy = s->miss_policy;
    q.n_params = std::uint32_t(s->n_params);
    std::snprintf(q.name, sizeof q.name, "%s", s->name);
    q.path_len = std::uint32_t(std::strlen(s->path) + 1);
    std::vector<char> body(sizeof q + q.n_params * sizeof(ParamOverride) + q.path_len);
    std::memcpy(body.data(), &q, sizeof q);
    for (std::uint32_t i = 0; i < q.n_params; ++i) {
        ParamOverride p{};
        if (!s->param_names[i] || std::strlen(s->param_names[i]) >= kNameLen)
            return fail(-EINVAL, "chm_servo_spawn %s: a parameter name is NULL or too long", s->name);
        std::snprintf(p.name, sizeof p.name, "%s", s->param_names[i]);
        p.value = s->param_values[i];
        std::memcpy(body.data() + sizeof q + i * sizeof p, &p, sizeof p);
    }
    std::memcpy(body.data() + sizeof q + q.n_params * sizeof(ParamOverride), s->path, q.path_len);
    Ref ref{};
    const int r = call(s->rtpu, kSpawn, body.data(), body.size(), &ref, sizeof ref);
    if (r) return leave(r, "chm_servo_spawn");
    *out = chm_servo_module_t{s->rtpu, ref.index, ref.gen};
    return 0;
}

int chm_servo_find(int rtpu, const char* name, chm_servo_module_t* out) {
    t_error[0] = 0;
    if (!name || !out || std::strlen(name) >= kNameLen)
        return leave((say("chm_servo_find: NULL or too long a name"), -EINVAL), "chm_servo_find");
    FindReq q{};
    std::snprintf(q.name, sizeof q.name, "%s", name);
    chm_bp_status_t st;
    const int first = rtpu >= 0 ? rtpu : 1;
    const int last = rtpu >= 0 ? rtpu : (chm_bp_status(&st) == 0 ? int(st.slots) - 1 : 31);
    for (int n = first; n <= last; ++n) {
        Ref ref{};
        if (call(n, kFind, &q, sizeof q, &ref, sizeof ref) == 0) {
            *out = chm_servo_module_t{n, ref.index, ref.gen};
            return 0;
        }
    }
    say("chm_servo_find: no module %s", name);
    return -ENOENT;
}

int chm_servo_switch(const chm_servo_module_t* off, size_t n_off, const chm_servo_module_t* on, size_t n_on,
                     unsigned flags, uint64_t* at_ns) {
    return leave(switch_impl(off, n_off, on, n_on, flags, at_ns), "chm_servo_switch");
}

int chm_servo_on(chm_servo_module_t m) { return chm_servo_switch(nullptr, 0, &m, 1, 0, nullptr); }
int chm_servo_off(chm_servo_module_t m) { return chm_servo_switch(&m, 1, nullptr, 0, 0, nullptr); }

int chm_servo_control(chm_servo_module_t m, const char* param, double value) {
    t_error[0] = 0;
    if (!param || std::strlen(param) >= kNameLen)
        return leave((say("chm_servo_control: NULL or too long a parameter name"), -EINVAL), "chm_servo_control");
    ControlReq q{};
    q.ref = ref_of(m);
    std::snprintf(q.name, sizeof q.name, "%s", param);
    q.value = value;
    return leave(call(m.rtpu, kControl, &q, sizeof q), "chm_servo_control");
}

int chm_servo_clear(chm_servo_module_t m) {
    t_error[0] = 0;
    const Ref r = ref_of(m);
    return leave(call(m.rtpu, kClear, &r, sizeof r), "chm_servo_clear");
}

int chm_servo_kill(chm_servo_module_t m) {
    t_error[0] = 0;
    const Ref r = ref_of(m);
    return leave(call(m.rtpu, kKill, &r, sizeof r), "chm_servo_kill");
}

int chm_servo_status(chm_servo_module_t m, chm_servo_status_t* out) {
    t_error[0] = 0;
    if (!out) return leave((say("chm_servo_status: NULL out"), -EINVAL), "chm_servo_status");
    StatusReply s;
    const int r = status_of(m, &s);
    std::memset(out, 0, sizeof *out);
    if (r == -EHOSTDOWN) {
        out->state = CHM_SERVO_DEAD;
        std::snprintf(out->last_error, sizeof out->last_error, "%s", t_error);
        return 0;
    }
    if (r) return leave(r, "chm_servo_status");
    std::memcpy(out->name, s.name, sizeof out->name);
    out->name[CHM_SERVO_NAME_MAX] = 0;
    std::memcpy(out->module, s.module, sizeof out->module);
    out->module[CHM_SERVO_NAME_MAX] = 0;
    out->state = s.state;
    out->period_ns = s.period_ns;
    out->cycles = s.cycles;
    out->misses = s.misses;
    out->worst_cycle_ns = s.worst_ns;
    out->switched_at_ns = s.switched_at;
    std::memcpy(out->last_error, s.last_error, sizeof out->last_error);
    out->last_error[sizeof out->last_error - 1] = 0;
    return 0;
}

const char* chm_servo_last_error(void) { return t_error; }

}  // extern "C"
