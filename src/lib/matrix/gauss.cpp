// Determinant, solve and inverse: Gaussian elimination with partial
// pivoting, done in the caller's workspace before any output is written
// (LU factors of P*A in n*n doubles, the interchanges in n more), so a
// singular matrix is reported with the outputs untouched.
#include <cfloat>
#include <algorithm>
#include <cmath>

#include "lib/matrix/matrix.hpp"

using chm::mat::check;
using chm::mat::fail;
using chm::mat::map;

namespace {

using Index = Eigen::Index;
using Work = Eigen::Map<chm::mat::Dense>;  // n x n, contiguous, row-major

struct Lu {
    Work w;
    double* piv;     // piv[c]: the row swapped with row c at step c
    int sign = 1;    // of the permutation
    Index bad = -1;  // the column whose pivot was within the tolerance, or -1
    double pivot = 0, tol = 0;  // that pivot's magnitude and the tolerance
};

// Checks shared by det, solve and inverse: a square, the workspace big
// enough and apart from every matrix of the call (mats[0..nmats)).
int check_square_work(const char* call, const chm_mat_t& a, double* work, size_t work_len,
                      const chm_mat_t* const* mats, int nmats) {
    if (a.rows != a.cols)
        return fail(call, CHM_EMAT_DIM, "a is %ux%u, not square", unsigned(a.rows),
                    unsigned(a.cols));
    const size_t need = CHM_MAT_WORK(a.rows);
    if (!work) return fail(call, CHM_EMAT_WORK, "%ux%u: NULL workspace", unsigned(a.rows),
                           unsigned(a.cols));
    // A view that passed check() fits the address space, so `need` does not wrap.
    if (work_len < need)
        return fail(call, CHM_EMAT_WORK, "%ux%u: workspace of %zu doubles, %zu needed",
                    unsigned(a.rows), unsigned(a.cols), work_len, need);
    for (int i = 0; i < nmats; ++i)
        if (chm::mat::overlap(*mats[i], work, need))
            return fail(call, CHM_EMAT_WORK, "%ux%u: workspace overlaps a matrix of the call",
                        unsigned(a.rows), unsigned(a.cols));
    return 0;
}

int check_finite(const char* call, const char* what, const chm_mat_t& m) {
    if (map(m).allFinite()) return 0;
    return fail(call, CHM_EMAT_NOTFINITE, "%s (%ux%u) holds a NaN or an infinity", what,
                unsigned(m.rows), unsigned(m.cols));
}

// Factor a into the workspace: P*A = L*U, L unit lower (below the
// diagonal), U upper. Stops at the first pivot within the tolerance
// CHM_MAT_PIVOT_TOL * n * DBL_EPSILON * ||A||inf; the norm is taken on A
// scaled by its largest magnitude so that the row sums cannot overflow.
Lu factor(const chm_mat_t& a, double* work) {
    const Index n = a.rows;
    Lu lu{Work(work, n, n), work + n * n};
    Work& w = lu.w;
    w = map(a);
    const double big = w.cwiseAbs().maxCoeff();
    double rows = 0;
    if (big > 0)
        for (Index i = 0; i < n; ++i) rows = std::max(rows, w.row(i).cwiseAbs().sum() / big);
    const double tol = CHM_MAT_PIVOT_TOL * double(n) * DBL_EPSILON * rows * big;
    for (Index c = 0; c < n; ++c) {
        Index p = 0;
        const double mag = w.col(c).tail(n - c).cwiseAbs().maxCoeff(&p);
        p += c;
        if (!(mag > tol)) {  // also a NaN born of overflow in the elimination
            lu.bad = c;
            lu.pivot = mag;
            lu.tol = tol;
            return lu;
        }
        lu.piv[c] = double(p);
        if (p != c) {
            w.row(p).swap(w.row(c));
            lu.sign = -lu.sign;
        }
        const Index rest = n - c - 1;
        for (Index r = c + 1; r < n; ++r) {
            const double f = w(r, c) /= w(c, c);
            w.row(r).tail(rest) -= f * w.row(c).tail(rest);
        }
    }
    return lu;
}

// x (n x k) holds b on entry and a^-1 b on return, from the factors.
void substitute(const Lu& lu, chm::mat::Map x) {
    const Index n = lu.w.rows();
    for (Index c = 0; c < n; ++c)
        if (const auto p = Index(lu.piv[c]); p != c) x.row(p).swap(x.row(c));
    for (Index r = 1; r < n; ++r)
        for (Index j = 0; j < r; ++j) x.row(r) -= lu.w(r, j) * x.row(j);
    for (Index r = n - 1; r >= 0; --r) {
        for (Index j = r + 1; j < n; ++j) x.row(r) -= lu.w(r, j) * x.row(j);
        x.row(r) /= lu.w(r, r);
    }
}

int singular(const char* call, const chm_mat_t& a, const Lu& lu) {
    return fail(call, CHM_EMAT_SINGULAR,
                "%ux%u matrix singular: column %ld's pivot %.3g is within the tolerance %.3g",
                unsigned(a.rows), unsigned(a.cols), long(lu.bad), lu.pivot, lu.tol);
}

}  // namespace

