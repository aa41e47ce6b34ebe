// Views over the caller's memory, blocks of them, copy, sub-copy and fill.
#include "lib/matrix/matrix.hpp"

using chm::mat::check;
using chm::mat::fail;
using chm::mat::map;

namespace {

// A view the caller builds: checked like any other, written only when good.
int make(const char* call, chm_mat_t* m, double* data, uint32_t rows, uint32_t cols,
         uint32_t stride) {
    if (!m) return fail(call, CHM_EMAT_ARG, "NULL view to fill in");
    const chm_mat_t v{data, rows, cols, stride};
    if (const int rc = check(call, "data", &v)) return rc;
    *m = v;
    return 0;
}

// 0, or CHM_EMAT_RANGE: the rows x cols block at (row, col) of m reaches
// outside it. Sums in 64 bits: row + rows may pass 2^32.
int inside(const char* call, const char* what, const chm_mat_t& m, uint32_t row, uint32_t col,
           uint32_t rows, uint32_t cols) {
    if (rows == 0 || cols == 0)
        return fail(call, CHM_EMAT_ARG, "%s: %ux%u block (rows and columns start at 1)", what,
                    unsigned(rows), unsigned(cols));
    if (uint64_t(row) + rows > m.rows || uint64_t(col) + cols > m.cols)
        return fail(call, CHM_EMAT_RANGE, "%s: %ux%u block at (%u, %u) outside its %ux%u matrix",
                    what, unsigned(rows), unsigned(cols), unsigned(row), unsigned(col),
                    unsigned(m.rows), unsigned(m.cols));
    return 0;
}

chm_mat_t sub(const chm_mat_t& m, uint32_t row, uint32_t col, uint32_t rows, uint32_t cols) {
    return chm_mat_t{m.data + size_t(row) * m.stride + col, rows, cols, m.stride};
}

int copy(const char* call, const chm_mat_t& src, const chm_mat_t& dst) {
    if (src.rows != dst.rows || src.cols != dst.cols)
        return fail(call, CHM_EMAT_DIM, "%ux%u into %ux%u: dimensions differ", unsigned(src.rows),
                    unsigned(src.cols), unsigned(dst.rows), unsigned(dst.cols));
    if (chm::mat::same(src, dst)) return 0;
    if (chm::mat::overlap(src, dst))
        return fail(call, CHM_EMAT_ALIAS, "%ux%u: destination overlaps the source",
                    unsigned(src.rows), unsigned(src.cols));
    map(dst) = map(src);
    return 0;
}

}  // namespace

extern "C" {

int chm_mat_view(chm_mat_t* m, double* data, uint32_t rows, uint32_t cols) {
    return make("chm_mat_view", m, data, rows, cols, cols);
}

int chm_mat_view_stride(chm_mat_t* m, double* data, uint32_t rows, uint32_t cols,
                        uint32_t stride) {
    return make("chm_mat_view_stride", m, data, rows, cols, stride);
}

int chm_mat_vector(chm_mat_t* v, double* data, uint32_t n) {
    return make("chm_mat_vector", v, data, n, 1, 1);
}

int chm_mat_block(chm_mat_t* blk, const chm_mat_t* m, uint32_t row, uint32_t col, uint32_t rows,
                  uint32_t cols) {
    static const char* const call = "chm_mat_block";
    if (!blk) return fail(call, CHM_EMAT_ARG, "NULL view to fill in");
    if (const int rc = check(call, "m", m)) return rc;
    if (const int rc = inside(call, "m", *m, row, col, rows, cols)) return rc;
    *blk = sub(*m, row, col, rows, cols);
    return 0;
}

int chm_mat_copy(const chm_mat_t* src, const chm_mat_t* dst) {
    static const char* const call = "chm_mat_copy";
    if (const int rc = check(call, "src", src)) return rc;
    if (const int rc = check(call, "dst", dst)) return rc;
    return copy(call, *src, *dst);
}

int chm_mat_subcopy(const chm_mat_t* src, uint32_t src_row, uint32_t src_col, uint32_t rows,
                    uint32_t cols, const chm_mat_t* dst, uint32_t dst_row, uint32_t dst_col) {
    static const char* const call = "chm_mat_subcopy";
    if (const int rc = check(call, "src", src)) return rc;
    if (const int rc = check(call, "dst", dst)) return rc;
    if (const int rc = inside(call, "src", *src, src_row, src_col, rows, cols)) return rc;
    if (const int rc = inside(call, "dst", *dst, dst_row, dst_col, rows, cols)) return rc;
    return copy(call, sub(*src, src_row, src_col, rows, cols),
                sub(*dst, dst_row, dst_col, rows, cols));
}

int chm_mat_fill(const chm_mat_t* m, double value) {
    if (const int rc = check("chm_mat_fill", "m", m)) return rc;
    map(*m).setConstant(value);
    return 0;
}

int chm_mat_identity(const chm_mat_t* m) {
    if (const int rc = check("chm_mat_identity", "m", m)) return rc;
    map(*m).setIdentity();
    return 0;
}

}  // extern "C"
