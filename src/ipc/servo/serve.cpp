// The RTPU's side of a servo request: decode a copy of it (anything a
// sender wrote), check every count and length against the bytes received,
// check that the sender controls this RTPU, and call the host.
#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>

#include "ipc/servo/host.hpp"

namespace chm::servo {

namespace {

// A fixed-size name field of a request: terminated within its bytes.
bool name_ok(const char* s) { return std::memchr(s, 0, kNameLen) != nullptr && s[0]; }

struct Reply {
    char* rep;
    std::uint32_t room;
    std::uint32_t* n;
    // Append the refusal's text after whatever fixed reply is there.
    int fail(int status, const char* why) {
        const std::uint32_t at = *n;
        if (at < room) {
            const std::uint32_t k = std::uint32_t(std::min<std::size_t>(std::strlen(why), room - at - 1));
            std::memcpy(rep + at, why, k);
            rep[at + k] = 0;
            *n = at + k + 1;
        }
        return status;
    }
    template <class T>
    void put(const T& v) {
        if (sizeof v <= room) std::memcpy(rep, &v, sizeof v), *n = sizeof v;
    }
};

int do_spawn(const char* req, std::uint32_t len, Reply& out, char* why, std::size_t wn) {
    SpawnReq q;
    if (len < sizeof q) return -EINVAL;
    std::memcpy(&q, req, sizeof q);
    const std::uint64_t need = sizeof q + std::uint64_t(q.n_params) * sizeof(ParamOverride) + q.path_len;
    if (q.n_params > CHM_MODULE_PARAMS_MAX || q.path_len == 0 || need > len || !name_ok(q.name))
        return std::snprintf(why, wn, "malformed spawn request"), -EINVAL;
    ParamOverride params[CHM_MODULE_PARAMS_MAX];
    std::memcpy(params, req + sizeof q, q.n_params * sizeof(ParamOverride));
    for (std::uint32_t i = 0; i < q.n_params; ++i)
        if (!name_ok(params[i].name)) return std::snprintf(why, wn, "malformed parameter name"), -EINVAL;
    char path[CHM_SERVO_PATH_MAX + 1];
    if (q.path_len > sizeof path) return std::snprintf(why, wn, "path longer than %d", CHM_SERVO_PATH_MAX), -ENAMETOOLONG;
    std::memcpy(path, req + sizeof q + q.n_params * sizeof(ParamOverride), q.path_len);
    if (path[q.path_len - 1] != 0) return std::snprintf(why, wn, "path not terminated"), -EINVAL;
    if (q.period_ns == 0 || q.deadline_ns > q.period_ns || q.wcet_ns > (q.deadline_ns ? q.deadline_ns : q.period_ns))
        return std::snprintf(why, wn, "timing: period %llu, deadline %llu, wcet %llu ns",
                             (unsigned long long)q.period_ns, (unsigned long long)q.deadline_ns,
                             (unsigned long long)q.wcet_ns),
               -EINVAL;
    // Every release is a timer expiry: on a host of this kind one costs
    // ~50 us, so a shorter period is beyond what the RTPU can run.
    if (q.period_ns < kMinPeriodNs)
        return std::snprintf(why, wn, "period %llu ns: this RTPU releases cycles at most every %llu ns (%.0f Hz)",
                             (unsigned long long)q.period_ns, (unsigned long long)kMinPeriodNs, 1e9 / kMinPeriodNs),
               -EINVAL;
    Ref ref{};
    const int r = spawn(q, params, path, &ref, why, wn);
    if (r == 0) out.put(ref);
    return r;
}

// A switch request: this RTPU's items resolved, the names checked.
int decode_switch(const char* req, std::uint32_t len, SwitchReq* q, Item* items, const char** names, char* why,
                  std::size_t wn) {
    if (len < sizeof *q) return -EINVAL;
    std::memcpy(q, req, sizeof *q);
    if (q->n > kSwitchMax || q->n_displace > kDisplaceMax ||
        sizeof *q + std::uint64_t(q->n) * sizeof(SwitchItem) + std::uint64_t(q->n_displace) * kNameLen > len)
        return std::snprintf(why, wn, "malformed switch request"), -EINVAL;
    const char* p = req + sizeof *q;
    for (std::uint32_t i = 0; i < q->n; ++i, p += sizeof(SwitchItem)) {
        SwitchItem it;
        std::memcpy(&it, p, sizeof it);
        items[i].m = lookup(it.ref);
        items[i].on = it.on == 1;
        items[i].handed = it.on == 2;
        if (!items[i].m)
            return std::snprintf(why, wn, "no module %d generation %u here (killed?)", it.ref.index, it.ref.gen),
                   -ESTALE;
    }
    for (std::uint32_t i = 0; i < q->n_displace; ++i, p += kNameLen) {
        if (!name_ok(p)) return std::snprintf(why, wn, "malformed name"), -EINVAL;
        names[i] = p;
    }
    return 0;
}

}  // namespace

int serve(const char* req, std::uint32_t len, char* rep, std::uint32_t room, std::uint32_t* n, std::uint32_t from) {
    *n = 0;
    Reply out{rep, room, n};
    char why[300] = "";
    if (len < 8) return out.fail(-EINVAL, "short servo request");
    std::uint32_t op;
    std::memcpy(&op, req, 4);
    req += 8;
    len -= 8;
    const bool changes = op != kFind && op != kStatus && op != kOutputs && op != kTake && op != kRelease;
    if (changes && !controls(from)) return out.fail(-EPERM, "this RTPU is not controlled by the caller (chm_servo_take)");
    int r = 0;
    switch (op) {
    case kTake: r = take(from, why, sizeof why); break;
    case kRelease: r = release(from); break;
    case kSpawn: r = do_spawn(req, len, out, why, sizeof why); break;
    case kFind: {
        if (len < kNameLen || !name_ok(req)) return out.fail(-EINVAL, "malformed name");
        chm_module* m = find_name(req);
        if (!m) return out.fail(-ENOENT, "no such module here");
        out.put(Ref{m->index, m->gen});
        return 0;
    }
    case kPrepare:
    case kCommit:
    case kResolve: {
        SwitchReq q;
        Item items[kSwitchMax];
        const char* names[kDisplaceMax];
        if ((r = decode_switch(req, len, &q, items, names, why, sizeof why)) != 0) break;
        const svar::DecisionRef sw{q.cell, q.seq};
        if (op != kPrepare && q.cell >= svar::kDecisionCells) {
            r = -EINVAL;
            std::snprintf(why, sizeof why, "malformed switch request: decision cell %u", q.cell);
        } else if (op == kPrepare) {
            r = prepare(items, q.n, names, q.n_displace, why, sizeof why);
        } else if (op == kCommit) {
            r = commit(q.at_ns, sw, items, q.n, names, q.n_displace, why, sizeof why);
        } else {
            r = resolve(sw, q.outcome, items, q.n, why, sizeof why);
        }
        break;
    }
    case kControl: {
        ControlReq q;
        if (len < sizeof q) return out.fail(-EINVAL, "malformed control request");
        std::memcpy(&q, req, sizeof q);
        if (!name_ok(q.name)) return out.fail(-EINVAL, "malformed parameter name");
        chm_module* m = lookup(q.ref);
        if (!m) return out.fail(-ESTALE, "no such module (killed?)");
        r = control(m, q.name, q.value, why, sizeof why);
        break;
    }
    case kClear:
    case kKill:
    case kStatus:
    case kOutputs: {
        Ref ref;
        if (len < sizeof ref) return out.fail(-EINVAL, "malformed request");
        std::memcpy(&ref, req, sizeof ref);
        chm_module* m = lookup(ref);
        if (!m) return out.fail(-ESTALE, "no such module (killed?)");
        if (op == kClear) r = clear(m, why, sizeof why);
        else if (op == kKill) r = kill(m, why, sizeof why);
        else if (op == kStatus) {
            StatusReply s;
            status(m, &s);
            if (sizeof s > room) return -EMSGSIZE;
            out.put(s);
        } else {
            OutputsReply h{std::uint32_t(m->desc->n_outputs), 0};
            if (sizeof h + h.count * kNameLen > room) return -EMSGSIZE;
            std::memcpy(rep, &h, sizeof h);
            for (std::uint32_t i = 0; i < h.count; ++i) {
                char name[kNameLen] = {};
                std::snprintf(name, sizeof name, "%s", m->desc->outputs[i]);
                std::memcpy(rep + sizeof h + i * kNameLen, name, kNameLen);
            }
            *n = sizeof h + h.count * kNameLen;
        }
        break;
    }
    default: return out.fail(-EPROTO, "unknown servo request");
    }
    if (r < 0) return out.fail(r, why[0] ? why : "refused");
    if (why[0] && op == kKill) out.fail(0, why);  // removed, but kill failed: say so
    return r;
}

}  // namespace chm::servo
