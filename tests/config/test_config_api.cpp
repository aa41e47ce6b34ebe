// Suite `config`: every getter of chimera/config.h, with its defaults,
// ranges and types, arrays, arrays of tables, key listing and unknown keys,
// and the exact file:line:column text of each error.
#include <gtest/gtest.h>

#include <cerrno>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <string>
#include <thread>

#include "chimera/chimera.h"

#ifndef CHM_CONFIG_EXAMPLE
#error CHM_CONFIG_EXAMPLE names tests/config/system.toml
#endif

namespace {

// A document parsed from text, closed at the end of the test.
struct Doc {
    chm_config_t* cfg = nullptr;
    explicit Doc(const std::string& text, const char* name = "t.toml") {
        EXPECT_EQ(chm_config_parse(text.data(), text.size(), name, &cfg), 0) << chm_config_last_error();
    }
    ~Doc() { chm_config_close(cfg); }
};

std::string err() { return chm_config_last_error(); }

const std::string kBasic =
    "title = \"rig\"\n"          // 1
    "count = 7\n"                // 2
    "ratio = 0.25\n"             // 3
    "on = true\n"                // 4
    "[arm]\n"                    // 5
    "gain = 2.5\n"               // 6
    "joints = 6\n"               // 7
    "mode = \"torque\"\n"        // 8
    "limits = [1, 2.5, -3]\n"    // 9
    "\"max.speed\" = 4\n";       // 10

TEST(ConfigParse, SyntaxErrorNamesLineAndColumn) {
    const std::string text = "a = 1\nb = [1, 2\nc = 3\n";
    chm_config_t* cfg = reinterpret_cast<chm_config_t*>(0x1);
    EXPECT_EQ(chm_config_parse(text.data(), text.size(), "bad.toml", &cfg), -EBADMSG);
    EXPECT_EQ(cfg, reinterpret_cast<chm_config_t*>(0x1));  // untouched on error
    EXPECT_EQ(err().rfind("bad.toml:3:1: ", 0), 0u) << err();
}

TEST(ConfigParse, DuplicateKeyAndBadValue) {
    chm_config_t* cfg = nullptr;
    const std::string dup = "x = 1\nx = 2\n";
    EXPECT_EQ(chm_config_parse(dup.data(), dup.size(), "d.toml", &cfg), -EBADMSG);
    EXPECT_EQ(err().rfind("d.toml:2:5: ", 0), 0u) << err();
    const std::string bad = "ok = 1\nv = 12abc\n";
    EXPECT_EQ(chm_config_parse(bad.data(), bad.size(), nullptr, &cfg), -EBADMSG);
    EXPECT_EQ(err().rfind("<string>:2:", 0), 0u) << err();
}

// toml++ 3.3.0 asserted (or, under NDEBUG, assumed) that a table header
// starts with a key character: src/lib/config/toml.hpp.
TEST(ConfigParse, TableHeaderWithoutKeyIsASyntaxError) {
    for (const std::string text : {"[{module]\n", "[[{module]]\n", "a = 1\n[ =]\n"}) {
        chm_config_t* cfg = nullptr;
        EXPECT_EQ(chm_config_parse(text.data(), text.size(), "h.toml", &cfg), -EBADMSG) << text;
        EXPECT_NE(err().find("expected bare key starting character or string delimiter"), std::string::npos)
            << err();
    }
    chm_config_t* cfg = nullptr;
    const std::string text = "[{module]\n";
    EXPECT_EQ(chm_config_parse(text.data(), text.size(), "h.toml", &cfg), -EBADMSG);
    EXPECT_EQ(err(), "h.toml:1:2: Error while parsing key: expected bare key starting character or "
                     "string delimiter, saw '{'");
}

TEST(ConfigParse, LengthNotNulTerminated) {
    // Only len bytes are read: the "= 2" beyond them never parses.
    const char text[] = "k = 1x = 2";
    chm_config_t* cfg = nullptr;
    ASSERT_EQ(chm_config_parse(text, 5, "n.toml", &cfg), 0) << err();
    int64_t v = 0;
    EXPECT_EQ(chm_config_require_int64(cfg, "k", 0, 10, &v), 0);
    EXPECT_EQ(v, 1);
    EXPECT_EQ(chm_config_type(cfg, "x"), CHM_CONFIG_NONE);
    chm_config_close(cfg);
}

TEST(ConfigParse, InvalidUtf8AndNulRefused) {
    chm_config_t* cfg = nullptr;
    const std::string bad_utf8 = "s = \"\xff\"\n";
    EXPECT_EQ(chm_config_parse(bad_utf8.data(), bad_utf8.size(), "u.toml", &cfg), -EBADMSG);
    EXPECT_EQ(err().rfind("u.toml:1:", 0), 0u) << err();
    const std::string nul("a = 1\n\0b = 2\n", 13);
    EXPECT_EQ(chm_config_parse(nul.data(), nul.size(), "z.toml", &cfg), -EBADMSG);
    EXPECT_EQ(err().rfind("z.toml:2:1: ", 0), 0u) << err();
}

TEST(ConfigParse, NullArguments) {
    chm_config_t* cfg = nullptr;
    EXPECT_EQ(chm_config_parse(nullptr, 0, "x", &cfg), -EINVAL);
    EXPECT_EQ(chm_config_parse("", 0, "x", nullptr), -EINVAL);
    EXPECT_EQ(chm_config_open(nullptr, &cfg), -EINVAL);
    chm_config_close(nullptr);  // allowed
    EXPECT_STREQ(chm_config_name(nullptr), "");
}

TEST(ConfigOpen, FileNamesItselfInErrors) {
    const std::string path = ::testing::TempDir() + "chm_config_open.toml";
    { std::ofstream(path) << "a = 1\nb = \"x\"\n"; }
    chm_config_t* cfg = nullptr;
    ASSERT_EQ(chm_config_open(path.c_str(), &cfg), 0) << err();
    EXPECT_EQ(std::string(chm_config_name(cfg)), path);
    int64_t v = 0;
    EXPECT_EQ(chm_config_get_int64(cfg, "b", 0, 0, 9, &v), -EBADMSG);
    EXPECT_EQ(err(), path + ":2:5: b: expected an integer in [0, 9], got string \"x\"");
    chm_config_close(cfg);
    std::remove(path.c_str());
}

TEST(ConfigOpen, MissingFileDirectoryAndSyntax) {
    chm_config_t* cfg = nullptr;
    EXPECT_EQ(chm_config_open("/nonexistent/chm.toml", &cfg), -ENOENT);
    EXPECT_NE(err().find("/nonexistent/chm.toml"), std::string::npos) << err();
    EXPECT_EQ(chm_config_open(::testing::TempDir().c_str(), &cfg), -EISDIR);
    const std::string path = ::testing::TempDir() + "chm_config_bad.toml";
    { std::ofstream(path) << "[a]\nb = \n"; }
    EXPECT_EQ(chm_config_open(path.c_str(), &cfg), -EBADMSG);
    EXPECT_EQ(err().rfind(path + ":2:", 0), 0u) << err();
    std::remove(path.c_str());
}

TEST(ConfigOpen, LargerThan16MiBRefused) {
    const std::string path = ::testing::TempDir() + "chm_config_big.toml";
    {
        std::ofstream f(path);
        const std::string line(1023, '#');
        for (int i = 0; i < 16 * 1024 + 1; ++i) f << line << '\n';
    }
    chm_config_t* cfg = nullptr;
    EXPECT_EQ(chm_config_open(path.c_str(), &cfg), -EFBIG);
    EXPECT_EQ(err(), path + ": larger than 16 MiB");
    std::remove(path.c_str());
}

TEST(ConfigErrors, MessageIsPerThread) {
    Doc d(kBasic);
    int64_t v = 0;
    ASSERT_EQ(chm_config_require_int64(d.cfg, "nope", 0, 1, &v), -ENOENT);
    const std::string mine = err();
    std::string theirs;
    std::thread([&] {
        EXPECT_EQ(chm_config_require_int64(d.cfg, "count", 0, 1, &v), -EBADMSG);
        theirs = err();
    }).join();
    EXPECT_EQ(err(), mine);
    EXPECT_EQ(theirs, "t.toml:2:9: count: expected an integer in [0, 1], got integer 7");
}

TEST(ConfigGet, IntegersWithDefaultsAndRanges) {
    Doc d(kBasic);
    int64_t v = -1;
    EXPECT_EQ(chm_config_get_int64(d.cfg, "count", 3, 0, 10, &v), 0);
    EXPECT_EQ(v, 7);
    EXPECT_EQ(chm_config_get_int64(d.cfg, "arm.joints", 1, 1, 7, &v), 0);
    EXPECT_EQ(v, 6);
    EXPECT_EQ(chm_config_get_int64(d.cfg, "absent", 3, 0, 10, &v), 0);
    EXPECT_EQ(v, 3);
    EXPECT_EQ(chm_config_get_int64(d.cfg, "arm.absent", -4, -5, 10, &v), 0);
    EXPECT_EQ(v, -4);
    EXPECT_EQ(chm_config_get_int64(d.cfg, "arm.\"max.speed\"", 0, 0, 10, &v), 0);
    EXPECT_EQ(v, 4);

    EXPECT_EQ(chm_config_get_int64(d.cfg, "count", 3, 0, 6, &v), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:2:9: count: expected an integer in [0, 6], got integer 7");
    EXPECT_EQ(chm_config_get_int64(d.cfg, "count", 8, 8, 10, &v), -EBADMSG);
    EXPECT_EQ(chm_config_get_int64(d.cfg, "ratio", 0, INT64_MIN, INT64_MAX, &v), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:3:9: ratio: expected an integer, got float 0.25");
    EXPECT_EQ(chm_config_get_int64(d.cfg, "arm", 0, 0, 1, &v), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:5:1: arm: expected an integer in [0, 1], got a table");

    EXPECT_EQ(chm_config_require_int64(d.cfg, "arm.links", 0, 9, &v), -ENOENT);
    EXPECT_EQ(err(), "t.toml:5:1: arm.links: expected an integer in [0, 9], got nothing "
                     "(table 'arm' has no key 'links')");
    EXPECT_EQ(chm_config_require_int64(d.cfg, "base.links", 0, 9, &v), -ENOENT);
    EXPECT_EQ(err(), "t.toml:1:1: base.links: expected an integer in [0, 9], got nothing "
                     "(the root table has no key 'base')");
}

TEST(ConfigGet, CallerBugsAreEinval) {
    Doc d(kBasic);
    int64_t v = 0;
    double x = 0;
    EXPECT_EQ(chm_config_get_int64(d.cfg, "count", 3, 5, 4, &v), -EINVAL);       // min > max
    EXPECT_EQ(chm_config_get_int64(d.cfg, "count", 11, 0, 10, &v), -EINVAL);     // def outside
    EXPECT_EQ(chm_config_get_int64(d.cfg, "count", 3, 0, 10, nullptr), -EINVAL);
    EXPECT_EQ(chm_config_get_int64(nullptr, "count", 3, 0, 10, &v), -EINVAL);
    EXPECT_EQ(chm_config_get_int64(d.cfg, nullptr, 3, 0, 10, &v), -EINVAL);
    EXPECT_EQ(chm_config_get_double(d.cfg, "ratio", 0, NAN, 1, &x), -EINVAL);
    EXPECT_EQ(chm_config_get_double(d.cfg, "ratio", 2, 0, 1, &x), -EINVAL);
    EXPECT_EQ(chm_config_get_bool(d.cfg, "on", 2, nullptr), -EINVAL);
    for (const char* bad : {"a..b", ".a", "a.", "a[", "a[]", "a[1", "a[x]", "a b", "\"open", "a]"}) {
        EXPECT_EQ(chm_config_get_int64(d.cfg, bad, 0, 0, 1, &v), -EINVAL) << bad;
        EXPECT_NE(err().find("malformed key path"), std::string::npos) << bad;
    }
}

TEST(ConfigGet, Doubles) {
    Doc d(kBasic + "big = 9007199254740993\nhuge = 1e300\nnan = nan\ninf = inf\n");
    double x = 0;
    EXPECT_EQ(chm_config_get_double(d.cfg, "arm.gain", 1, 0, 10, &x), 0);
    EXPECT_EQ(x, 2.5);
    EXPECT_EQ(chm_config_get_double(d.cfg, "count", 1, 0, 10, &x), 0);  // an integer is a number
    EXPECT_EQ(x, 7.0);
    EXPECT_EQ(chm_config_get_double(d.cfg, "arm.nothing", 1.5, 0, 10, &x), 0);
    EXPECT_EQ(x, 1.5);
    EXPECT_EQ(chm_config_get_double(d.cfg, "arm.gain", 1, 0, 2, &x), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:6:8: arm.gain: expected a number in [0, 2], got float 2.5");
    EXPECT_EQ(chm_config_get_double(d.cfg, "title", 0, -INFINITY, INFINITY, &x), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:1:9: title: expected a number, got string \"rig\"");
    EXPECT_EQ(chm_config_get_double(d.cfg, "arm.big", 0, -INFINITY, INFINITY, &x), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:11:7: arm.big: expected a number, got integer 9007199254740993 "
                     "(not exact as a double)");
    EXPECT_EQ(chm_config_get_double(d.cfg, "arm.nan", 0, -INFINITY, INFINITY, &x), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:13:7: arm.nan: expected a number, got float nan");
    EXPECT_EQ(chm_config_get_double(d.cfg, "arm.inf", 0, -INFINITY, INFINITY, &x), 0);
    EXPECT_TRUE(std::isinf(x));
    EXPECT_EQ(chm_config_get_double(d.cfg, "arm.huge", 0, -1e308, 1e299, &x), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:12:8: arm.huge: expected a number in [-1e+308, 1e+299], got float 1e+300");
    EXPECT_EQ(chm_config_require_double(d.cfg, "arm.kd", 0, 1, &x), -ENOENT);
    EXPECT_EQ(err(), "t.toml:5:1: arm.kd: expected a number in [0, 1], got nothing "
                     "(table 'arm' has no key 'kd')");
    EXPECT_EQ(chm_config_require_double(d.cfg, "ratio", 0.1, 0.3, &x), 0);
    EXPECT_EQ(x, 0.25);
}

TEST(ConfigGet, Bools) {
    Doc d(kBasic);
    int b = -1;
    EXPECT_EQ(chm_config_get_bool(d.cfg, "on", 0, &b), 0);
    EXPECT_EQ(b, 1);
    EXPECT_EQ(chm_config_get_bool(d.cfg, "off", 1, &b), 0);
    EXPECT_EQ(b, 1);
    EXPECT_EQ(chm_config_get_bool(d.cfg, "off", 0, &b), 0);
    EXPECT_EQ(b, 0);
    EXPECT_EQ(chm_config_get_bool(d.cfg, "count", 0, &b), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:2:9: count: expected true or false, got integer 7");
    EXPECT_EQ(chm_config_require_bool(d.cfg, "arm.on", &b), -ENOENT);
    EXPECT_EQ(err(), "t.toml:5:1: arm.on: expected true or false, got nothing "
                     "(table 'arm' has no key 'on')");
}

TEST(ConfigGet, Strings) {
    Doc d(kBasic + "long = \"0123456789abcdef\"\nnul = \"a\\u0000b\"\n");
    char buf[16];
    EXPECT_EQ(chm_config_get_string(d.cfg, "title", "none", buf, sizeof buf), 0);
    EXPECT_STREQ(buf, "rig");
    EXPECT_EQ(chm_config_get_string(d.cfg, "subtitle", "none", buf, sizeof buf), 0);
    EXPECT_STREQ(buf, "none");
    EXPECT_EQ(chm_config_get_string(d.cfg, "subtitle", nullptr, buf, sizeof buf), 0);
    EXPECT_STREQ(buf, "");
    EXPECT_EQ(chm_config_get_string(d.cfg, "subtitle", "0123456789abcdef", buf, sizeof buf), -EINVAL);
    EXPECT_EQ(chm_config_get_string(d.cfg, "title", "x", buf, 0), -EINVAL);
    // 16 bytes do not fit in 16 with the NUL: the field's size is its type.
    EXPECT_EQ(chm_config_get_string(d.cfg, "arm.long", "", buf, sizeof buf), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:11:8: arm.long: expected a string of at most 15 bytes, "
                     "got string \"0123456789abcdef\"");
    char big[17];
    EXPECT_EQ(chm_config_get_string(d.cfg, "arm.long", "", big, sizeof big), 0);
    EXPECT_STREQ(big, "0123456789abcdef");
    EXPECT_EQ(chm_config_get_string(d.cfg, "arm.nul", "", buf, sizeof buf), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:12:7: arm.nul: expected a string of at most 15 bytes, got string "
                     "\"a\\x00b\" (it holds a NUL character)");
    EXPECT_EQ(chm_config_get_string(d.cfg, "on", "", buf, sizeof buf), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:4:6: on: expected a string of at most 15 bytes, got boolean true");
    EXPECT_EQ(chm_config_require_string(d.cfg, "arm.name", buf, sizeof buf), -ENOENT);
    EXPECT_EQ(chm_config_require_string(d.cfg, "arm.mode", buf, sizeof buf), 0);
    EXPECT_STREQ(buf, "torque");
}

TEST(ConfigGet, Choices) {
    Doc d(kBasic);
    const char* const modes[] = {"position", "velocity", "torque"};
    size_t i = 99;
    EXPECT_EQ(chm_config_get_choice(d.cfg, "arm.mode", modes, 3, 0, &i), 0);
    EXPECT_EQ(i, 2u);
    EXPECT_EQ(chm_config_get_choice(d.cfg, "arm.other", modes, 3, 1, &i), 0);
    EXPECT_EQ(i, 1u);
    EXPECT_EQ(chm_config_get_choice(d.cfg, "arm.mode", modes, 2, 0, &i), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:8:8: arm.mode: expected one of \"position\", \"velocity\", "
                     "got string \"torque\"");
    EXPECT_EQ(chm_config_get_choice(d.cfg, "count", modes, 3, 0, &i), -EBADMSG);
    EXPECT_EQ(chm_config_get_choice(d.cfg, "arm.mode", modes, 3, 3, &i), -EINVAL);  // def >= n
    EXPECT_EQ(chm_config_get_choice(d.cfg, "arm.mode", modes, 0, 0, &i), -EINVAL);
    EXPECT_EQ(chm_config_require_choice(d.cfg, "arm.other", modes, 3, &i), -ENOENT);
    EXPECT_EQ(err(), "t.toml:5:1: arm.other: expected one of \"position\", \"velocity\", "
                     "\"torque\", got nothing (table 'arm' has no key 'other')");
}

TEST(ConfigArrays, NumbersWithCountsAndRanges) {
    Doc d(kBasic + "mixed = [1, \"two\"]\nempty = []\n");
    double v[8] = {0};
    size_t n = 99;
    EXPECT_EQ(chm_config_get_doubles(d.cfg, "arm.limits", -5, 5, 1, 8, v, &n), 0);
    ASSERT_EQ(n, 3u);
    EXPECT_EQ(v[0], 1.0);
    EXPECT_EQ(v[1], 2.5);
    EXPECT_EQ(v[2], -3.0);
    EXPECT_EQ(chm_config_get_doubles(d.cfg, "absent", -5, 5, 0, 8, v, &n), 0);
    EXPECT_EQ(n, 0u);
    EXPECT_EQ(chm_config_get_doubles(d.cfg, "arm.empty", -5, 5, 0, 8, v, &n), 0);
    EXPECT_EQ(n, 0u);
    EXPECT_EQ(chm_config_get_doubles(d.cfg, "arm.absent", -5, 5, 2, 8, v, &n), -ENOENT);
    EXPECT_EQ(err(), "t.toml:5:1: arm.absent: expected an array of 2 to 8 numbers in [-5, 5], "
                     "got nothing (table 'arm' has no key 'absent')");
    double w[4] = {7, 7, 7, 7};
    EXPECT_EQ(chm_config_get_doubles(d.cfg, "arm.limits", 0, 5, 0, 4, w, &n), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:9:19: arm.limits[2]: expected a number in [0, 5], got integer -3");
    EXPECT_EQ(w[0], 7.0);  // nothing stored on error
    EXPECT_EQ(chm_config_get_doubles(d.cfg, "arm.limits", -5, 5, 4, 4, v, &n), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:9:10: arm.limits: expected an array of 4 numbers in [-5, 5], "
                     "got an array of 3");
    EXPECT_EQ(chm_config_get_doubles(d.cfg, "arm.limits", -5, 5, 0, 2, v, &n), -EBADMSG);
    EXPECT_EQ(chm_config_get_doubles(d.cfg, "arm.mixed", -5, 5, 0, 2, v, &n), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:11:13: arm.mixed[1]: expected a number in [-5, 5], got string \"two\"");
    EXPECT_EQ(chm_config_get_doubles(d.cfg, "count", -5, 5, 0, 2, v, &n), -EBADMSG);
    EXPECT_EQ(chm_config_get_doubles(d.cfg, "arm.limits", -5, 5, 3, 2, v, &n), -EINVAL);

    int64_t k[4];
    EXPECT_EQ(chm_config_get_int64s(d.cfg, "arm.limits", -5, 5, 0, 4, k, &n), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:9:14: arm.limits[1]: expected an integer in [-5, 5], got float 2.5");
    EXPECT_EQ(chm_config_get_int64s(d.cfg, "arm.mixed", INT64_MIN, INT64_MAX, 0, 4, k, &n), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:11:13: arm.mixed[1]: expected an integer, got string \"two\"");
    Doc e("ids = [3, 1, 2]\n");
    EXPECT_EQ(chm_config_get_int64s(e.cfg, "ids", 0, 3, 3, 3, k, &n), 0);
    EXPECT_EQ(n, 3u);
    EXPECT_EQ(k[0], 3);
    EXPECT_EQ(k[2], 2);
    // Elements are reached by index too.
    int64_t one = 0;
    EXPECT_EQ(chm_config_require_int64(e.cfg, "ids[1]", 0, 3, &one), 0);
    EXPECT_EQ(one, 1);
    EXPECT_EQ(chm_config_require_int64(e.cfg, "ids[3]", 0, 3, &one), -ENOENT);
    EXPECT_EQ(err(), "t.toml:1:7: ids[3]: expected an integer in [0, 3], got nothing "
                     "(array 'ids' has 3 elements)");
}

TEST(ConfigPaths, ThroughNonContainersIsAnError) {
    Doc d(kBasic);
    int64_t v = 0;
    EXPECT_EQ(chm_config_get_int64(d.cfg, "count.x", 0, 0, 1, &v), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:2:9: count: expected a table, got integer 7 (on the way to count.x)");
    EXPECT_EQ(chm_config_get_int64(d.cfg, "arm[0]", 0, 0, 1, &v), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:5:1: arm: expected an array, got a table (on the way to arm[0])");
    EXPECT_EQ(chm_config_type(d.cfg, "count.x"), -EBADMSG);
}

TEST(ConfigTables, TypesCountsKeysAndWhere) {
    Doc d(kBasic + "dt = 1979-05-27T07:32:00Z\n");
    EXPECT_EQ(chm_config_type(d.cfg, ""), CHM_CONFIG_TABLE);
    EXPECT_EQ(chm_config_type(d.cfg, "arm"), CHM_CONFIG_TABLE);
    EXPECT_EQ(chm_config_type(d.cfg, "arm.limits"), CHM_CONFIG_ARRAY);
    EXPECT_EQ(chm_config_type(d.cfg, "title"), CHM_CONFIG_STRING);
    EXPECT_EQ(chm_config_type(d.cfg, "count"), CHM_CONFIG_INTEGER);
    EXPECT_EQ(chm_config_type(d.cfg, "ratio"), CHM_CONFIG_FLOAT);
    EXPECT_EQ(chm_config_type(d.cfg, "on"), CHM_CONFIG_BOOL);
    EXPECT_EQ(chm_config_type(d.cfg, "arm.dt"), CHM_CONFIG_DATETIME);
    EXPECT_EQ(chm_config_type(d.cfg, "nope"), CHM_CONFIG_NONE);

    size_t n = 99;
    EXPECT_EQ(chm_config_count(d.cfg, "arm.limits", &n), 0);
    EXPECT_EQ(n, 3u);
    EXPECT_EQ(chm_config_count(d.cfg, "arm", &n), 0);
    EXPECT_EQ(n, 6u);
    EXPECT_EQ(chm_config_count(d.cfg, "", &n), 0);
    EXPECT_EQ(n, 5u);
    EXPECT_EQ(chm_config_count(d.cfg, "module", &n), 0);
    EXPECT_EQ(n, 0u);
    EXPECT_EQ(chm_config_count(d.cfg, "count", &n), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:2:9: count: expected an array or a table, got integer 7");

    // Keys come in document order, not toml++'s sorted order.
    const char* want[] = {"gain", "joints", "mode", "limits", "max.speed"};
    char key[16];
    for (size_t i = 0; i < 5; ++i) {
        ASSERT_EQ(chm_config_key(d.cfg, "arm", i, key, sizeof key), 0) << err();
        EXPECT_STREQ(key, want[i]);
    }
    EXPECT_EQ(chm_config_key(d.cfg, "arm", 5, key, sizeof key), 0);
    EXPECT_STREQ(key, "dt");
    EXPECT_EQ(chm_config_key(d.cfg, "arm", 6, key, sizeof key), -ENOENT);
    EXPECT_EQ(chm_config_key(d.cfg, "nope", 0, key, sizeof key), -ENOENT);
    EXPECT_EQ(chm_config_key(d.cfg, "arm", 4, key, 5), -ENAMETOOLONG);
    EXPECT_EQ(err(), "t.toml:10:1: key 'max.speed' is longer than 4 bytes");
    EXPECT_EQ(chm_config_key(d.cfg, "title", 0, key, sizeof key), -EBADMSG);
    EXPECT_EQ(chm_config_key(d.cfg, "", 1, key, sizeof key), 0);
    EXPECT_STREQ(key, "count");

    char at[64];
    EXPECT_EQ(chm_config_where(d.cfg, "arm.mode", at, sizeof at), 0);
    EXPECT_STREQ(at, "t.toml:8:8");
    EXPECT_EQ(chm_config_where(d.cfg, "arm.absent", at, sizeof at), 0);
    EXPECT_STREQ(at, "t.toml:5:1");
    EXPECT_EQ(chm_config_where(d.cfg, "arm.mode", at, 5), -ENAMETOOLONG);

    EXPECT_EQ(chm_config_error(d.cfg, "arm.mode", "mode %s needs a sensor", "torque"), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:8:8: arm.mode: mode torque needs a sensor");
    EXPECT_EQ(chm_config_error(d.cfg, "a..b", "x"), -EINVAL);
}

TEST(ConfigTables, UnknownKeysNamedWithTheirPlace) {
    Doc d("[arm]\ngain = 1\ngian = 2\nrate = 3\n");
    const char* const allowed[] = {"gain", "rate", "mode"};
    EXPECT_EQ(chm_config_check_keys(d.cfg, "arm", allowed, 3), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:3:1: unknown key 'gian' in table 'arm' (did you mean 'gain'?)");
    const char* const more[] = {"gain", "gian", "rate"};
    EXPECT_EQ(chm_config_check_keys(d.cfg, "arm", more, 3), 0);
    const char* const far[] = {"alpha", "beta"};
    EXPECT_EQ(chm_config_check_keys(d.cfg, "arm", far, 2), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:2:1: unknown key 'gain' in table 'arm' (expected alpha, beta)");
    EXPECT_EQ(chm_config_check_keys(d.cfg, "arm", nullptr, 0), -EBADMSG);
    EXPECT_EQ(err(), "t.toml:2:1: unknown key 'gain' in table 'arm' (it takes no keys)");
    const char* const top[] = {"arm"};
    EXPECT_EQ(chm_config_check_keys(d.cfg, "", top, 1), 0);
    EXPECT_EQ(chm_config_check_keys(d.cfg, "absent", top, 1), 0);
    EXPECT_EQ(chm_config_check_keys(d.cfg, "arm.gain", top, 1), -EBADMSG);
    const char* const with_null[] = {"gain", nullptr};
    EXPECT_EQ(chm_config_check_keys(d.cfg, "arm", with_null, 2), -EINVAL);
}

// The example system layout, read the way the state-variable planner and
// the module loader will read it.
TEST(ConfigExample, SystemLayout) {
    chm_config_t* cfg = nullptr;
    ASSERT_EQ(chm_config_open(CHM_CONFIG_EXAMPLE, &cfg), 0) << err();
    const std::string file = CHM_CONFIG_EXAMPLE;
    const char* const top[] = {"name", "rtpus", "svar", "module"};
    EXPECT_EQ(chm_config_check_keys(cfg, "", top, 4), 0) << err();

    size_t nsv = 0;
    ASSERT_EQ(chm_config_count(cfg, "svar", &nsv), 0);
    ASSERT_EQ(nsv, 4u);
    const char* const types[] = {"double", "float", "int32", "uint32", "bool"};
    size_t elements[4] = {0};
    for (size_t i = 0; i < nsv; ++i) {
        const std::string sv = "svar[" + std::to_string(i) + "]";
        const char* const keys[] = {"name", "type", "shape", "unit"};
        EXPECT_EQ(chm_config_check_keys(cfg, sv.c_str(), keys, 4), 0) << err();
        char name[32];
        size_t type = 0;
        int64_t shape[2];
        size_t dims = 0;
        ASSERT_EQ(chm_config_require_string(cfg, (sv + ".name").c_str(), name, sizeof name), 0);
        ASSERT_EQ(chm_config_require_choice(cfg, (sv + ".type").c_str(), types, 5, &type), 0);
        ASSERT_EQ(chm_config_get_int64s(cfg, (sv + ".shape").c_str(), 1, 4096, 0, 2, shape, &dims), 0);
        elements[i] = dims == 0 ? 1 : dims == 1 ? size_t(shape[0]) : size_t(shape[0] * shape[1]);
    }
    EXPECT_EQ(elements[0], 6u);
    EXPECT_EQ(elements[2], 36u);
    EXPECT_EQ(elements[3], 1u);

    size_t nm = 0;
    ASSERT_EQ(chm_config_count(cfg, "module", &nm), 0);
    ASSERT_EQ(nm, 2u);
    int64_t rtpus = 0;
    ASSERT_EQ(chm_config_require_int64(cfg, "rtpus", 1, 31, &rtpus), 0);
    int64_t rate = 0, rtpu = 0;
    ASSERT_EQ(chm_config_require_int64(cfg, "module[1].rate_hz", 1, 10000, &rate), 0);
    EXPECT_EQ(rate, 1000);
    ASSERT_EQ(chm_config_require_int64(cfg, "module[1].rtpu", 1, rtpus, &rtpu), 0);
    EXPECT_EQ(rtpu, 2);
    const char* const crit[] = {"soft", "hard"};
    size_t c = 9;
    EXPECT_EQ(chm_config_get_choice(cfg, "module[0].criticality", crit, 2, 0, &c), 0);
    EXPECT_EQ(c, 0u);
    EXPECT_EQ(chm_config_get_choice(cfg, "module[1].criticality", crit, 2, 0, &c), 0);
    EXPECT_EQ(c, 1u);
    double kp[6];
    size_t n = 0;
    EXPECT_EQ(chm_config_get_doubles(cfg, "module[1].params.kp", 0, 1000, 6, 6, kp, &n), 0);
    EXPECT_EQ(kp[2], 80.0);
    double via[4];
    EXPECT_EQ(chm_config_get_doubles(cfg, "module[0].params.via_points", 0, 1, 2, 4, via, &n), 0);
    EXPECT_EQ(n, 3u);
    char in[32];
    EXPECT_EQ(chm_config_require_string(cfg, "module[1].inputs[1]", in, sizeof in), 0);
    EXPECT_STREQ(in, "q");

    // A rate the RTPU cannot run names the module's line and column.
    EXPECT_EQ(chm_config_require_int64(cfg, "module[1].rate_hz", 1, 500, &rate), -EBADMSG);
    EXPECT_EQ(err(), file + ":38:11: module[1].rate_hz: expected an integer in [1, 500], got integer 1000");
    // A missing key of an array-of-tables entry is placed at its header.
    EXPECT_EQ(chm_config_require_double(cfg, "module[0].deadline", 0, 1, &kp[0]), -ENOENT);
    EXPECT_EQ(err(), file + ":28:1: module[0].deadline: expected a number in [0, 1], got nothing "
                            "(table 'module[0]' has no key 'deadline')");
    // The caller's own findings in the same format (a second writer).
    EXPECT_EQ(chm_config_error(cfg, "module[1].outputs[0]", "'%s' has a writer already", "tau"), -EBADMSG);
    EXPECT_EQ(err(), file + ":41:12: module[1].outputs[0]: 'tau' has a writer already");
    chm_config_close(cfg);
}

}  // namespace
