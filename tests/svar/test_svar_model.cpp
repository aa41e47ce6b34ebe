// Differential test of the state-variable table against a plain model: a
// map of variables (shape, value, writer, writes) and a list of sets with
// their local copies. Thousands of random declarations, set creations,
// copy-ins, copy-outs, gets and destroys run through the public API and
// through the model; every status, every local copy, every global value,
// writer and write count must agree after each step.
#include <gtest/gtest.h>

#include <cstring>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "chimera/chimera.h"
#include "../ipc/ipc_fixture.hpp"

using namespace chm::test;

namespace {

struct ModelVar {
    chm_svar_type_t type;
    uint32_t rows, cols;
    std::string unit;
    std::vector<unsigned char> value;
    int writer = -1;  // index into sets, -1 none
    uint32_t writes = 0;
};

struct ModelSet {
    chm_svar_set_t* handle = nullptr;
    std::string owner;
    std::vector<std::string> ins, outs;
    std::map<std::string, std::vector<unsigned char>> local;
    bool live = false;
};

uint32_t elem(chm_svar_type_t t) { return t == CHM_SVAR_DOUBLE ? 8 : t == CHM_SVAR_BOOL ? 1 : 4; }

class SvarModel : public IpcTest {
protected:
    std::mt19937 rng;
    std::map<std::string, ModelVar> vars;
    std::vector<ModelSet> sets;
    const char* names[10] = {"q", "qd", "tau", "J", "force", "grip", "mode", "x", "y", "ref"};

    int pick(int n) { return std::uniform_int_distribution<int>(0, n - 1)(rng); }

    void declare_op() {
        const std::string name = names[pick(10)];
        // Each name has a "true" shape; now and then a conflicting one.
        const std::size_t h = std::hash<std::string>{}(name);
        chm_svar_type_t type = chm_svar_type_t(1 + h % 5);
        uint32_t rows = 1 + h % 7, cols = 1 + (h / 7) % 3;
        std::string unit = (h & 1) ? "m" : "";
        if (pick(5) == 0) rows += 1 + pick(3);
        if (pick(8) == 0) unit = "kg";
        chm_svar_decl_t d{name.c_str(), type, rows, cols, unit.c_str()};
        int want = 0;
        auto it = vars.find(name);
        if (it == vars.end()) {
            ModelVar v{type, rows, cols, unit, std::vector<unsigned char>(rows * cols * elem(type), 0)};
            vars.emplace(name, v);
        } else if (it->second.type != type || it->second.rows != rows || it->second.cols != cols ||
                   it->second.unit != unit) {
            want = -EEXIST;
        }
        ASSERT_EQ(chm_svar_declare(&d), want) << name << ": " << chm_bp_last_error();
    }

    void create_op() {
        std::vector<std::string> ins, outs;
        for (int k = pick(4); k > 0; --k) ins.push_back(names[pick(10)]);
        for (int k = pick(3); k > 0; --k) outs.push_back(names[pick(10)]);
        std::vector<const char*> in_c, out_c;
        for (auto& s : ins) in_c.push_back(s.c_str());
        for (auto& s : outs) out_c.push_back(s.c_str());
        // The model's verdict, in the API's order: duplicates, unknown names, writers.
        int want = 0;
        std::vector<std::string> all = ins;
        all.insert(all.end(), outs.begin(), outs.end());
        for (std::size_t i = 0; i < all.size() && !want; ++i)
            for (std::size_t j = i + 1; j < all.size(); ++j)
                if (all[i] == all[j]) want = -EINVAL;
        if (!want && vars.empty()) want = -ENOENT;  // no table yet
        for (std::size_t i = 0; i < all.size() && !want; ++i)
            if (!vars.count(all[i])) want = -ENOENT;
        for (std::size_t i = 0; i < outs.size() && !want; ++i)
            if (vars[outs[i]].writer >= 0) want = -EBUSY;
        ModelSet s;
        s.owner = "set" + std::to_string(sets.size());
        const int r = chm_svar_set_create(s.owner.c_str(), in_c.data(), in_c.size(), out_c.data(), out_c.size(),
                                          &s.handle);
        ASSERT_EQ(r, want) << chm_bp_last_error();
        if (r) return;
        s.ins = ins;
        s.outs = outs;
        s.live = true;
        for (auto& n : all) s.local[n] = vars[n].value;
        for (auto& n : outs) vars[n].writer = int(sets.size());
        sets.push_back(s);
    }

