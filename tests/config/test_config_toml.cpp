// Suite `config`: the library's replacement for toml++ 3.3.0's
// is_non_ascii_horizontal_whitespace (src/lib/config/toml.hpp), whose
// generated lookup is undefined behaviour on three blocks of code points:
// it must agree with the generated one everywhere else, and input with
// those code points where toml++ looks for whitespace must get a clean
// syntax error.
#include <gtest/gtest.h>

#include <cerrno>
#include <string>

#include "toml.hpp"

#include "chimera/config.h"

namespace {

bool in_broken_block(char32_t c) {
    return (c >= 0xA1 && c <= 0x499) || (c >= 0x2C5E && c <= 0x3057 && c != 0x3000) ||
           (c >= 0xFB26 && c <= 0xFEFE);
}

TEST(ConfigToml, WhitespaceAgreesWithTomlOutsideItsBrokenBlocks) {
    int whitespace = 0;
    for (char32_t c = 0; c <= 0x10FFFF; ++c) {
        const bool mine = toml::impl::is_non_ascii_horizontal_whitespace(c);
        whitespace += mine;
        if (in_broken_block(c)) continue;
        ASSERT_EQ(mine, toml::impl::toml_generated_is_non_ascii_horizontal_whitespace(c))
            << std::hex << static_cast<unsigned>(c);
    }
    EXPECT_EQ(whitespace, 20);  // the count toml++'s generator states
}

std::string utf8(char32_t c) {
    std::string s;
    if (c < 0x800) {
        s += static_cast<char>(0xC0 | (c >> 6));
    } else {
        s += static_cast<char>(0xE0 | (c >> 12));
        s += static_cast<char>(0x80 | ((c >> 6) & 0x3F));
    }
    s += static_cast<char>(0x80 | (c & 0x3F));
    return s;
}

TEST(ConfigToml, BrokenBlockCodePointsGiveSyntaxErrors) {
    for (char32_t c : {char32_t{0xE9}, char32_t{0x499}, char32_t{0x2C60}, char32_t{0x3001}, char32_t{0xFB30},
                       char32_t{0xFEFE}}) {
        for (const std::string& text : {"k = " + utf8(c) + "\n", "k = 1 " + utf8(c) + "\n", utf8(c) + " = 1\n"}) {
            chm_config_t* cfg = nullptr;
            EXPECT_EQ(chm_config_parse(text.data(), text.size(), "w.toml", &cfg), -EBADMSG) << text;
            EXPECT_EQ(std::string(chm_config_last_error()).rfind("w.toml:1:", 0), 0u) << chm_config_last_error();
        }
        // As a string's content it is just a character.
        const std::string ok = "k = \"" + utf8(c) + "\"\n";
        chm_config_t* cfg = nullptr;
        ASSERT_EQ(chm_config_parse(ok.data(), ok.size(), "w.toml", &cfg), 0) << chm_config_last_error();
        char buf[8];
        EXPECT_EQ(chm_config_require_string(cfg, "k", buf, sizeof buf), 0);
        EXPECT_EQ(std::string(buf), utf8(c));
        chm_config_close(cfg);
    }
}

}  // namespace
