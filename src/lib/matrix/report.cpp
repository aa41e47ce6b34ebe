// Module "matrix" of global error handling, the per-thread last error, and
// the view checks every call makes before it touches an element.
#include <pthread.h>

#include <algorithm>
#include <cerrno>
#include <cstdarg>
#include <cstdint>
#include <cstdio>

#include "chimera/err.h"
#include "kernel/err/err_internal.hpp"
#include "lib/matrix/matrix.hpp"

namespace chm::mat {
namespace {

thread_local char t_last[192];
thread_local int t_code = 0;

const chm_err_code_t kCodes[] = {
    {CHM_EMAT_ARG, "invalid argument (NULL, malformed view, unknown norm)"},
    {CHM_EMAT_DIM, "dimension mismatch"},
    {CHM_EMAT_RANGE, "block outside its matrix"},
    {CHM_EMAT_ALIAS, "output overlaps an input"},
    {CHM_EMAT_WORK, "workspace missing, too small or overlapping"},
    {CHM_EMAT_SINGULAR, "matrix singular to working precision"},
    {CHM_EMAT_NOTFINITE, "NaN or infinity in the input"},
};

pthread_once_t g_once = PTHREAD_ONCE_INIT;
int g_module = -1;

void register_module() {
    int m = chm_err_module_register("matrix", kCodes, sizeof kCodes / sizeof kCodes[0]);
    if (m == -EEXIST) m = chm_err_module_find("matrix");
    g_module = m;
}

}  // namespace

int fail(const char* call, int code, const char* fmt, ...) {
    const int status = code == CHM_EMAT_SINGULAR || code == CHM_EMAT_NOTFINITE ? -EDOM : -EINVAL;
    t_code = code;
    int k = std::snprintf(t_last, sizeof t_last, "%s: ", call);
    if (k < 0 || std::size_t(k) >= sizeof t_last) k = 0;
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(t_last + k, sizeof t_last - std::size_t(k), fmt, ap);
    va_end(ap);
    kernel::err_last_set(t_last);  // chm_err_last
    // Host threads, tasks without global handling, and the interrupt mask
    // (a handler must not run inside the kernel): a status only.
    if (!chm_err_global_get() || port::irq_masked()) return status;
    pthread_once(&g_once, register_module);
    if (g_module <= 0) return status;
    chm_err_info_t info{};
    info.module = g_module;
    info.code = code;
    info.call = call;
    info.detail = t_last + k;  // the call is named in info.call
    info.status = status;
    const int saved = errno;
    kernel::err_raise(info);  // returns when a handler continues
    errno = saved;
    return status;
}

int check(const char* call, const char* what, const chm_mat_t* m) {
    if (!m) return fail(call, CHM_EMAT_ARG, "%s: NULL view", what);
    if (!m->data) return fail(call, CHM_EMAT_ARG, "%s: view of NULL data", what);
    if (m->rows == 0 || m->cols == 0)
        return fail(call, CHM_EMAT_ARG, "%s: %ux%u view (rows and columns start at 1)", what,
                    unsigned(m->rows), unsigned(m->cols));
    if (m->stride < m->cols)
        return fail(call, CHM_EMAT_ARG, "%s: stride %u below its %u columns", what,
                    unsigned(m->stride), unsigned(m->cols));
    // Eigen indexes with ptrdiff_t, and the elements must not wrap around
    // the address space (a 32-bit target reaches that with a large view).
    const std::uint64_t limit = std::uint64_t(PTRDIFF_MAX) / sizeof(double);
    const std::uint64_t span = std::uint64_t(m->rows - 1) * m->stride + m->cols;
    if (std::uint64_t(m->rows) * m->stride > limit ||
        span > (UINTPTR_MAX - std::uintptr_t(m->data)) / sizeof(double))
        return fail(call, CHM_EMAT_ARG, "%s: %ux%u view of stride %u larger than the address space",
                    what, unsigned(m->rows), unsigned(m->cols), unsigned(m->stride));
    return 0;
}

namespace {

struct Interval {
    std::int64_t lo, hi;  // [lo, hi)
};
bool meet(Interval a, Interval b) { return a.lo < b.hi && b.lo < a.hi && a.lo < a.hi && b.lo < b.hi; }

std::uintptr_t end_of(const chm_mat_t& m) {
    return std::uintptr_t(m.data) +
           (std::uintptr_t(m.rows - 1) * m.stride + m.cols) * sizeof(double);
}

}  // namespace

bool overlap(const chm_mat_t& a, const chm_mat_t& b) {
    const auto a0 = std::uintptr_t(a.data), b0 = std::uintptr_t(b.data);
    if (a0 >= end_of(b) || b0 >= end_of(a)) return false;
    // The address ranges meet. Unless both views lie on one grid of doubles
    // of one width, that is taken as overlapping.
    const std::uintptr_t gap = a0 > b0 ? a0 - b0 : b0 - a0;
    if (gap % sizeof(double) != 0) return true;
    const std::int64_t d = b0 > a0 ? std::int64_t(gap / sizeof(double))
                                   : -std::int64_t(gap / sizeof(double));
    if (a.rows == 1 && b.rows == 1) return meet({0, a.cols}, {d, d + b.cols});
    std::uint32_t s;  // the grid's width: the stride of the views with rows > 1
    if (a.rows > 1 && b.rows > 1) {
        if (a.stride != b.stride) return true;
        s = a.stride;
    } else {
        s = a.rows > 1 ? a.stride : b.stride;
        if ((a.rows == 1 ? a.cols : b.cols) > s) return true;  // a row wider than the grid
    }
    // b's element (k, l) is a's offset d + k*s + l, d = q*s + r with
    // 0 <= r < s: the columns l < s - r stay in a's row q + k, the others
    // wrap into row q + k + 1 at column l - (s - r).
    const std::int64_t ss = s;
    std::int64_t q = d / ss, r = d % ss;
    if (r < 0) r += ss, q -= 1;
    const Interval arows{0, a.rows}, acols{0, a.cols};
    const std::int64_t stay = std::min<std::int64_t>(b.cols, ss - r);
    if (meet(arows, {q, q + b.rows}) && meet(acols, {r, r + stay})) return true;
    return b.cols > stay && meet(arows, {q + 1, q + 1 + b.rows}) &&
           meet(acols, {0, b.cols - stay});
}

bool overlap(const chm_mat_t& m, const double* p, std::size_t len) {
    const auto p0 = std::uintptr_t(p);
    const std::uintptr_t p1 = p0 + len * sizeof(double);
    return std::uintptr_t(m.data) < p1 && p0 < end_of(m);
}

}  // namespace chm::mat

extern "C" int chm_mat_err_module(void) {
    pthread_once(&chm::mat::g_once, chm::mat::register_module);
    return chm::mat::g_module;
}

extern "C" const char* chm_mat_last_error(void) { return chm::mat::t_last; }
extern "C" int chm_mat_last_code(void) { return chm::mat::t_code; }