    ModelSet* live_set() {
        std::vector<ModelSet*> live;
        for (auto& s : sets)
            if (s.live) live.push_back(&s);
        return live.empty() ? nullptr : live[pick(int(live.size()))];
    }

    // Scribble on every local copy (inputs too: copy-in must restore them).
    void scribble(ModelSet& s) {
        for (auto& [name, bytes] : s.local) {
            auto* p = static_cast<unsigned char*>(chm_svar_set_local(s.handle, name.c_str()));
            ASSERT_NE(p, nullptr) << name;
            for (std::size_t i = 0; i < bytes.size(); ++i) p[i] = bytes[i] = (unsigned char)rng();
        }
    }

    void write_op() {
        ModelSet* s = live_set();
        if (!s) return;
        scribble(*s);
        ASSERT_EQ(chm_svar_set_write(s->handle), 0);
        for (auto& n : s->outs) {
            vars[n].value = s->local[n];
            ++vars[n].writes;
        }
    }

    void read_op() {
        ModelSet* s = live_set();
        if (!s) return;
        if (pick(2)) scribble(*s);
        ASSERT_EQ(chm_svar_set_read(s->handle), 0);
        for (auto& n : s->ins) s->local[n] = vars[n].value;
    }

    void destroy_op() {
        ModelSet* s = live_set();
        if (!s) return;
        ASSERT_EQ(chm_svar_set_destroy(s->handle), 0);
        s->live = false;
        for (auto& n : s->outs) vars[n].writer = -1;
    }

    void compare() {
        for (auto& [name, v] : vars) {
            chm_svar_info_t i;
            ASSERT_EQ(chm_svar_info(name.c_str(), &i), 0) << name;
            EXPECT_EQ(i.writes, v.writes) << name;
            ASSERT_EQ(i.has_writer, v.writer >= 0) << name;
            if (v.writer >= 0) {
                EXPECT_EQ(sets[v.writer].owner, i.writer) << name;
            }
            std::vector<unsigned char> got(v.value.size() + 1);
            ASSERT_EQ(chm_svar_get(name.c_str(), got.data(), got.size()), 0) << name;
            got.pop_back();
            ASSERT_EQ(got, v.value) << name;
        }
        for (auto& s : sets) {
            if (!s.live) continue;
            for (auto& [name, bytes] : s.local)
                ASSERT_EQ(std::memcmp(chm_svar_set_local(s.handle, name.c_str()), bytes.data(), bytes.size()), 0)
                    << s.owner << " " << name;
        }
        ASSERT_EQ(chm_svar_count(), int(vars.size()));
    }
};

TEST_F(SvarModel, RandomOperationsMatchTheModel) {
    const char* e = std::getenv("CHM_SVAR_MODEL_ROUNDS");
    const int rounds = e && *e ? std::atoi(e) : 20;
    for (int round = 0; round < rounds; ++round) {
        SCOPED_TRACE("round " + std::to_string(round));
        (void)chm_bp_leave();
        ::unlink(path_.c_str());
        create();
        ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
        rng.seed(1000 + round);
        vars.clear();
        sets.clear();
        for (int step = 0; step < 400; ++step) {
            switch (pick(10)) {
            case 0:
            case 1: declare_op(); break;
            case 2:
            case 3: create_op(); break;
            case 4:
            case 5:
            case 6: write_op(); break;
            case 7:
            case 8: read_op(); break;
            default: destroy_op(); break;
            }
            if (HasFatalFailure()) return;
            compare();
            if (HasFatalFailure()) return;
        }
        for (auto& s : sets)
            if (s.live) (void)chm_svar_set_destroy(s.handle);
    }
}

}  // namespace
