/* Chimera matrix library: the matrix and vector arithmetic a control module
 * needs in its cycle (Jacobians, rotations, gains), as a C API over views of
 * the caller's memory.
 *
 * A view (chm_mat_t) describes rows x cols doubles stored row by row, row i
 * starting `stride` elements after row i-1. It owns nothing: it shows an
 * array, a struct member, a state variable's local copy, or a block of a
 * larger view (chm_mat_block), which is why the stride exists. A vector is
 * an n x 1 view (chm_mat_vector); dot, cross and the norms also take 1 x n.
 * No operation changes a view, only the elements it shows, so inputs and
 * outputs alike are passed as const chm_mat_t*.
 *
 * Nothing allocates: no call takes memory from the heap, and none keeps a
 * buffer larger than a few scalars on the stack, whatever the dimensions.
 * The products are computed coefficient by coefficient (no blocking into
 * scratch buffers); det, solve and inverse take the caller's workspace of
 * CHM_MAT_WORK(n) doubles. Every call takes time bounded by its dimensions
 * alone (no iteration to convergence), so its cost is known in advance.
 *
 * Aliasing. Element-wise operations (copy, add, sub, scale) accept an
 * output that is exactly an input view (same data, dimensions and stride):
 * `chm_mat_add(&x, &dx, &x)` updates x in place. The transpose of a square
 * view into itself is done in place; cross accepts any aliasing; solve and
 * inverse accept any overlap with a, and solve's x may be exactly b.
 * Any other overlap between an output and an input is refused with
 * -EINVAL (CHM_EMAT_ALIAS), and a workspace overlapping any matrix of the
 * call with -EINVAL (CHM_EMAT_WORK), before anything is written. Two
 * views with the same stride overlap when they share an element; two views
 * with different strides are taken as overlapping when their address
 * ranges intersect.
 *
 * Errors. Every call returns 0 or a negative errno-style status, and a
 * failed call has written nothing (but the workspace):
 *   -EINVAL  a bad argument or view, a dimension mismatch, a block outside
 *            its matrix, a refused overlap, a workspace too small;
 *   -EDOM    a singular matrix (solve, inverse), or a NaN or infinity in
 *            the input of det, solve or inverse.
 * After a failure, chm_err_last() names the call, the dimensions and
 * the problem ("chm_mat_mul: 3x4 times 3x4: inner dimensions differ") and
 * chm_mat_last_code() says which of the CHM_EMAT_* codes it was. With
 * global error handling on (chimera/err.h), the failure is also raised in
 * the calling task as the error signal (module "matrix", CHM_EMAT_*) after
 * the call has done its work; a handler that continues makes the call
 * return its status as when handling is off.
 *
 * Arithmetic follows IEEE 754 otherwise: a sum or product that overflows
 * is an infinity, not an error.
 *
 * Calling context: any thread or task, not a signal handler. Under the
 * interrupt mask a failure is only returned, never raised. Views and
 * workspaces shared between tasks need the caller's own locking. */
#ifndef CHIMERA_MATRIX_H
#define CHIMERA_MATRIX_H

#include "chimera/status.h"

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* A view: element (i, j) is data[i * stride + j], 0 <= i < rows,
 * 0 <= j < cols. Valid when data is not NULL, rows and cols are at least 1
 * and stride is at least cols. Build one with chm_mat_view or fill the
 * fields directly; every call checks the views it is given. */
typedef struct chm_mat {
    double* data;
    uint32_t rows;
    uint32_t cols;
    uint32_t stride; /* in elements, >= cols */
} chm_mat_t;

/* Element (i, j) of view m as an lvalue, unchecked. */
#define CHM_MAT_AT(m, i, j) ((m)->data[(size_t)(i) * (m)->stride + (size_t)(j)])

/* Doubles of workspace det, solve and inverse need for an n x n matrix:
 * its LU factors and the row interchanges. */
#define CHM_MAT_WORK(n) ((size_t)(n) * (size_t)(n) + (size_t)(n))

/* Codes of the error module "matrix" (chm_mat_err_module). */
#define CHM_EMAT_ARG 1       /* -EINVAL: NULL, malformed view, unknown norm */
#define CHM_EMAT_DIM 2       /* -EINVAL: dimensions do not fit the operation */
#define CHM_EMAT_RANGE 3     /* -EINVAL: a block reaches outside its matrix */
#define CHM_EMAT_ALIAS 4     /* -EINVAL: an output overlaps an input in a way
                              * the call does not handle */
#define CHM_EMAT_WORK 5      /* -EINVAL: workspace NULL, too small, or
                              * overlapping a matrix */
#define CHM_EMAT_SINGULAR 6  /* -EDOM: singular to working precision */
#define CHM_EMAT_NOTFINITE 7 /* -EDOM: a NaN or an infinity in the input */

/* ------------------------------------------------------------- views */