extern "C" {

int chm_mat_det(const chm_mat_t* a, double* out, double* work, size_t work_len) {
    static const char* const call = "chm_mat_det";
    if (const int rc = check(call, "a", a)) return rc;
    if (!out) return fail(call, CHM_EMAT_ARG, "NULL result");
    const chm_mat_t* const mats[] = {a};
    if (const int rc = check_square_work(call, *a, work, work_len, mats, 1)) return rc;
    if (const int rc = check_finite(call, "a", *a)) return rc;
    const Lu lu = factor(*a, work);
    if (lu.bad >= 0) {
        *out = 0.0;  // singular: its determinant, not an error
        return 0;
    }
    *out = double(lu.sign) * lu.w.diagonal().prod();
    return 0;
}

int chm_mat_solve(const chm_mat_t* a, const chm_mat_t* b, const chm_mat_t* x, double* work,
                  size_t work_len) {
    static const char* const call = "chm_mat_solve";
    if (const int rc = check(call, "a", a)) return rc;
    if (const int rc = check(call, "b", b)) return rc;
    if (const int rc = check(call, "x", x)) return rc;
    if (a->rows != a->cols)
        return fail(call, CHM_EMAT_DIM, "a is %ux%u, not square", unsigned(a->rows),
                    unsigned(a->cols));
    if (b->rows != a->rows || x->rows != b->rows || x->cols != b->cols)
        return fail(call, CHM_EMAT_DIM, "%ux%u a, %ux%u b, %ux%u x: b and x must be %ux%u",
                    unsigned(a->rows), unsigned(a->cols), unsigned(b->rows), unsigned(b->cols),
                    unsigned(x->rows), unsigned(x->cols), unsigned(a->rows),
                    unsigned(b->rows == a->rows ? b->cols : x->cols));
    // a is copied into the workspace before x is written, so only b matters.
    if (!chm::mat::elementwise_ok(*b, *x))
        return fail(call, CHM_EMAT_ALIAS, "%ux%u: x overlaps b without being the same view",
                    unsigned(x->rows), unsigned(x->cols));
    const chm_mat_t* const mats[] = {a, b, x};
    if (const int rc = check_square_work(call, *a, work, work_len, mats, 3)) return rc;
    if (const int rc = check_finite(call, "a", *a)) return rc;
    if (const int rc = check_finite(call, "b", *b)) return rc;
    const Lu lu = factor(*a, work);
    if (lu.bad >= 0) return singular(call, *a, lu);
    if (!chm::mat::same(*b, *x)) map(*x) = map(*b);
    substitute(lu, map(*x));
    return 0;
}

int chm_mat_inverse(const chm_mat_t* a, const chm_mat_t* out, double* work, size_t work_len) {
    static const char* const call = "chm_mat_inverse";
    if (const int rc = check(call, "a", a)) return rc;
    if (const int rc = check(call, "out", out)) return rc;
    if (out->rows != a->rows || out->cols != a->cols)
        return fail(call, CHM_EMAT_DIM, "a is %ux%u, out %ux%u", unsigned(a->rows),
                    unsigned(a->cols), unsigned(out->rows), unsigned(out->cols));
    const chm_mat_t* const mats[] = {a, out};
    if (const int rc = check_square_work(call, *a, work, work_len, mats, 2)) return rc;
    if (const int rc = check_finite(call, "a", *a)) return rc;
    // a is in the workspace from here: out may overlap it in any way.
    const Lu lu = factor(*a, work);
    if (lu.bad >= 0) return singular(call, *a, lu);
    map(*out).setIdentity();
    substitute(lu, map(*out));
    return 0;
}

}  // extern "C"
