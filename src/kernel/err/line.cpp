// The one diagnostic line of an error signal, formatted without stdio or
// the heap so that the fail-stop path can use it in a signal handler.
#include <unistd.h>

#include "err/err_internal.hpp"

namespace chm::kernel {

void LineBuf::put(const char* p) {
    if (!p) return;
    while (*p && n < sizeof s - 2) s[n++] = *p++;
}

void LineBuf::num(long long v) {
    char d[24];
    int i = 0;
    unsigned long long u = v < 0 ? 0ull - static_cast<unsigned long long>(v) : static_cast<unsigned long long>(v);
    do {
        d[i++] = char('0' + u % 10);
        u /= 10;
    } while (u);
    if (v < 0) d[i++] = '-';
    while (i && n < sizeof s - 2) s[n++] = d[--i];
}

void LineBuf::hex(std::uintptr_t v) {
    char d[2 * sizeof v];
    int i = 0;
    do {
        d[i++] = "0123456789abcdef"[v & 15];
        v >>= 4;
    } while (v);
    put("0x");
    while (i && n < sizeof s - 2) s[n++] = d[--i];
}

// chimera: RTPU 1 task ctrl (id 65537): unix error 2 (No such file or
// directory) in open("/x") at main.c:12
void err_format_line(LineBuf& b, const chm_err_info_t& info, const char* task_name) {
    b.put("chimera: RTPU ");
    b.num(err_rtpu());
    if (info.task != CHM_TID_NONE) {
        b.put(" task ");
        b.put(task_name ? task_name : "?");
        b.put(" (id ");
        b.num(info.task);
        b.put(")");
    } else {
        b.put(" (no task)");
    }
    b.put(": ");
    b.put(info.module_name ? info.module_name : "?");
    b.put(" error ");
    b.num(info.code);
    b.put(" (");
    b.put(info.message ? info.message : "?");
    b.put(")");
    if (info.call) {
        b.put(" in ");
        b.put(info.call);
        if (info.detail) {
            b.put("(\"");
            b.put(info.detail);
            b.put("\")");
        }
    } else if (info.detail) {
        b.put(": ");
        b.put(info.detail);
    }
    if (info.module == CHM_ERR_CPU) {
        b.put(", address ");
        b.hex(info.addr);
        b.put(", pc ");
        b.hex(info.pc);
    }
    if (info.file) {
        b.put(" at ");
        b.put(info.file);
        b.put(":");
        b.num(info.line);
    }
    b.s[b.n++] = '\n';
}

}  // namespace chm::kernel
