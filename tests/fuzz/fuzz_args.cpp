// libFuzzer harness: the command-line value parsers of the tools, which
// every number on the chimera and chimera-rtpu command lines goes through
// (tools/parse_num.hpp; --rt-priority and --cpu in
// tools/chimera-rtpu/realtime.cpp). The input is a list of NUL-separated
// arguments; each is parsed with the ranges the tools use. An accepted
// value must be the whole argument read as a decimal number inside the
// range; a refused one must leave the output alone and, for the named
// options, say which option wanted what.
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <string>

#include <sched.h>

#include "../../tools/chimera-rtpu/realtime.hpp"
#include "../../tools/parse_num.hpp"

namespace {

void check_num(const char* s, long lo, long hi) {
    long v = -12345;
    if (!chimera_tools::parse_num(s, lo, hi, &v)) {
        if (v != -12345) std::abort();  // a refusal writes nothing
        return;
    }
    char* end = nullptr;
    errno = 0;
    const long w = std::strtol(s, &end, 10);
    if (!*s || *end || errno || v != w || v < lo || v > hi) std::abort();
}

void check_option(const char* s) {
    int v = -7;
    std::string why = chimera_rtpu::parse_fifo_priority(s, &v);
    if (why.empty() ? (v < 1 || v > 99) : (v != -7 || why.find("--rt-priority") == std::string::npos)) std::abort();
    v = -7;
    why = chimera_rtpu::parse_cpu(s, &v);
    if (why.empty() ? (v < 0 || v >= CPU_SETSIZE) : (v != -7 || why.find("--cpu") == std::string::npos)) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    std::string all(reinterpret_cast<const char*>(data), size);
    all.push_back('\0');
    for (std::size_t at = 0; at < all.size();) {
        const char* s = all.c_str() + at;
        check_num(s, 1, 30);      // chimera start --rtpus
        check_num(s, 0, 100000);  // --idle-poll
        check_num(s, 1, 1000);    // --program RTPU:
        check_num(s, 0, 1000000); // chimera-rtpu --rtpu
        check_option(s);
        at += std::strlen(s) + 1;
    }
    return 0;
}
