// Suite `cmdi`: the command interpreter's lines (words, quotes, escapes,
// comments, errors with columns), commands (registration, abbreviation,
// ambiguity, failures), suggestions and help (chimera/cmdi.h).
#include <cerrno>
#include <cstring>
#include <fstream>

#include "../private_dir.hpp"
#include "cmdi_test.hpp"

namespace {

using chm::test::Cmdi;
using Words = std::vector<std::string>;

// The words `line` gives the recorder "w", without argv[0].
Words words_of(Cmdi& t, const std::string& line) {
    t.calls.clear();
    EXPECT_EQ(t.run("w " + line), 0) << line << ": " << t.err();
    if (t.calls.size() != 1) return {"<not called>"};
    return Words(t.calls[0].begin() + 1, t.calls[0].end());
}

TEST(CmdiLine, WordsQuotesEscapesComments) {
    Cmdi t;
    t.add_recorder("w");
    EXPECT_EQ(words_of(t, "a  b\tc"), (Words{"a", "b", "c"}));
    EXPECT_EQ(words_of(t, "'a b' \"c d\""), (Words{"a b", "c d"}));
    EXPECT_EQ(words_of(t, "a\"b c\"d 'e'f"), (Words{"ab cd", "ef"}));
    EXPECT_EQ(words_of(t, "\"\" ''"), (Words{"", ""}));
    EXPECT_EQ(words_of(t, "a\\ b \\'c \\\\"), (Words{"a b", "'c", "\\"}));
    EXPECT_EQ(words_of(t, "\"q\\\"uote\\\\ \\n\\t\""), (Words{"q\"uote\\ \n\t"}));
    EXPECT_EQ(words_of(t, "'no \\n escapes \"here\"'"), (Words{"no \\n escapes \"here\""}));
    EXPECT_EQ(words_of(t, "a # the rest 'is not parsed"), (Words{"a"}));
    EXPECT_EQ(words_of(t, "a#b '#' \\#c"), (Words{"a#b", "#", "#c"}));
    EXPECT_EQ(words_of(t, "x\r"), (Words{"x"}));
}

TEST(CmdiLine, BlankAndCommentLinesDoNothing) {
    Cmdi t;
    t.add_recorder("w");
    for (const char* line : {"", "   ", "\t", "# comment", "   # w"}) EXPECT_EQ(t.run(line), 0) << line;
    EXPECT_TRUE(t.calls.empty());
}

TEST(CmdiLine, ErrorsNameTheColumn) {
    Cmdi t;
    t.add_recorder("w");
    EXPECT_EQ(t.run("w abc \"def"), -EINVAL);
    EXPECT_EQ(t.err(), "unterminated double quote opened at column 7");
    EXPECT_EQ(t.run("w 'x"), -EINVAL);
    EXPECT_EQ(t.err(), "unterminated single quote opened at column 3");
    EXPECT_EQ(t.run("w \"ok\" \"a\\qb\""), -EINVAL);
    EXPECT_EQ(t.err(), "unknown escape '\\q' in double quotes at column 10");
    EXPECT_EQ(t.run("w ab\\"), -EINVAL);
    EXPECT_EQ(t.err(), "backslash at the end of the line (column 5)");
    EXPECT_EQ(t.run("w \"x\\"), -EINVAL);
    EXPECT_EQ(t.err(), "unterminated double quote opened at column 3");
    EXPECT_EQ(t.run("w \"\\\x01\""), -EINVAL);
    EXPECT_EQ(t.err(), "unknown escape '\\\\x01' in double quotes at column 4");
    EXPECT_TRUE(t.calls.empty());  // a line with an error runs nothing
    EXPECT_EQ(chm_cmdi_run_line(t.c, nullptr), -EINVAL);
    EXPECT_EQ(chm_cmdi_run_line(nullptr, "w"), -EINVAL);
}

TEST(CmdiCommands, AddChecksNames) {
    Cmdi t;
    auto fn = &Cmdi::record;
    EXPECT_EQ(chm_cmdi_add(t.c, "status", fn, &t, nullptr, nullptr), 0);
    EXPECT_EQ(chm_cmdi_add(t.c, "status", fn, &t, nullptr, nullptr), -EEXIST);
    EXPECT_EQ(t.err(), "chm_cmdi_add: a command 'status' exists already");
    EXPECT_EQ(chm_cmdi_add(t.c, "help", fn, &t, nullptr, nullptr), -EEXIST);
    EXPECT_EQ(chm_cmdi_add(t.c, "", fn, &t, nullptr, nullptr), -EINVAL);
    EXPECT_EQ(t.err(), "chm_cmdi_add: command name is empty");
    EXPECT_EQ(chm_cmdi_add(t.c, "set speed", fn, &t, nullptr, nullptr), -EINVAL);
    EXPECT_EQ(t.err(),
              "chm_cmdi_add: command name 'set speed' has the character ' ' at byte 4 "
              "(allowed: letters, digits, '_', '-', '.')");
    EXPECT_EQ(chm_cmdi_add(t.c, "-v", fn, &t, nullptr, nullptr), -EINVAL);
    EXPECT_EQ(t.err(), "chm_cmdi_add: command name '-v' starts with '-'");
    EXPECT_EQ(chm_cmdi_add(t.c, std::string(64, 'a').c_str(), fn, &t, nullptr, nullptr), -EINVAL);
    EXPECT_EQ(chm_cmdi_add(t.c, std::string(63, 'a').c_str(), fn, &t, nullptr, nullptr), 0);
    EXPECT_EQ(chm_cmdi_add(t.c, "x", nullptr, &t, nullptr, nullptr), -EINVAL);
    EXPECT_EQ(t.err(), "chm_cmdi_add: command 'x' has a NULL function");
    EXPECT_EQ(chm_cmdi_add(nullptr, "x", fn, &t, nullptr, nullptr), -EINVAL);
    EXPECT_EQ(chm_cmdi_create("has space"), nullptr);
    EXPECT_EQ(errno, EINVAL);
    EXPECT_EQ(chm_cmdi_create(nullptr), nullptr);
}

TEST(CmdiCommands, ArgvAndStatus) {
    Cmdi t;
    t.add_recorder("rec");
    EXPECT_EQ(t.run("rec a b"), 0);
    ASSERT_EQ(t.calls.size(), 1u);
    EXPECT_EQ(t.calls[0], (Words{"rec", "a", "b"}));
    EXPECT_EQ(t.run("rec fail 7"), 7);
    EXPECT_EQ(t.err(), "rec failed with status 7");
    EXPECT_EQ(t.run("rec fail -5"), -EIO);
    EXPECT_EQ(t.err(), std::string("rec failed: ") + std::strerror(EIO) + " (status -5)");
    auto says = [](chm_cmdi_t* c, int, char** argv, void*) {
        return chm_cmdi_error(c, -ERANGE, "speed %s is out of range", argv[1]);
    };
    ASSERT_EQ(chm_cmdi_add(t.c, "speed", says, nullptr, "RPM", "set the speed"), 0);
    EXPECT_EQ(t.run("speed 9000"), -ERANGE);
    EXPECT_EQ(t.err(), "speed 9000 is out of range");
    // A command's output goes to the output stream.
    auto prints = [](chm_cmdi_t* c, int argc, char**, void*) { return chm_cmdi_printf(c, "%d words\n", argc) > 0 ? 0 : 1; };
    ASSERT_EQ(chm_cmdi_add(t.c, "count", prints, nullptr, nullptr, nullptr), 0);
    t.out();
    EXPECT_EQ(t.run("count 1 2 3"), 0);
    EXPECT_EQ(t.out(), "4 words\n");
}

TEST(CmdiCommands, UniquePrefixRunsAmbiguousListsCandidates) {
    Cmdi t;
    t.add_recorder("status");
    t.add_recorder("step");
    t.add_recorder("stop");
    t.add_recorder("st");  // an exact name wins over the longer ones it begins
    EXPECT_EQ(t.run("sta x"), 0);
    EXPECT_EQ(t.run("ste"), 0);
    EXPECT_EQ(t.run("st"), 0);
    ASSERT_EQ(t.calls.size(), 3u);
    EXPECT_EQ(t.calls[0], (Words{"status", "x"}));  // argv[0] is the full name
    EXPECT_EQ(t.calls[1], (Words{"step"}));
    EXPECT_EQ(t.calls[2], (Words{"st"}));
    EXPECT_EQ(t.run("s"), -ENOTUNIQ);
    EXPECT_EQ(t.err(), "ambiguous command 's': source, st, status, step, stop");
    EXPECT_EQ(t.run("sto"), 0);
    EXPECT_EQ(t.calls.back(), (Words{"stop"}));
    EXPECT_EQ(t.run("h"), -ENOTUNIQ);  // help, history
    EXPECT_EQ(t.err(), "ambiguous command 'h': help, history");
}

TEST(CmdiCommands, UnknownCommandSuggestsTheClosest) {
    Cmdi t;
    t.add_recorder("status");
    t.add_recorder("start");
    t.add_recorder("reset");
    EXPECT_EQ(t.run("stauts"), -ENOENT);
    EXPECT_EQ(t.err(), "unknown command 'stauts'; did you mean 'status'?");
    EXPECT_EQ(t.run("rest"), -ENOENT);
    EXPECT_EQ(t.err(), "unknown command 'rest'; did you mean 'reset'?");
    EXPECT_EQ(t.run("frobnicate"), -ENOENT);
    EXPECT_EQ(t.err(), "unknown command 'frobnicate'; 'help' lists the commands");
    EXPECT_EQ(t.run("'a\x01'"), -ENOENT);
    EXPECT_EQ(t.err(), "unknown command 'a\\x01'; 'help' lists the commands");
    EXPECT_TRUE(t.calls.empty());
}

TEST(CmdiSuggest, DistanceBoundsAndTies) {
    Cmdi t;
    for (const char* n : {"status", "stats", "go", "calibrate", "load", "lead"}) t.add_recorder(n);
    char buf[64];
    auto suggest = [&](const char* w) {
        const int rc = chm_cmdi_suggest(t.c, w, buf, sizeof buf);
        return rc == 0 ? std::string(buf) : "<" + std::to_string(rc) + ">";
    };
    EXPECT_EQ(suggest("stauts"), "status");     // one transposition (and 1 from stats: longer)
    EXPECT_EQ(suggest("STATUS"), "status");     // case ignored
    EXPECT_EQ(suggest("stat"), "stats");        // 1 from stats, 2 from status
    EXPECT_EQ(suggest("calbirate"), "calibrate");
    EXPECT_EQ(suggest("clibrte"), "calibrate");  // 2 deletions, 7 bytes: bound 2
    EXPECT_EQ(suggest("clbrte"), "<-2>");        // 3 away, 6 bytes: bound 2
    EXPECT_EQ(suggest("laod"), "load");          // 1 from load (transposition), 2 from lead
    EXPECT_EQ(suggest("xo"), "go");
    EXPECT_EQ(suggest("x"), "<-2>");  // one byte: every one-letter change is too far
    EXPECT_EQ(suggest("lxad"), "lead");  // lead and load both 1 away: alphabetically first
    EXPECT_EQ(chm_cmdi_suggest(t.c, "stauts", buf, 6), -ENAMETOOLONG);
    EXPECT_EQ(chm_cmdi_suggest(t.c, "stauts", buf, 7), 0);
    EXPECT_EQ(chm_cmdi_suggest(t.c, nullptr, buf, 7), -EINVAL);
    EXPECT_EQ(chm_cmdi_suggest(t.c, "x", buf, 0), -EINVAL);
}

TEST(CmdiHelp, ListAndDescribe) {
    Cmdi t;
    t.add_recorder("status", "show the state of every RTPU\nOne line per RTPU: its name, state and load.");
    ASSERT_EQ(chm_cmdi_add(t.c, "go", &Cmdi::record, &t, nullptr, nullptr), 0);
    EXPECT_EQ(t.run("help"), 0);
    EXPECT_EQ(t.out(),
              "Commands (any unique prefix of a name runs it; 'help CMD' describes one):\n"
              "  exit              leave the command line (the same as quit)\n"
              "  go\n"
              "  help [CMD]        list the commands, or describe one\n"
              "  history [COUNT]   list the lines entered (the last COUNT of them)\n"
              "  quit              leave the command line (the same as exit)\n"
              "  source FILE       run the commands in FILE, one a line\n"
              "  status [WORD]...  show the state of every RTPU\n");
    EXPECT_EQ(t.run("help stat"), 0);  // a prefix works here too
    EXPECT_EQ(t.out(),
              "usage: status [WORD]...\n"
              "show the state of every RTPU\n"
              "One line per RTPU: its name, state and load.\n");
    EXPECT_EQ(t.run("help go"), 0);
    EXPECT_EQ(t.out(), "usage: go\n");
    EXPECT_EQ(t.run("help stauts"), -ENOENT);
    EXPECT_EQ(t.err(), "no help for 'stauts'; did you mean 'status'?");
    EXPECT_EQ(t.run("help s"), -ENOENT);
    EXPECT_EQ(t.err(), "no help for 's': ambiguous, it begins source, status");
    EXPECT_EQ(t.run("help a b"), -EINVAL);
    EXPECT_EQ(t.err(), "usage: help [CMD]");
    EXPECT_EQ(t.out(), "");
}

TEST(CmdiHelp, ShellLineListedOnlyWhenAllowed) {
    Cmdi t;
    ASSERT_EQ(t.run("help"), 0);
    EXPECT_EQ(t.out().find("!CMD"), std::string::npos);
    ASSERT_EQ(chm_cmdi_allow_shell(t.c, 1), 0);
    ASSERT_EQ(t.run("help"), 0);
    EXPECT_NE(t.out().find("  !CMD             run CMD with /bin/sh\n"), std::string::npos);
}

class CmdiHelpFiles : public ::testing::Test {
protected:
    void SetUp() override {
        dir = chm::test::make_private_dir("chm-cmdi-help-");
        ASSERT_FALSE(dir.empty());
    }
    void TearDown() override { chm::test::remove_private_dir(dir); }
    void write(const std::string& name, const std::string& text) { std::ofstream(dir + "/" + name) << text; }
    std::string dir;
};

TEST_F(CmdiHelpFiles, DirectoryOfTopicFiles) {
    Cmdi t;
    t.add_recorder("status", "show the state");
    write("status.help", "Columns: NAME STATE LOAD.\n");
    write("scripts.help", "A script is a file of commands.\n");
    ASSERT_EQ(chm_cmdi_help_path(t.c, dir.c_str()), 0) << t.err();
    EXPECT_EQ(t.run("help status"), 0);
    EXPECT_EQ(t.out(), "usage: status [WORD]...\nshow the state\n\nColumns: NAME STATE LOAD.\n");
    EXPECT_EQ(t.run("help scripts"), 0);  // a topic that is no command
    EXPECT_EQ(t.out(), "A script is a file of commands.\n");
    EXPECT_EQ(t.run("help ../status"), -ENOENT);  // topics are names, not paths
    EXPECT_EQ(t.run("help history"), 0);           // no file: the registered help only
    EXPECT_EQ(t.out(), "usage: history [COUNT]\nlist the lines entered (the last COUNT of them)\n");
    EXPECT_EQ(chm_cmdi_help_path(t.c, (dir + "/none").c_str()), -ENOENT);
    EXPECT_EQ(t.err(), "help path '" + dir + "/none': No such file or directory");
}

TEST_F(CmdiHelpFiles, SectionsOfOneFile) {
    Cmdi t;
    t.add_recorder("status", "show the state");
    write("all.help",
          "[intro]\nChimera's console.\n\n"
          "[status]\r\nColumns: NAME STATE LOAD.\nSee also: top.\n\n"
          "[top]\nNot this.\n");
    ASSERT_EQ(chm_cmdi_help_path(t.c, (dir + "/all.help").c_str()), 0) << t.err();
    EXPECT_EQ(t.run("help status"), 0);
    EXPECT_EQ(t.out(), "usage: status [WORD]...\nshow the state\n\nColumns: NAME STATE LOAD.\nSee also: top.\n");
    EXPECT_EQ(t.run("help intro"), 0);
    EXPECT_EQ(t.out(), "Chimera's console.\n");
    EXPECT_EQ(t.run("help nothere"), -ENOENT);
}

}  // namespace
