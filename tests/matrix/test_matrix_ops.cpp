// Every operation against results computed by hand: square and not, 1x1,
// strided blocks of larger matrices, in-place and refused aliasing,
// singular and near-singular systems, and each refusal's status, code and
// message. Every result's guards show nothing outside the view was written.
#include <cerrno>
#include <cfloat>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "matrix_util.hpp"

namespace chm::test {
namespace {

#define EXPECT_FAIL(call, status, code)                    \
    do {                                                   \
        EXPECT_EQ((call), (status));                       \
        EXPECT_EQ(chm_mat_last_code(), (code)) << chm_mat_last_error(); \
    } while (0)

// ------------------------------------------------------------------ views

TEST(MatrixViews, ViewStrideVectorAndBlock) {
    double d[12];
    for (int i = 0; i < 12; ++i) d[i] = i;
    chm_mat_t m, b, v;
    ASSERT_EQ(chm_mat_view(&m, d, 3, 4), 0);
    EXPECT_EQ(m.stride, 4u);
    EXPECT_EQ(CHM_MAT_AT(&m, 2, 1), 9);
    ASSERT_EQ(chm_mat_block(&b, &m, 1, 2, 2, 2), 0);
    EXPECT_EQ(b.data, d + 6);
    EXPECT_EQ(b.stride, 4u);
    EXPECT_EQ(CHM_MAT_AT(&b, 1, 1), 11);
    ASSERT_EQ(chm_mat_view_stride(&m, d, 2, 3, 6), 0);
    EXPECT_EQ(CHM_MAT_AT(&m, 1, 2), 8);
    ASSERT_EQ(chm_mat_vector(&v, d + 1, 5), 0);
    EXPECT_EQ(v.rows, 5u);
    EXPECT_EQ(v.cols, 1u);
    EXPECT_EQ(CHM_MAT_AT(&v, 4, 0), 5);
}

TEST(MatrixViews, BadViewsAreRefusedAndLeaveTheOutputAlone) {
    double d[4] = {};
    chm_mat_t m{d, 7, 7, 7};
    const chm_mat_t before = m;
    EXPECT_FAIL(chm_mat_view(&m, nullptr, 2, 2), -EINVAL, CHM_EMAT_ARG);
    EXPECT_FAIL(chm_mat_view(&m, d, 0, 2), -EINVAL, CHM_EMAT_ARG);
    EXPECT_FAIL(chm_mat_view(&m, d, 2, 0), -EINVAL, CHM_EMAT_ARG);
    EXPECT_FAIL(chm_mat_view(nullptr, d, 2, 2), -EINVAL, CHM_EMAT_ARG);
    EXPECT_FAIL(chm_mat_view_stride(&m, d, 2, 3, 2), -EINVAL, CHM_EMAT_ARG);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_view_stride: data: stride 2 below its 3 columns");
    // Larger than any address space (2^64 doubles and more).
    EXPECT_FAIL(chm_mat_view(&m, d, UINT32_MAX, UINT32_MAX), -EINVAL, CHM_EMAT_ARG);
    EXPECT_EQ(std::memcmp(&m, &before, sizeof m), 0);

    chm_mat_t big, blk{};
    ASSERT_EQ(chm_mat_view(&big, d, 2, 2), 0);
    EXPECT_FAIL(chm_mat_block(&blk, &big, 1, 1, 2, 1), -EINVAL, CHM_EMAT_RANGE);
    EXPECT_STREQ(chm_mat_last_error(),
                 "chm_mat_block: m: 2x1 block at (1, 1) outside its 2x2 matrix");
    EXPECT_FAIL(chm_mat_block(&blk, &big, UINT32_MAX, 0, 2, 1), -EINVAL, CHM_EMAT_RANGE);
    EXPECT_FAIL(chm_mat_block(&blk, &big, 0, 0, 0, 1), -EINVAL, CHM_EMAT_ARG);
    EXPECT_FAIL(chm_mat_block(nullptr, &big, 0, 0, 1, 1), -EINVAL, CHM_EMAT_ARG);
    const chm_mat_t bad{d, 2, 2, 1};
    EXPECT_FAIL(chm_mat_block(&blk, &bad, 0, 0, 1, 1), -EINVAL, CHM_EMAT_ARG);
    EXPECT_EQ(blk.data, nullptr);
    // Every operation checks the views it is given.
    EXPECT_FAIL(chm_mat_fill(&bad, 1), -EINVAL, CHM_EMAT_ARG);
    EXPECT_FAIL(chm_mat_add(&big, nullptr, &big), -EINVAL, CHM_EMAT_ARG);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_add: b: NULL view");
    const chm_mat_t empty{d, 0, 2, 2};
    EXPECT_FAIL(chm_mat_mul(&big, &big, &empty), -EINVAL, CHM_EMAT_ARG);
    EXPECT_STREQ(chm_mat_last_error(),
                 "chm_mat_mul: out: 0x2 view (rows and columns start at 1)");
}

// ------------------------------------------------------- copy and fill

TEST(MatrixCopy, CopySubcopyFillIdentity) {
    Mat a(2, 3, {1, 2, 3, 4, 5, 6});
    Mat c(2, 3, 5);
    ASSERT_EQ(chm_mat_copy(&a.v, &c.v), 0);
    EXPECT_TRUE(equal(c, {1, 2, 3, 4, 5, 6}));
    EXPECT_EQ(chm_mat_copy(&c.v, &c.v), 0);  // the same view: nothing to do
    EXPECT_TRUE(equal(c, {1, 2, 3, 4, 5, 6}));

    Mat big(4, 4, 6);
    ASSERT_EQ(chm_mat_fill(&big.v, 0), 0);
    ASSERT_EQ(chm_mat_subcopy(&a.v, 0, 1, 2, 2, &big.v, 1, 2), 0);
    EXPECT_TRUE(equal(big, {0, 0, 0, 0, 0, 0, 2, 3, 0, 0, 5, 6, 0, 0, 0, 0}));
    EXPECT_FAIL(chm_mat_subcopy(&a.v, 1, 1, 2, 2, &big.v, 0, 0), -EINVAL, CHM_EMAT_RANGE);
    EXPECT_STREQ(chm_mat_last_error(),
                 "chm_mat_subcopy: src: 2x2 block at (1, 1) outside its 2x3 matrix");
    EXPECT_FAIL(chm_mat_subcopy(&a.v, 0, 0, 2, 2, &big.v, 3, 3), -EINVAL, CHM_EMAT_RANGE);
    EXPECT_FAIL(chm_mat_copy(&a.v, &big.v), -EINVAL, CHM_EMAT_DIM);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_copy: 2x3 into 4x4: dimensions differ");

    Mat r(2, 3, 0, 5);
    ASSERT_EQ(chm_mat_identity(&r.v), 0);
    EXPECT_TRUE(equal(r, {1, 0, 0, 0, 1, 0}));
    ASSERT_EQ(chm_mat_fill(&r.v, -2.5), 0);
    EXPECT_TRUE(equal(r, {-2.5, -2.5, -2.5, -2.5, -2.5, -2.5}));
}

TEST(MatrixCopy, BlocksSharingNoElementMayCopyBlocksSharingOneMayNot) {
    // The left and right halves of a 2x4 matrix interleave in memory (their
    // address ranges meet) but share no element.
    Mat m(2, 4, {1, 2, 3, 4, 5, 6, 7, 8});
    ASSERT_EQ(chm_mat_subcopy(&m.v, 0, 0, 2, 2, &m.v, 0, 2), 0);
    EXPECT_TRUE(equal(m, {1, 2, 1, 2, 5, 6, 5, 6}));
    // Columns 0..1 into 1..2: column 1 is in both.
    EXPECT_FAIL(chm_mat_subcopy(&m.v, 0, 0, 2, 2, &m.v, 0, 1), -EINVAL, CHM_EMAT_ALIAS);
    EXPECT_TRUE(equal(m, {1, 2, 1, 2, 5, 6, 5, 6}));
    // Views of one stride decide by element: column 3 of rows 0..1 (memory
    // offsets 3 and 7) and a 2x1 of stride 4 from offset 4 (4 and 8) have
    // meeting address ranges; a 2x2 from offset 3 (3, 4, 7, 8) wraps across
    // rows and shares offset 4 with the second.
    Mat g(3, 4, {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11});
    chm_mat_t x, y, z;
    ASSERT_EQ(chm_mat_block(&x, &g.v, 0, 3, 2, 1), 0);
    ASSERT_EQ(chm_mat_view_stride(&y, g.v.data + 4, 2, 1, 4), 0);
    EXPECT_EQ(chm_mat_copy(&x, &y), 0) << chm_mat_last_error();
    EXPECT_TRUE(equal(g, {0, 1, 2, 3, 3, 5, 6, 7, 7, 9, 10, 11}));
    ASSERT_EQ(chm_mat_view_stride(&z, g.v.data + 3, 2, 2, 4), 0);
    chm_mat_t w;  // offsets 4, 5, 8, 9
    ASSERT_EQ(chm_mat_block(&w, &g.v, 1, 0, 2, 2), 0);
    EXPECT_FAIL(chm_mat_copy(&z, &w), -EINVAL, CHM_EMAT_ALIAS);
    ASSERT_EQ(chm_mat_block(&w, &g.v, 1, 1, 2, 2), 0);  // offsets 5, 6, 9, 10
    EXPECT_EQ(chm_mat_copy(&z, &w), 0) << chm_mat_last_error();
    EXPECT_TRUE(equal(g, {0, 1, 2, 3, 3, 3, 3, 7, 7, 7, 7, 11}));
    // Different strides: meeting address ranges count as overlap.
    chm_mat_t col;
    ASSERT_EQ(chm_mat_view_stride(&col, g.v.data + 4, 2, 1, 1), 0);  // offsets 4, 5
    chm_mat_t far;
    ASSERT_EQ(chm_mat_view_stride(&far, g.v.data + 2, 2, 1, 6), 0);  // offsets 2, 8
    EXPECT_FAIL(chm_mat_copy(&far, &col), -EINVAL, CHM_EMAT_ALIAS);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_copy: 2x1: destination overlaps the source");
}

// ------------------------------------------------------ arithmetic

TEST(MatrixArith, AddSubScale) {
    Mat a(2, 3, {1, 2, 3, 4, 5, 6});
    Mat b(2, 3, {10, 20, 30, 40, 50, 60}, 7);
    Mat out(2, 3, 4);
    ASSERT_EQ(chm_mat_add(&a.v, &b.v, &out.v), 0);
    EXPECT_TRUE(equal(out, {11, 22, 33, 44, 55, 66}));
    ASSERT_EQ(chm_mat_sub(&b.v, &a.v, &out.v), 0);
    EXPECT_TRUE(equal(out, {9, 18, 27, 36, 45, 54}));
    ASSERT_EQ(chm_mat_scale(&a.v, 0.5, &out.v), 0);
    EXPECT_TRUE(equal(out, {0.5, 1, 1.5, 2, 2.5, 3}));
    // In place: out is exactly an input.
    ASSERT_EQ(chm_mat_add(&a.v, &b.v, &a.v), 0);
    EXPECT_TRUE(equal(a, {11, 22, 33, 44, 55, 66}));
    ASSERT_EQ(chm_mat_sub(&a.v, &b.v, &b.v), 0);
    EXPECT_TRUE(equal(b, {1, 2, 3, 4, 5, 6}));
    ASSERT_EQ(chm_mat_scale(&b.v, -2, &b.v), 0);
    EXPECT_TRUE(equal(b, {-2, -4, -6, -8, -10, -12}));
    ASSERT_EQ(chm_mat_add(&b.v, &b.v, &b.v), 0);
    EXPECT_TRUE(equal(b, {-4, -8, -12, -16, -20, -24}));

    Mat wrong(3, 2);
    EXPECT_FAIL(chm_mat_add(&a.v, &wrong.v, &out.v), -EINVAL, CHM_EMAT_DIM);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_add: 2x3 plus 3x2 into 2x3: dimensions differ");
    EXPECT_FAIL(chm_mat_sub(&a.v, &b.v, &wrong.v), -EINVAL, CHM_EMAT_DIM);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_sub: 2x3 minus 2x3 into 3x2: dimensions differ");
    EXPECT_FAIL(chm_mat_scale(&a.v, 2, &wrong.v), -EINVAL, CHM_EMAT_DIM);
    EXPECT_TRUE(equal(wrong, {0, 0, 0, 0, 0, 0}));
}

TEST(MatrixArith, ElementwiseOutputOverlappingAnInputIsRefused) {
    double d[8] = {1, 2, 3, 4, 5, 6, 7, 8};
    chm_mat_t a, shifted;
    ASSERT_EQ(chm_mat_view(&a, d, 2, 2), 0);
    ASSERT_EQ(chm_mat_view(&shifted, d + 1, 2, 2), 0);
    EXPECT_FAIL(chm_mat_add(&a, &a, &shifted), -EINVAL, CHM_EMAT_ALIAS);
    EXPECT_STREQ(chm_mat_last_error(),
                 "chm_mat_add: 2x2: out overlaps a without being the same view");
    EXPECT_FAIL(chm_mat_scale(&shifted, 2, &a), -EINVAL, CHM_EMAT_ALIAS);
    // The same memory seen with another stride is not the same view.
    chm_mat_t other;
    ASSERT_EQ(chm_mat_view_stride(&other, d, 2, 2, 3), 0);
    EXPECT_FAIL(chm_mat_sub(&a, &a, &other), -EINVAL, CHM_EMAT_ALIAS);
    for (int i = 0; i < 8; ++i) EXPECT_EQ(d[i], i + 1);
}

TEST(MatrixArith, Multiply) {
    Mat a(2, 3, {1, 2, 3, 4, 5, 6});
    Mat c(3, 2, {7, 8, 9, 10, 11, 12}, 5);
    Mat out(2, 2, 3);
    ASSERT_EQ(chm_mat_mul(&a.v, &c.v, &out.v), 0);
    EXPECT_TRUE(equal(out, {58, 64, 139, 154}));
    Mat big(3, 3, 4);
    ASSERT_EQ(chm_mat_mul(&c.v, &a.v, &big.v), 0);
    EXPECT_TRUE(equal(big, {39, 54, 69, 49, 68, 87, 59, 82, 105}));
    // Row times column and column times row.
    Mat r(1, 3, {1, 2, 3}), col(3, 1, {4, 5, 6}), one(1, 1), outer(3, 3);
    ASSERT_EQ(chm_mat_mul(&r.v, &col.v, &one.v), 0);
    EXPECT_TRUE(equal(one, {32}));
    ASSERT_EQ(chm_mat_mul(&col.v, &r.v, &outer.v), 0);
    EXPECT_TRUE(equal(outer, {4, 8, 12, 5, 10, 15, 6, 12, 18}));
    Mat x(1, 1, {3}), y(1, 1, {-4});
    ASSERT_EQ(chm_mat_mul(&x.v, &y.v, &one.v), 0);
    EXPECT_TRUE(equal(one, {-12}));

    Mat b34(3, 4), o34(3, 4);
    EXPECT_FAIL(chm_mat_mul(&b34.v, &b34.v, &o34.v), -EINVAL, CHM_EMAT_DIM);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_mul: 3x4 times 3x4: inner dimensions differ");
    EXPECT_FAIL(chm_mat_mul(&a.v, &c.v, &big.v), -EINVAL, CHM_EMAT_DIM);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_mul: 2x3 times 3x2 is 2x2, out is 3x3");
    // Into an input: refused, even when the shapes allow it.
    Mat s(2, 2, {1, 2, 3, 4}), t(2, 2, {5, 6, 7, 8});
    EXPECT_FAIL(chm_mat_mul(&s.v, &t.v, &s.v), -EINVAL, CHM_EMAT_ALIAS);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_mul: 2x2 times 2x2: out overlaps a");
    EXPECT_FAIL(chm_mat_mul(&s.v, &t.v, &t.v), -EINVAL, CHM_EMAT_ALIAS);
    EXPECT_TRUE(equal(s, {1, 2, 3, 4}));
    EXPECT_TRUE(equal(t, {5, 6, 7, 8}));
}

TEST(MatrixArith, OnBlocksOfLargerMatrices) {
    // The 2x2 blocks at (1, 1) of two 4x5 matrices, and an output block:
    // only the blocks' elements change.
    Mat m(4, 5, {0, 0, 0, 0, 0, 0, 1, 2, 0, 0, 0, 3, 4, 0, 0, 0, 0, 0, 0, 0}, 7);
    Mat n(4, 5, {9, 9, 9, 9, 9, 9, 5, 6, 9, 9, 9, 7, 8, 9, 9, 9, 9, 9, 9, 9});
    chm_mat_t bm, bn, bo;
    ASSERT_EQ(chm_mat_block(&bm, &m.v, 1, 1, 2, 2), 0);
    ASSERT_EQ(chm_mat_block(&bn, &n.v, 1, 1, 2, 2), 0);
    Mat o(3, 6, 0, 4);
    ASSERT_EQ(chm_mat_block(&bo, &o.v, 1, 3, 2, 2), 0);
    ASSERT_EQ(chm_mat_mul(&bm, &bn, &bo), 0);
    EXPECT_TRUE(equal(o, {0, 0, 0, 0, 0, 0, 0, 0, 0, 19, 22, 0, 0, 0, 0, 43, 50, 0}));
    ASSERT_EQ(chm_mat_add(&bm, &bn, &bm), 0);
    EXPECT_TRUE(equal(m, {0, 0, 0, 0, 0, 0, 6, 8, 0, 0, 0, 10, 12, 0, 0, 0, 0, 0, 0, 0}));
    ASSERT_EQ(chm_mat_transpose(&bn, &bn), 0);
    EXPECT_TRUE(equal(n, {9, 9, 9, 9, 9, 9, 5, 7, 9, 9, 9, 6, 8, 9, 9, 9, 9, 9, 9, 9}));
    // A column of a matrix is a vector.
    chm_mat_t c0, c4;
    ASSERT_EQ(chm_mat_block(&c0, &n.v, 0, 0, 3, 1), 0);
    ASSERT_EQ(chm_mat_block(&c4, &n.v, 1, 1, 1, 3), 0);
    double dot = 0;
    ASSERT_EQ(chm_mat_dot(&c0, &c4, &dot), 0);
    EXPECT_EQ(dot, 9 * 5 + 9 * 7 + 9 * 9);
}

TEST(MatrixArith, Transpose) {
    Mat a(2, 3, {1, 2, 3, 4, 5, 6});
    Mat t(3, 2, 0, 4);
    ASSERT_EQ(chm_mat_transpose(&a.v, &t.v), 0);
    EXPECT_TRUE(equal(t, {1, 4, 2, 5, 3, 6}));
    Mat s(3, 3, {1, 2, 3, 4, 5, 6, 7, 8, 9}, 5);
    ASSERT_EQ(chm_mat_transpose(&s.v, &s.v), 0);  // square, in place
    EXPECT_TRUE(equal(s, {1, 4, 7, 2, 5, 8, 3, 6, 9}));
    Mat one(1, 1, {7});
    ASSERT_EQ(chm_mat_transpose(&one.v, &one.v), 0);
    EXPECT_TRUE(equal(one, {7}));
    EXPECT_FAIL(chm_mat_transpose(&a.v, &a.v), -EINVAL, CHM_EMAT_DIM);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_transpose: 2x3 transposed is 3x2, out is 2x3");
    // The same memory seen as 3x2: not the same view, refused.
    chm_mat_t over;
    ASSERT_EQ(chm_mat_view(&over, a.v.data, 3, 2), 0);
    EXPECT_FAIL(chm_mat_transpose(&a.v, &over), -EINVAL, CHM_EMAT_ALIAS);
    EXPECT_TRUE(equal(a, {1, 2, 3, 4, 5, 6}));
}

TEST(MatrixArith, DotCrossNorm) {
    Mat u(3, 1, {1, 2, 3}), w(1, 3, {4, -5, 6}, 8);
    double r = 0;
    ASSERT_EQ(chm_mat_dot(&u.v, &w.v, &r), 0);
    EXPECT_EQ(r, 12);
    Mat c(3, 1);
    Mat x(1, 3, {1, 2, 3}), y(3, 1, {4, 5, 6});
    ASSERT_EQ(chm_mat_cross(&x.v, &y.v, &c.v), 0);
    EXPECT_TRUE(equal(c, {-3, 6, -3}));
    Mat e1(3, 1, {1, 0, 0}), e2(3, 1, {0, 1, 0});
    ASSERT_EQ(chm_mat_cross(&e1.v, &e2.v, &e1.v), 0);  // into an input
    EXPECT_TRUE(equal(e1, {0, 0, 1}));
    ASSERT_EQ(chm_mat_cross(&y.v, &y.v, &y.v), 0);
    EXPECT_TRUE(equal(y, {0, 0, 0}));

    Mat m(2, 3);
    EXPECT_FAIL(chm_mat_dot(&u.v, &m.v, &r), -EINVAL, CHM_EMAT_DIM);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_dot: b is 2x3, not a vector");
    Mat four(4, 1);
    EXPECT_FAIL(chm_mat_dot(&u.v, &four.v, &r), -EINVAL, CHM_EMAT_DIM);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_dot: 3x1 dot 4x1: lengths 3 and 4 differ");
    EXPECT_FAIL(chm_mat_dot(&u.v, &u.v, nullptr), -EINVAL, CHM_EMAT_ARG);
    EXPECT_FAIL(chm_mat_cross(&u.v, &four.v, &c.v), -EINVAL, CHM_EMAT_DIM);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_cross: b is 4x1, not a three-element vector");

    Mat a(2, 2, {1, -2, -3, 4});
    ASSERT_EQ(chm_mat_norm(&a.v, CHM_MAT_NORM_FRO, &r), 0);
    EXPECT_DOUBLE_EQ(r, std::sqrt(30.0));
    ASSERT_EQ(chm_mat_norm(&a.v, CHM_MAT_NORM_ONE, &r), 0);
    EXPECT_EQ(r, 6);
    ASSERT_EQ(chm_mat_norm(&a.v, CHM_MAT_NORM_INF, &r), 0);
    EXPECT_EQ(r, 7);
    ASSERT_EQ(chm_mat_norm(&a.v, CHM_MAT_NORM_MAX, &r), 0);
    EXPECT_EQ(r, 4);
    Mat v(2, 1, {3, -4});
    ASSERT_EQ(chm_mat_norm(&v.v, CHM_MAT_NORM_FRO, &r), 0);
    EXPECT_EQ(r, 5);
    // Scaled: the squares of 3e200 and 1e-200 * 3 overflow and underflow.
    Mat huge(2, 1, {3e200, -4e200}), tiny(1, 2, {3e-200, 4e-200});
    ASSERT_EQ(chm_mat_norm(&huge.v, CHM_MAT_NORM_FRO, &r), 0);
    EXPECT_NEAR(r / 5e200, 1, 1e-15);
    ASSERT_EQ(chm_mat_norm(&tiny.v, CHM_MAT_NORM_FRO, &r), 0);
    EXPECT_NEAR(r / 5e-200, 1, 1e-15);
    Mat zero(2, 2);
    ASSERT_EQ(chm_mat_norm(&zero.v, CHM_MAT_NORM_FRO, &r), 0);
    EXPECT_EQ(r, 0);
    Mat nan(1, 3, {1, std::numeric_limits<double>::quiet_NaN(), 9});
    for (int k = 0; k < 4; ++k) {
        ASSERT_EQ(chm_mat_norm(&nan.v, chm_mat_norm_kind(k), &r), 0);
        EXPECT_TRUE(std::isnan(r)) << k;
    }
    EXPECT_FAIL(chm_mat_norm(&a.v, chm_mat_norm_kind(4), &r), -EINVAL, CHM_EMAT_ARG);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_norm: unknown norm 4");
}

}  // namespace
}  // namespace chm::test