/* A view of rows x cols contiguous doubles at data (stride = cols).
 * Errors: -EINVAL (CHM_EMAT_ARG) m or data NULL, rows or cols 0, or the
 * view larger than the address space. */
CHM_CHECK int chm_mat_view(chm_mat_t* m, double* data, uint32_t rows, uint32_t cols);

/* The same with rows `stride` elements apart (a matrix padded per row, or
 * a block of a larger one). Errors: as chm_mat_view; -EINVAL (ARG) also
 * stride < cols. */
CHM_CHECK int chm_mat_view_stride(chm_mat_t* m, double* data, uint32_t rows, uint32_t cols,
                        uint32_t stride);

/* An n x 1 column vector of n contiguous doubles. Errors: as chm_mat_view. */
CHM_CHECK int chm_mat_vector(chm_mat_t* v, double* data, uint32_t n);

/* The rows x cols block of m whose top-left element is m(row, col), as a
 * view sharing m's elements and stride. Errors: -EINVAL (ARG) blk NULL, m
 * not a valid view, rows or cols 0; -EINVAL (RANGE) the block reaches
 * outside m. */
CHM_CHECK int chm_mat_block(chm_mat_t* blk, const chm_mat_t* m, uint32_t row, uint32_t col, uint32_t rows,
                  uint32_t cols);

/* ------------------------------------------------------ copy and fill */

/* dst = src. dst may be exactly src (nothing to do). Errors: -EINVAL (ARG)
 * a view invalid; (DIM) different dimensions; (ALIAS) dst overlaps src
 * without being the same view. */
CHM_CHECK int chm_mat_copy(const chm_mat_t* src, const chm_mat_t* dst);

/* Sub-copy: the rows x cols block of src at (src_row, src_col) into dst at
 * (dst_row, dst_col). Errors: -EINVAL (ARG) a view invalid, rows or cols 0;
 * (RANGE) either block reaches outside its matrix; (ALIAS) the two blocks
 * overlap without being the same elements. */
CHM_CHECK int chm_mat_subcopy(const chm_mat_t* src, uint32_t src_row, uint32_t src_col, uint32_t rows,
                    uint32_t cols, const chm_mat_t* dst, uint32_t dst_row, uint32_t dst_col);

/* Every element of m set to value. Errors: -EINVAL (ARG) m invalid. */
CHM_CHECK int chm_mat_fill(const chm_mat_t* m, double value);

/* m = I (ones on the diagonal, zeros elsewhere; m need not be square).
 * Errors: -EINVAL (ARG) m invalid. */
CHM_CHECK int chm_mat_identity(const chm_mat_t* m);

/* ------------------------------------------------------- arithmetic */

/* out = a + b, out = a - b, element by element; out may be exactly a or b.
 * Errors: -EINVAL (ARG) a view invalid; (DIM) a, b and out not all of one
 * shape; (ALIAS) out overlaps a or b without being the same view. */
CHM_CHECK int chm_mat_add(const chm_mat_t* a, const chm_mat_t* b, const chm_mat_t* out);
CHM_CHECK int chm_mat_sub(const chm_mat_t* a, const chm_mat_t* b, const chm_mat_t* out);

/* out = s * a; out may be exactly a. Errors: as chm_mat_add. */
CHM_CHECK int chm_mat_scale(const chm_mat_t* a, double s, const chm_mat_t* out);

/* out = a * b: a is m x k, b is k x n, out is m x n. out must not overlap a
 * or b (the product reads every input element many times).
 * Errors: -EINVAL (ARG) a view invalid; (DIM) a's columns differ from b's
 * rows, or out is not m x n; (ALIAS) out overlaps a or b. */
CHM_CHECK int chm_mat_mul(const chm_mat_t* a, const chm_mat_t* b, const chm_mat_t* out);

/* out = a transposed: a is m x n, out n x m. A square a may be transposed
 * into itself (out exactly a); any other overlap is refused.
 * Errors: -EINVAL (ARG); (DIM) out not n x m; (ALIAS). */
CHM_CHECK int chm_mat_transpose(const chm_mat_t* a, const chm_mat_t* out);

/* *out = a . b: the sum of a[i] * b[i] over two vectors (n x 1 or 1 x n,
 * not necessarily both the same way) of one length n.
 * Errors: -EINVAL (ARG) a view invalid or out NULL; (DIM) a or b not a
 * vector, or of different lengths. */
CHM_CHECK int chm_mat_dot(const chm_mat_t* a, const chm_mat_t* b, double* out);

/* out = a x b for three-element vectors (3 x 1 or 1 x 3 each). Any of the
 * three may overlap: the inputs are read before out is written.
 * Errors: -EINVAL (ARG) a view invalid; (DIM) one of them not a
 * three-element vector. */
CHM_CHECK int chm_mat_cross(const chm_mat_t* a, const chm_mat_t* b, const chm_mat_t* out);

