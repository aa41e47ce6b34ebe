// The line splitter of the command interpreter (chimera/cmdi.h, "Lines"):
// blanks, quotes, backslashes, comments; errors name the column.
#include <cstdio>

#include "cmdi.hpp"

namespace chm::cmdi {

namespace {

bool blank(char ch) {
    return ch == ' ' || ch == '\t' || ch == '\r' || ch == '\n' || ch == '\v' || ch == '\f';
}

// How messages show one character: itself when printable, else \xHH.
std::string shown(char ch) {
    const unsigned char u = static_cast<unsigned char>(ch);
    if (u >= 0x20 && u < 0x7f) return std::string(1, ch);
    char hex[8];
    std::snprintf(hex, sizeof hex, "\\x%02x", u);
    return hex;
}

// " at column N" for the 0-based index i.
std::string at(std::size_t i) { return " at column " + std::to_string(i + 1); }

}  // namespace

std::string printable(std::string_view s) {
    std::string out;
    for (std::size_t i = 0; i < s.size(); ++i) {
        if (i == 60) return out + "...";
        out += shown(s[i]);
    }
    return out;
}

int split(std::string_view line, std::vector<std::string>& words, std::string& err) {
    words.clear();
    std::size_t i = 0;
    const std::size_t n = line.size();
    for (;;) {
        while (i < n && blank(line[i])) ++i;
        if (i == n || line[i] == '#') return 0;
        std::string word;
        while (i < n && !blank(line[i])) {
            const char ch = line[i];
            if (ch == '\\') {
                if (i + 1 == n) {
                    err = "backslash at the end of the line (column " + std::to_string(i + 1) + ")";
                    return -EINVAL;
                }
                word += line[i + 1];
                i += 2;
            } else if (ch == '\'') {
                const std::size_t close = line.find('\'', i + 1);
                if (close == std::string_view::npos) {
                    err = "unterminated single quote opened" + at(i);
                    return -EINVAL;
                }
                word.append(line.substr(i + 1, close - i - 1));
                i = close + 1;
            } else if (ch == '"') {
                const std::size_t open = i++;
                for (;;) {
                    if (i == n) {
                        err = "unterminated double quote opened" + at(open);
                        return -EINVAL;
                    }
                    const char q = line[i];
                    if (q == '"') {
                        ++i;
                        break;
                    }
                    if (q != '\\') {
                        word += q;
                        ++i;
                        continue;
                    }
                    if (i + 1 == n) {
                        err = "unterminated double quote opened" + at(open);
                        return -EINVAL;
                    }
                    const char e = line[i + 1];
                    if (e == '"' || e == '\\') {
                        word += e;
                    } else if (e == 'n') {
                        word += '\n';
                    } else if (e == 't') {
                        word += '\t';
                    } else {
                        err = "unknown escape '\\" + shown(e) + "' in double quotes" + at(i);
                        return -EINVAL;
                    }
                    i += 2;
                }
            } else {
                word += ch;
                ++i;
            }
        }
        words.push_back(std::move(word));
    }
}

}  // namespace chm::cmdi
