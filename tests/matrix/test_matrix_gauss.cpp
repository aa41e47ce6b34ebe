// Determinant, solve and inverse against results computed by hand:
// pivoting, several right-hand sides, 1x1, in place, strided blocks,
// singular (exact and within the tolerance), near-singular but regular,
// badly scaled, not finite, and the workspace checks.
#include <cerrno>
#include <cfloat>
#include <cmath>
#include <limits>
#include <vector>

#include "matrix_util.hpp"

namespace chm::test {
namespace {

#define EXPECT_FAIL(call, status, code)                                 \
    do {                                                                \
        EXPECT_EQ((call), (status));                                    \
        EXPECT_EQ(chm_mat_last_code(), (code)) << chm_mat_last_error(); \
    } while (0)

struct Work {
    std::vector<double> w;
    explicit Work(uint32_t n) : w(CHM_MAT_WORK(n)) {}
    double* p() { return w.data(); }
    size_t n() const { return w.size(); }
};

TEST(MatrixGauss, Determinant) {
    Work ws(3);
    double d = 0;
    Mat a(2, 2, {1, 2, 3, 4});
    ASSERT_EQ(chm_mat_det(&a.v, &d, ws.p(), ws.n()), 0);
    EXPECT_NEAR(d, -2, 1e-15);
    Mat t(3, 3, {2, -1, 0, -1, 2, -1, 0, -1, 2}, 5);
    ASSERT_EQ(chm_mat_det(&t.v, &d, ws.p(), ws.n()), 0);
    EXPECT_NEAR(d, 4, 1e-14);
    Mat swap(2, 2, {0, 1, 1, 0});  // needs a row interchange: the sign flips
    ASSERT_EQ(chm_mat_det(&swap.v, &d, ws.p(), ws.n()), 0);
    EXPECT_EQ(d, -1);
    Mat perm(3, 3, {0, 0, 2, 0, 3, 0, 5, 0, 0});  // -(2 * 3 * 5)
    ASSERT_EQ(chm_mat_det(&perm.v, &d, ws.p(), ws.n()), 0);
    EXPECT_EQ(d, -30);
    Mat one(1, 1, {-7.5});
    ASSERT_EQ(chm_mat_det(&one.v, &d, ws.p(), ws.n()), 0);
    EXPECT_EQ(d, -7.5);
    EXPECT_TRUE(equal(t, {2, -1, 0, -1, 2, -1, 0, -1, 2}));  // the input is untouched
}

TEST(MatrixGauss, SingularDeterminantIsZeroNotAnError) {
    Work ws(3);
    double d = 99;
    Mat dep(2, 2, {1, 2, 2, 4});
    ASSERT_EQ(chm_mat_det(&dep.v, &d, ws.p(), ws.n()), 0);
    EXPECT_EQ(d, 0);
    Mat zero(3, 3);
    d = 99;
    ASSERT_EQ(chm_mat_det(&zero.v, &d, ws.p(), ws.n()), 0);
    EXPECT_EQ(d, 0);
    // Rank 2 up to rounding: the last pivot is rounding error, not exactly
    // zero, and falls within the tolerance.
    Mat r2(3, 3, {1, 2, 3, 4, 5, 6, 7, 8, 9});
    d = 99;
    ASSERT_EQ(chm_mat_det(&r2.v, &d, ws.p(), ws.n()), 0);
    EXPECT_EQ(d, 0);
    // Exactly, det = 6 * 2^-50 (not 0), inside the tolerance.
    Mat near(2, 2, {1, 2, 3, std::nextafter(6.0, 7.0)});
    d = 99;
    ASSERT_EQ(chm_mat_det(&near.v, &d, ws.p(), ws.n()), 0);
    EXPECT_EQ(d, 0);
}

TEST(MatrixGauss, Solve) {
    Work ws(3);
    Mat a(2, 2, {2, 1, 1, 3});
    Mat b(2, 1, {4, 7}), x(2, 1);
    ASSERT_EQ(chm_mat_solve(&a.v, &b.v, &x.v, ws.p(), ws.n()), 0);
    EXPECT_TRUE(equal(x, {1, 2}, 1e-15));
    Mat p(2, 2, {0, 1, 1, 0}), pb(2, 1, {2, 3});  // pivoting: a zero first pivot
    ASSERT_EQ(chm_mat_solve(&p.v, &pb.v, &x.v, ws.p(), ws.n()), 0);
    EXPECT_TRUE(equal(x, {3, 2}));
    // Two right-hand sides at once, x exactly b (solved in place).
    Mat t(3, 3, {2, -1, 0, -1, 2, -1, 0, -1, 2});
    // t * (1, 1, 1) = (1, 0, 1) and t * (4, 4, 4) = (4, 0, 4).
    Mat tb(3, 2, {1, 4, 0, 0, 1, 4});
    ASSERT_EQ(chm_mat_solve(&t.v, &tb.v, &tb.v, ws.p(), ws.n()), 0);
    EXPECT_TRUE(equal(tb, {1, 4, 1, 4, 1, 4}, 1e-14));
    Mat one(1, 1, {2}), ob(1, 1, {6}), ox(1, 1);
    ASSERT_EQ(chm_mat_solve(&one.v, &ob.v, &ox.v, ws.p(), ws.n()), 0);
    EXPECT_TRUE(equal(ox, {3}));
    EXPECT_TRUE(equal(a, {2, 1, 1, 3}));
    EXPECT_TRUE(equal(b, {4, 7}));
}

TEST(MatrixGauss, SolveIntoTheMatrixItselfAndOnBlocks) {
    Work ws(2);
    // x exactly a: a is copied into the workspace first.
    Mat a(2, 2, {2, 1, 1, 3}), b(2, 2, {4, 2, 7, 1});
    ASSERT_EQ(chm_mat_solve(&a.v, &b.v, &a.v, ws.p(), ws.n()), 0);
    EXPECT_TRUE(equal(a, {1, 1, 2, 0}, 1e-15));
    // A system stored as blocks of one augmented matrix [A | b | x].
    Mat aug(2, 4, {2, 1, 4, 0, 1, 3, 7, 0}, 6);
    chm_mat_t A, B, X;
    ASSERT_EQ(chm_mat_block(&A, &aug.v, 0, 0, 2, 2), 0);
    ASSERT_EQ(chm_mat_block(&B, &aug.v, 0, 2, 2, 1), 0);
    ASSERT_EQ(chm_mat_block(&X, &aug.v, 0, 3, 2, 1), 0);
    ASSERT_EQ(chm_mat_solve(&A, &B, &X, ws.p(), ws.n()), 0);
    EXPECT_TRUE(equal(aug, {2, 1, 4, 1, 1, 3, 7, 2}, 1e-15));
    // x overlapping b without being b: refused.
    chm_mat_t X2;
    ASSERT_EQ(chm_mat_block(&X2, &aug.v, 0, 2, 2, 2), 0);
    Mat wide(2, 2, {1, 0, 0, 1});
    chm_mat_t B2;
    ASSERT_EQ(chm_mat_block(&B2, &aug.v, 0, 1, 2, 2), 0);
    EXPECT_FAIL(chm_mat_solve(&wide.v, &B2, &X2, ws.p(), ws.n()), -EINVAL, CHM_EMAT_ALIAS);
    EXPECT_STREQ(chm_mat_last_error(),
                 "chm_mat_solve: 2x2: x overlaps b without being the same view");
}

TEST(MatrixGauss, SingularSystemsAreReportedWithNothingWritten) {
    Work ws(3);
    Mat dep(2, 2, {1, 2, 2, 4}), b(2, 1, {1, 2}), x(2, 1, {5, 5});
    EXPECT_FAIL(chm_mat_solve(&dep.v, &b.v, &x.v, ws.p(), ws.n()), -EDOM, CHM_EMAT_SINGULAR);
    EXPECT_TRUE(equal(x, {5, 5}));
    EXPECT_FAIL(chm_mat_solve(&dep.v, &b.v, &b.v, ws.p(), ws.n()), -EDOM, CHM_EMAT_SINGULAR);
    EXPECT_TRUE(equal(b, {1, 2}));  // x was b: still b
    EXPECT_FAIL(chm_mat_inverse(&dep.v, &dep.v, ws.p(), ws.n()), -EDOM, CHM_EMAT_SINGULAR);
    EXPECT_TRUE(equal(dep, {1, 2, 2, 4}));  // in place: a is still a
    EXPECT_STREQ(chm_mat_last_error(),
                 "chm_mat_inverse: 2x2 matrix singular: column 1's pivot 0 is within the "
                 "tolerance 2.73e-12");
    Mat r2(3, 3, {1, 2, 3, 4, 5, 6, 7, 8, 9}), b3(3, 1, {1, 1, 1}), x3(3, 1);
    EXPECT_FAIL(chm_mat_solve(&r2.v, &b3.v, &x3.v, ws.p(), ws.n()), -EDOM, CHM_EMAT_SINGULAR);
    Mat inv(3, 3);
    EXPECT_FAIL(chm_mat_inverse(&r2.v, &inv.v, ws.p(), ws.n()), -EDOM, CHM_EMAT_SINGULAR);
    EXPECT_TRUE(equal(inv, {0, 0, 0, 0, 0, 0, 0, 0, 0}));
    Mat zero(1, 1), z1(1, 1, {3});
    EXPECT_FAIL(chm_mat_solve(&zero.v, &z1.v, &z1.v, ws.p(), ws.n()), -EDOM, CHM_EMAT_SINGULAR);
    EXPECT_STREQ(chm_mat_last_error(),
                 "chm_mat_solve: 1x1 matrix singular: column 0's pivot 0 is within the "
                 "tolerance 0");
    // Not exactly singular (det = 6 * 2^-50) but within the tolerance.
    Mat near(2, 2, {1, 2, 3, std::nextafter(6.0, 7.0)}), inv2(2, 2);
    EXPECT_FAIL(chm_mat_inverse(&near.v, &inv2.v, ws.p(), ws.n()), -EDOM, CHM_EMAT_SINGULAR);
}

TEST(MatrixGauss, NearSingularButRegularAndBadlyScaledAreSolved) {
    Work ws(3);
    // det = 1e-10: ill-conditioned (about 4e10), but far from the tolerance.
    Mat a(2, 2, {1, 1, 1, 1 + 1e-10}), b(2, 1, {2, 2 + 1e-10}), x(2, 1);
    ASSERT_EQ(chm_mat_solve(&a.v, &b.v, &x.v, ws.p(), ws.n()), 0);
    EXPECT_TRUE(equal(x, {1, 1}, 1e-5));
    double d = 0;
    ASSERT_EQ(chm_mat_det(&a.v, &d, ws.p(), ws.n()), 0);
    EXPECT_NEAR(d, 1e-10, 1e-16);
    // The tolerance is relative: a tiny and a huge diagonal are regular.
    Mat tiny(3, 3, {1e-200, 0, 0, 0, 2e-200, 0, 0, 0, 4e-200}), inv(3, 3);
    ASSERT_EQ(chm_mat_inverse(&tiny.v, &inv.v, ws.p(), ws.n()), 0);
    EXPECT_NEAR(inv(0, 0) / 1e200, 1, 1e-15);
    EXPECT_NEAR(inv(1, 1) / 5e199, 1, 1e-15);
    EXPECT_NEAR(inv(2, 2) / 2.5e199, 1, 1e-15);
    EXPECT_EQ(inv(0, 1), 0);
    Mat huge(2, 2, {1e300, 1e300, 0, 1e300}), hb(2, 1, {2e300, 1e300}), hx(2, 1);
    ASSERT_EQ(chm_mat_solve(&huge.v, &hb.v, &hx.v, ws.p(), ws.n()), 0);
    EXPECT_TRUE(equal(hx, {1, 1}, 1e-15));
}

TEST(MatrixGauss, Inverse) {
    Work ws(3);
    Mat t(3, 3, {2, -1, 0, -1, 2, -1, 0, -1, 2}), inv(3, 3, 0, 4);
    ASSERT_EQ(chm_mat_inverse(&t.v, &inv.v, ws.p(), ws.n()), 0);
    EXPECT_TRUE(equal(inv, {0.75, 0.5, 0.25, 0.5, 1, 0.5, 0.25, 0.5, 0.75}, 1e-15));
    ASSERT_EQ(chm_mat_inverse(&t.v, &t.v, ws.p(), ws.n()), 0);  // in place
    EXPECT_TRUE(equal(t, {0.75, 0.5, 0.25, 0.5, 1, 0.5, 0.25, 0.5, 0.75}, 1e-15));
    Mat p(2, 2, {0, 2, 4, 0}), pi(2, 2);
    ASSERT_EQ(chm_mat_inverse(&p.v, &pi.v, ws.p(), ws.n()), 0);
    EXPECT_TRUE(equal(pi, {0, 0.25, 0.5, 0}));
    Mat one(1, 1, {4});
    ASSERT_EQ(chm_mat_inverse(&one.v, &one.v, ws.p(), ws.n()), 0);
    EXPECT_TRUE(equal(one, {0.25}));
    // out overlapping a partly is fine too: a is in the workspace by then.
    Mat m(2, 3, {2, 0, 0, 0, 4, 0});
    chm_mat_t A, O;
    ASSERT_EQ(chm_mat_block(&A, &m.v, 0, 0, 2, 2), 0);
    ASSERT_EQ(chm_mat_block(&O, &m.v, 0, 1, 2, 2), 0);
    ASSERT_EQ(chm_mat_inverse(&A, &O, ws.p(), ws.n()), 0);
    EXPECT_TRUE(equal(m, {2, 0.5, 0, 0, 0, 0.25}));
}

TEST(MatrixGauss, NotFiniteInputsAreRefusedBeforeAnythingIsWritten) {
    Work ws(2);
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double inf = std::numeric_limits<double>::infinity();
    Mat a(2, 2, {1, nan, 0, 1}), b(2, 1, {1, 1}), x(2, 1, {8, 8});
    double d = 5;
    EXPECT_FAIL(chm_mat_det(&a.v, &d, ws.p(), ws.n()), -EDOM, CHM_EMAT_NOTFINITE);
    EXPECT_EQ(d, 5);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_det: a (2x2) holds a NaN or an infinity");
    EXPECT_FAIL(chm_mat_solve(&a.v, &b.v, &x.v, ws.p(), ws.n()), -EDOM, CHM_EMAT_NOTFINITE);
    EXPECT_FAIL(chm_mat_inverse(&a.v, &a.v, ws.p(), ws.n()), -EDOM, CHM_EMAT_NOTFINITE);
    Mat good(2, 2, {1, 0, 0, 1}), binf(2, 1, {1, -inf});
    EXPECT_FAIL(chm_mat_solve(&good.v, &binf.v, &x.v, ws.p(), ws.n()), -EDOM, CHM_EMAT_NOTFINITE);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_solve: b (2x1) holds a NaN or an infinity");
    EXPECT_TRUE(equal(x, {8, 8}));
}

TEST(MatrixGauss, WorkspaceAndShapeChecks) {
    Work ws(3);
    Mat a(3, 3, {1, 0, 0, 0, 1, 0, 0, 0, 1}), b(3, 1), x(3, 1);
    double d = 0;
    EXPECT_FAIL(chm_mat_det(&a.v, &d, nullptr, 12), -EINVAL, CHM_EMAT_WORK);
    EXPECT_FAIL(chm_mat_det(&a.v, &d, ws.p(), ws.n() - 1), -EINVAL, CHM_EMAT_WORK);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_det: 3x3: workspace of 11 doubles, 12 needed");
    EXPECT_FAIL(chm_mat_det(&a.v, nullptr, ws.p(), ws.n()), -EINVAL, CHM_EMAT_ARG);
    // The workspace inside a matrix of the call.
    std::vector<double> big(40, 0.0);
    chm_mat_t in;
    ASSERT_EQ(chm_mat_view(&in, big.data() + 10, 3, 3), 0);
    EXPECT_FAIL(chm_mat_inverse(&a.v, &in, big.data(), 12), -EINVAL, CHM_EMAT_WORK);
    EXPECT_STREQ(chm_mat_last_error(),
                 "chm_mat_inverse: 3x3: workspace overlaps a matrix of the call");
    EXPECT_EQ(chm_mat_inverse(&a.v, &in, big.data(), 10), -EINVAL);  // too small
    EXPECT_EQ(chm_mat_inverse(&a.v, &in, big.data() + 19, 21), 0);   // just past it
    EXPECT_FAIL(chm_mat_solve(&a.v, &b.v, &x.v, b.v.data, 12), -EINVAL, CHM_EMAT_WORK);

    Mat r(2, 3);
    EXPECT_FAIL(chm_mat_det(&r.v, &d, ws.p(), ws.n()), -EINVAL, CHM_EMAT_DIM);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_det: a is 2x3, not square");
    EXPECT_FAIL(chm_mat_solve(&r.v, &b.v, &x.v, ws.p(), ws.n()), -EINVAL, CHM_EMAT_DIM);
    Mat b2(2, 1);
    EXPECT_FAIL(chm_mat_solve(&a.v, &b2.v, &x.v, ws.p(), ws.n()), -EINVAL, CHM_EMAT_DIM);
    EXPECT_STREQ(chm_mat_last_error(),
                 "chm_mat_solve: 3x3 a, 2x1 b, 3x1 x: b and x must be 3x1");
    Mat x2(3, 2);
    EXPECT_FAIL(chm_mat_solve(&a.v, &b.v, &x2.v, ws.p(), ws.n()), -EINVAL, CHM_EMAT_DIM);
    Mat o2(2, 2);
    EXPECT_FAIL(chm_mat_inverse(&a.v, &o2.v, ws.p(), ws.n()), -EINVAL, CHM_EMAT_DIM);
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_inverse: a is 3x3, out 2x2");
    EXPECT_TRUE(equal(x, {0, 0, 0}));
}

}  // namespace
}  // namespace chm::test
