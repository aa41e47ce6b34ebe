// Suite `cmdi`: a differential test of the line splitter (words.cpp)
// against an independent model built on std::regex: a word is a run of
// pieces (a plain character, a backslash and any character, a single-quoted
// string, a double-quoted string with the escapes \" \\ \n \t), and where
// the run stops on something other than a blank, the character there says
// which error it is. Random lines over an alphabet dense in quotes,
// backslashes and blanks; the words and the exact error text must agree,
// through the splitter and through chm_cmdi_run_line. CHM_DIFF_SEED picks
// the seed (0: random, printed), CHM_DIFF_LINES the count.
#include <cstdlib>
#include <random>
#include <regex>

#include "cmdi.hpp"
#include "cmdi_test.hpp"

namespace {

const std::string kBlanks = " \t\r\n\v\f";

struct Model {
    int rc = 0;
    std::vector<std::string> words;
    std::string err;
};

std::string decode(const std::string& token) {
    static const std::regex piece("\\\\([\\s\\S])|'([^']*)'|\"((?:[^\"\\\\]|\\\\[\"\\\\nt])*)\"|([\\s\\S])");
    static const std::regex esc("\\\\([\"\\\\nt])");
    std::string out;
    for (std::sregex_iterator it(token.begin(), token.end(), piece), end; it != end; ++it) {
        const std::smatch& m = *it;
        if (m[1].matched) {
            out += m[1].str();
        } else if (m[2].matched) {
            out += m[2].str();
        } else if (m[3].matched) {
            const std::string body = m[3].str();
            for (std::sregex_token_iterator t(body.begin(), body.end(), esc, {-1, 1}), te; t != te; ++t) {
                out += t->str();
                if (++t == te) break;
                const std::string e = t->str();
                out += e == "n" ? "\n" : e == "t" ? "\t" : e;
            }
        } else {
            out += m[4].str();
        }
    }
    return out;
}

Model model(const std::string& line) {
    const std::string not_blank = "[^" + kBlanks + "'\"\\\\]";
    static const std::regex word("(?:" + not_blank +
                                 "|\\\\[\\s\\S]|'[^']*'|\"(?:[^\"\\\\]|\\\\[\"\\\\nt])*\")+");
    Model r;
    std::size_t pos = 0;
    const std::size_t n = line.size();
    for (;;) {
        pos = line.find_first_not_of(kBlanks, pos);
        if (pos == std::string::npos || line[pos] == '#') return r;
        std::smatch m;
        const auto from = line.begin() + static_cast<std::ptrdiff_t>(pos);
        const std::size_t len =
            std::regex_search(from, line.end(), m, word, std::regex_constants::match_continuous) ? m.length(0) : 0;
        const std::string token = line.substr(pos, len);
        pos += len;
        if (pos < n && kBlanks.find(line[pos]) == std::string::npos) {
            r.rc = -EINVAL;
            const std::string col = std::to_string(pos + 1);
            if (line[pos] == '\'') {
                r.err = "unterminated single quote opened at column " + col;
            } else if (line[pos] == '\\') {
                r.err = "backslash at the end of the line (column " + col + ")";
            } else {
                r.err = "unterminated double quote opened at column " + col;
                for (std::size_t j = pos + 1; j + 1 < n; ++j) {
                    if (line[j] == '"') break;
                    if (line[j] != '\\') continue;
                    const char e = line[j + 1];
                    if (e != '"' && e != '\\' && e != 'n' && e != 't') {
                        char shown[8];
                        const unsigned char u = static_cast<unsigned char>(e);
                        if (u >= 0x20 && u < 0x7f)
                            std::snprintf(shown, sizeof shown, "%c", e);
                        else
                            std::snprintf(shown, sizeof shown, "\\x%02x", u);
                        r.err = std::string("unknown escape '\\") + shown + "' in double quotes at column " +
                                std::to_string(j + 1);
                        break;
                    }
                    ++j;
                }
            }
            r.words.clear();
            return r;
        }
        r.words.push_back(decode(token));
    }
}

std::string random_line(std::mt19937& rng) {
    static const std::vector<std::string> alphabet = {"a", "b", "#", " ", " ", "\t", "'", "'", "\"", "\"", "\\",
                                                      "\\", "n", "t", "q", "\r", "\n", "\v", "\x01", "é"};
    std::uniform_int_distribution<std::size_t> len(0, 24), pick(0, alphabet.size() - 1);
    std::string line;
    for (std::size_t i = len(rng); i > 0; --i) line += alphabet[pick(rng)];
    return line;
}

TEST(CmdiSplitModel, ModelAgreesOnKnownLines) {
    // The model itself, on lines whose answer is known (so the comparison
    // below compares two right answers, not two wrong ones).
    EXPECT_EQ(model("a 'b c'\"d\\\"\"e \\ f # g").words, (std::vector<std::string>{"a", "b cd\"e", " f"}));
    EXPECT_EQ(model("x \"a\\q").err, "unknown escape '\\q' in double quotes at column 5");
    EXPECT_EQ(model("x 'a").err, "unterminated single quote opened at column 3");
    EXPECT_EQ(model("\"a\\").err, "unterminated double quote opened at column 1");
    EXPECT_EQ(model("ab\\").err, "backslash at the end of the line (column 3)");
    EXPECT_EQ(model("\"\\n\\t\"").words, (std::vector<std::string>{"\n\t"}));
}

TEST(CmdiSplitModel, RandomLinesAgree) {
    unsigned seed = 20240519;
    if (const char* s = std::getenv("CHM_DIFF_SEED")) seed = static_cast<unsigned>(std::strtoul(s, nullptr, 10));
    if (seed == 0) seed = std::random_device{}();
    std::size_t count = 20000;
    if (const char* s = std::getenv("CHM_DIFF_LINES")) count = std::strtoul(s, nullptr, 10);
    std::printf("seed %u, %zu lines\n", seed, count);
    std::mt19937 rng(seed);
    chm::test::Cmdi t;
    t.add_recorder("w");
    std::size_t errors = 0, words = 0, failures = 0;
    for (std::size_t i = 0; i < count && failures < 10; ++i) {
        const std::string line = random_line(rng);
        const Model want = model(line);
        std::vector<std::string> got;
        std::string err;
        const int rc = chm::cmdi::split(line, got, err);
        errors += rc != 0;
        words += got.size();
        const bool same = rc == want.rc && (rc ? err == want.err : got == want.words);
        if (!same) ++failures;
        EXPECT_TRUE(same) << "seed " << seed << " line " << i << " '" << chm::cmdi::printable(line)
                          << "': splitter " << rc << " '" << err << "' " << ::testing::PrintToString(got)
                          << ", model " << want.rc << " '" << want.err << "' "
                          << ::testing::PrintToString(want.words);
        // Through the public API: the same line after a command name.
        if (i % 4) continue;
        const Model full = model("w " + line);
        t.calls.clear();
        const int run = chm_cmdi_run_line(t.c, ("w " + line).c_str());
        if (full.rc) {
            EXPECT_EQ(run, -EINVAL) << chm::cmdi::printable(line);
            EXPECT_EQ(t.err(), full.err) << chm::cmdi::printable(line);
        } else {
            EXPECT_EQ(run, 0) << chm::cmdi::printable(line) << ": " << t.err();
            ASSERT_EQ(t.calls.size(), 1u);
            EXPECT_EQ(std::vector<std::string>(t.calls[0].begin() + 1, t.calls[0].end()),
                      std::vector<std::string>(full.words.begin() + 1, full.words.end()));
        }
    }
    // The alphabet must reach both outcomes often, or the test says little.
    EXPECT_GT(errors, count / 10);
    EXPECT_LT(errors, count - count / 10);
    EXPECT_GT(words, count / 2);
}

}  // namespace
