// Helpers of suite `cmdi`: an interpreter whose output is captured, and a
// command that records the words it was given.
#pragma once

#include <gtest/gtest.h>

#include <cstdio>
#include <string>
#include <vector>

#include "chimera/chimera.h"

namespace chm::test {

// An interpreter named "t" writing to a temporary file; out() returns and
// forgets what was written so far.
struct Cmdi {
    chm_cmdi_t* c = nullptr;
    FILE* f = nullptr;
    std::vector<std::vector<std::string>> calls;  // argv of each call of `rec`

    Cmdi() {
        c = chm_cmdi_create("t");
        f = std::tmpfile();
        EXPECT_NE(c, nullptr);
        EXPECT_NE(f, nullptr);
        EXPECT_EQ(chm_cmdi_set_output(c, f), 0);
    }
    ~Cmdi() {
        chm_cmdi_destroy(c);
        if (f) std::fclose(f);
    }
    Cmdi(const Cmdi&) = delete;
    Cmdi& operator=(const Cmdi&) = delete;

    std::string out() {
        std::fflush(f);
        std::rewind(f);
        std::string s;
        char buf[4096];
        std::size_t n;
        while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) s.append(buf, n);
        std::fclose(f);
        f = std::tmpfile();
        (void)chm_cmdi_set_output(c, f);
        return s;
    }
    std::string err() const { return chm_cmdi_last_error(c); }
    int run(const std::string& line) { return chm_cmdi_run_line(c, line.c_str()); }

    // Registers `name` recording its argv in calls and returning the
    // number in argv[1] when it is "fail N".
    void add_recorder(const char* name, const char* help = "records its words") {
        ASSERT_EQ(chm_cmdi_add(c, name, &Cmdi::record, this, "[WORD]...", help), 0) << err();
    }
    static int record(chm_cmdi_t*, int argc, char** argv, void* user) {
        auto* self = static_cast<Cmdi*>(user);
        std::vector<std::string> words(argv, argv + argc);
        EXPECT_EQ(argv[argc], nullptr);
        self->calls.push_back(words);
        if (argc >= 3 && words[1] == "fail") return std::stoi(words[2]);
        return 0;
    }
};

}  // namespace chm::test