/* Which norm chm_mat_norm computes. */
enum chm_mat_norm_kind {
    CHM_MAT_NORM_FRO = 0, /* Frobenius: sqrt of the sum of squares; the
                           * Euclidean length of a vector */
    CHM_MAT_NORM_ONE = 1, /* the largest sum of |a(i,j)| down a column */
    CHM_MAT_NORM_INF = 2, /* the largest sum of |a(i,j)| along a row */
    CHM_MAT_NORM_MAX = 3  /* the largest |a(i,j)| */
};

/* *out = the norm `kind` of a. The Frobenius norm is computed with scaling,
 * so it neither overflows nor underflows where the result is representable.
 * Errors: -EINVAL (ARG) a invalid, out NULL or kind unknown. */
CHM_CHECK int chm_mat_norm(const chm_mat_t* a, enum chm_mat_norm_kind kind, double* out);

/* ------------------------------------------ Gaussian elimination
 *
 * det, solve and inverse eliminate with partial pivoting (each column's
 * largest remaining element is its pivot) in the caller's workspace: `work`
 * points to at least CHM_MAT_WORK(n) doubles (n x n + n for an n x n
 * matrix), overwritten, and must not overlap any matrix of the call. The
 * elimination is done in the workspace before any output is written, so a
 * singular matrix leaves the outputs (and an input they alias) untouched.
 *
 * A is taken as singular when a pivot's magnitude is at most
 *   CHM_MAT_PIVOT_TOL * n * DBL_EPSILON * ||A||inf
 * (||A||inf: the largest row sum of |A|). The tolerance scales with A, so
 * 1e-200 * I is regular. Rounding leaves the last pivots of an exactly
 * singular matrix not zero but up to a few hundred times n * DBL_EPSILON *
 * ||A||inf (measured over a million random integer matrices of rank n-1;
 * small earlier pivots amplify it), hence the factor. A regular matrix it
 * refuses is that close to singular (a condition number of order 1e12 and
 * beyond for small n): its solution would keep only a few correct digits,
 * nothing a controller should act on. The cost is O(n^3). */
#define CHM_MAT_PIVOT_TOL 1024.0

/* *out = det(a) for a square a. A singular a (a pivot within the tolerance)
 * gives exactly 0.0 and status 0: zero is the determinant of a singular
 * matrix, not an error. The product of the pivots may overflow to an
 * infinity or underflow to zero for large n with large or small elements.
 * Errors: -EINVAL (ARG) a invalid or out NULL; (DIM) a not square; (WORK)
 * work NULL, work_len < CHM_MAT_WORK(n), or work overlapping a; -EDOM
 * (NOTFINITE) a holds a NaN or an infinity. */
CHM_CHECK int chm_mat_det(const chm_mat_t* a, double* out, double* work, size_t work_len);

/* Solve a * x = b for x: a is n x n, b and x are n x k (k right-hand sides
 * at once). x may be exactly b (b is overwritten by the solution), and may
 * overlap a in any way (a is copied into the workspace first); any other
 * overlap of x with b is refused.
 * Errors: -EINVAL (ARG) a view invalid; (DIM) a not square, or b and x not
 * n x k alike; (ALIAS) x overlaps b without being b; (WORK) as
 * chm_mat_det; -EDOM (SINGULAR) a is singular within the tolerance; -EDOM
 * (NOTFINITE) a or b holds a NaN or an infinity. */
CHM_CHECK int chm_mat_solve(const chm_mat_t* a, const chm_mat_t* b, const chm_mat_t* x, double* work,
                  size_t work_len);

/* out = a^-1 for a square a. out may overlap a in any way, exactly a
 * included (inversion in place): a is copied into the workspace first.
 * Errors: -EINVAL (ARG); (DIM) a not square or out not a's size;
 * (WORK) as chm_mat_det; -EDOM (SINGULAR) a is singular within the
 * tolerance; -EDOM (NOTFINITE) a holds a NaN or an infinity. */
CHM_CHECK int chm_mat_inverse(const chm_mat_t* a, const chm_mat_t* out, double* work, size_t work_len);

/* ------------------------------------------------------------ errors */

/* The message of the last failing matrix call on this thread ("" if
 * none): the call, the dimensions and the problem.
 * chm_err_last() (err.h) gives the same text per task, whatever the
 * subsystem: use it; this call is kept for one release (CHANGELOG.md). */
const char* chm_mat_last_error(void);

/* Returns the CHM_EMAT_* code of the last failing matrix call on this
 * thread (0 if none). Never fails. */
int chm_mat_last_code(void);

/* The id of error module "matrix" (registered on first use: its codes are
 * the CHM_EMAT_* above), or a negative status from chm_err_module_register.
 * Error signals carry call = the failing function's name and detail = the
 * chm_err_last() message after that name. */
CHM_CHECK int chm_mat_err_module(void);

#ifdef __cplusplus
}
#endif
#endif /* CHIMERA_MATRIX_H */
