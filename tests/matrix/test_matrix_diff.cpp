// Differential tests: thousands of random matrices of random shapes,
// strides and offsets, every operation against a naive reference written
// here (triple-loop product, cofactor expansion, Gauss-Jordan in long
// double), with tolerances scaled by the operands (and, for solve and
// inverse, by the condition number). Random rank-deficient matrices must be
// found singular. The overlap rule behind aliasing is checked against a
// brute-force element comparison. Fixed seeds: a failure reproduces.
// CHM_MAT_DIFF_CASES sets the number of random cases per test.
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <random>
#include <set>
#include <vector>

#include "lib/matrix/matrix.hpp"
#include "matrix_util.hpp"

namespace chm::test {
namespace {

int cases() {
    const char* e = std::getenv("CHM_MAT_DIFF_CASES");
    return e ? std::max(1, std::atoi(e)) : 3000;
}

using LMat = std::vector<std::vector<long double>>;

// got is the double nearest to want, give or take the last bit: m68k's FPU
// computes in 80 bits and rounds twice (to 64 bits, then to 53) where the
// library's code may round once, so one ulp apart is the same result.
::testing::AssertionResult same_double(double got, long double want) {
    if (std::fabs(got - want) <= DBL_EPSILON * std::fabs(want)) return ::testing::AssertionSuccess();
    return ::testing::AssertionFailure() << got << " vs " << double(want);
}

struct Rng {
    std::mt19937_64 g;
    explicit Rng(uint64_t seed) : g(seed) {}
    uint32_t dim(uint32_t hi) { return uint32_t(g() % hi) + 1; }
    double value() { return std::uniform_real_distribution<double>(-10, 10)(g); }
    int small() { return int(g() % 11) - 5; }
    // A rows x cols matrix at a random stride (up to 3 spare columns).
    Mat mat(uint32_t rows, uint32_t cols) {
        Mat m(rows, cols, cols + uint32_t(g() % 4));
        for (uint32_t i = 0; i < rows; ++i)
            for (uint32_t j = 0; j < cols; ++j) m(i, j) = value();
        return m;
    }
};

LMat to_l(const Mat& m) {
    LMat r(m.v.rows, std::vector<long double>(m.v.cols));
    for (uint32_t i = 0; i < m.v.rows; ++i)
        for (uint32_t j = 0; j < m.v.cols; ++j) r[i][j] = m(i, j);
    return r;
}

long double max_abs(const Mat& m) {
    long double r = 0;
    for (uint32_t i = 0; i < m.v.rows; ++i)
        for (uint32_t j = 0; j < m.v.cols; ++j) r = std::max(r, std::fabs((long double)m(i, j)));
    return r;
}

long double cofactor_det(const LMat& a) {
    const size_t n = a.size();
    if (n == 1) return a[0][0];
    long double d = 0;
    for (size_t c = 0; c < n; ++c) {
        LMat minor(n - 1);
        for (size_t i = 1; i < n; ++i)
            for (size_t j = 0; j < n; ++j)
                if (j != c) minor[i - 1].push_back(a[i][j]);
        d += ((c % 2) ? -1 : 1) * a[0][c] * cofactor_det(minor);
    }
    return d;
}

// Gauss-Jordan with partial pivoting in long double on [a | b]: returns
// false when a pivot is exactly zero. b becomes a^-1 b; det is returned.
bool gauss_jordan(LMat a, LMat& b, long double* det) {
    const size_t n = a.size();
    long double d = 1;
    for (size_t c = 0; c < n; ++c) {
        size_t p = c;
        for (size_t r = c + 1; r < n; ++r)
            if (std::fabs(a[r][c]) > std::fabs(a[p][c])) p = r;
        if (a[p][c] == 0) return false;
        if (p != c) std::swap(a[p], a[c]), std::swap(b[p], b[c]), d = -d;
        d *= a[c][c];
        for (size_t r = 0; r < n; ++r) {
            if (r == c) continue;
            const long double f = a[r][c] / a[c][c];
            for (size_t j = c; j < n; ++j) a[r][j] -= f * a[c][j];
            for (size_t j = 0; j < b[r].size(); ++j) b[r][j] -= f * b[c][j];
        }
    }
    for (size_t r = 0; r < n; ++r)
        for (auto& v : b[r]) v /= a[r][r];
    *det = d;
    return true;
}

LMat identity(size_t n) {
    LMat r(n, std::vector<long double>(n, 0));
    for (size_t i = 0; i < n; ++i) r[i][i] = 1;
    return r;
}

long double inf_norm(const LMat& a) {
    long double r = 0;
    for (const auto& row : a) {
        long double s = 0;
        for (auto v : row) s += std::fabs(v);
        r = std::max(r, s);
    }
    return r;
}

TEST(MatrixDiff, ElementwiseTransposeAndProducts) {
    Rng rng(0x6d61747269780001);
    for (int t = 0; t < cases(); ++t) {
        const uint32_t m = rng.dim(t % 10 == 0 ? 24 : 7), k = rng.dim(7), n = rng.dim(7);
        Mat a = rng.mat(m, k), b = rng.mat(m, k), c = rng.mat(k, n);
        Mat sum(m, k, k + 2), diff(m, k), sc(m, k), tr(k, m, m + 1), prod(m, n, n + 3);
        const double s = rng.value();
        ASSERT_EQ(chm_mat_add(&a.v, &b.v, &sum.v), 0);
        ASSERT_EQ(chm_mat_sub(&a.v, &b.v, &diff.v), 0);
        ASSERT_EQ(chm_mat_scale(&a.v, s, &sc.v), 0);
        ASSERT_EQ(chm_mat_transpose(&a.v, &tr.v), 0);
        ASSERT_EQ(chm_mat_mul(&a.v, &c.v, &prod.v), 0);
        for (uint32_t i = 0; i < m; ++i)
            for (uint32_t j = 0; j < k; ++j) {
                ASSERT_TRUE(same_double(sum(i, j), (long double)a(i, j) + b(i, j)));
                ASSERT_TRUE(same_double(diff(i, j), (long double)a(i, j) - b(i, j)));
                ASSERT_TRUE(same_double(sc(i, j), (long double)s * a(i, j)));
                ASSERT_EQ(tr(j, i), a(i, j));
            }
        const long double tol = 4 * k * DBL_EPSILON * max_abs(a) * max_abs(c);
        for (uint32_t i = 0; i < m; ++i)
            for (uint32_t j = 0; j < n; ++j) {
                long double ref = 0;
                for (uint32_t l = 0; l < k; ++l) ref += (long double)a(i, l) * c(l, j);
                ASSERT_LE(std::fabs(prod(i, j) - ref), tol) << t << ": " << m << "x" << k << "x" << n;
            }
        ASSERT_TRUE(sum.guards_intact() && diff.guards_intact() && sc.guards_intact() &&
                    tr.guards_intact() && prod.guards_intact());
    }
}

TEST(MatrixDiff, DotCrossNorms) {
    Rng rng(0x6d61747269780002);
    for (int t = 0; t < cases(); ++t) {
        const uint32_t n = rng.dim(t % 10 == 0 ? 40 : 8);
        Mat u = rng.mat(n, 1), w = rng.g() % 2 ? rng.mat(1, n) : rng.mat(n, 1);
        double got = 0;
        ASSERT_EQ(chm_mat_dot(&u.v, &w.v, &got), 0);
        long double ref = 0;
        for (uint32_t i = 0; i < n; ++i)
            ref += (long double)u(i, 0) * (w.v.cols == 1 ? w(i, 0) : w(0, i));
        ASSERT_LE(std::fabs(got - ref), 4 * n * DBL_EPSILON * max_abs(u) * max_abs(w));

        Mat x = rng.mat(3, 1), y = rng.mat(1, 3), z(3, 1);
        ASSERT_EQ(chm_mat_cross(&x.v, &y.v, &z.v), 0);
        const long double X[3] = {x(0, 0), x(1, 0), x(2, 0)}, Y[3] = {y(0, 0), y(0, 1), y(0, 2)};
        const long double Z[3] = {X[1] * Y[2] - X[2] * Y[1], X[2] * Y[0] - X[0] * Y[2],
                                  X[0] * Y[1] - X[1] * Y[0]};
        for (int i = 0; i < 3; ++i)
            ASSERT_LE(std::fabs(z(i, 0) - Z[i]), 4 * DBL_EPSILON * max_abs(x) * max_abs(y));

        const uint32_t r = rng.dim(8), c = rng.dim(8);
        Mat a = rng.mat(r, c);
        const LMat la = to_l(a);
        long double fro = 0, one = 0, inf = inf_norm(la), mx = max_abs(a);
        for (uint32_t j = 0; j < c; ++j) {
            long double s = 0;
            for (uint32_t i = 0; i < r; ++i) s += std::fabs(la[i][j]), fro += la[i][j] * la[i][j];
            one = std::max(one, s);
        }
        fro = std::sqrt(fro);
        const long double want[4] = {fro, one, inf, mx};
        for (int kind = 0; kind < 4; ++kind) {
            ASSERT_EQ(chm_mat_norm(&a.v, chm_mat_norm_kind(kind), &got), 0);
            ASSERT_LE(std::fabs(got - want[kind]), 4 * r * c * DBL_EPSILON * want[kind]) << kind;
        }
    }
}

TEST(MatrixDiff, DeterminantSolveInverse) {
    Rng rng(0x6d61747269780003);
    std::vector<double> work(CHM_MAT_WORK(16));
    for (int t = 0; t < cases(); ++t) {
        const uint32_t n = rng.dim(t % 10 == 0 ? 16 : 6), k = rng.dim(3);
        Mat a = rng.mat(n, n), b = rng.mat(n, k), x(n, k, k + 1), inv(n, n, n + 2);
        const LMat la = to_l(a);
        LMat lx = to_l(b), linv = identity(n);
        long double ref_det = 0;
        ASSERT_TRUE(gauss_jordan(la, lx, &ref_det));
        ASSERT_TRUE(gauss_jordan(la, linv, &ref_det));
        if (n <= 6) ref_det = cofactor_det(la);
        const long double cond = inf_norm(la) * inf_norm(linv);

        double det = 0;
        ASSERT_EQ(chm_mat_det(&a.v, &det, work.data(), work.size()), 0);
        // Hadamard's bound on |det| scales the error of its terms.
        long double hadamard = 1;
        for (const auto& row : la) {
            long double s = 0;
            for (auto v : row) s += v * v;
            hadamard *= std::sqrt(s);
        }
        ASSERT_LE(std::fabs(det - ref_det), 64 * n * DBL_EPSILON * hadamard * std::min<long double>(cond, 1e6))
            << t << ": n " << n << " det " << det << " ref " << (double)ref_det;

        ASSERT_EQ(chm_mat_solve(&a.v, &b.v, &x.v, work.data(), work.size()), 0)
            << chm_mat_last_error();
        ASSERT_EQ(chm_mat_inverse(&a.v, &inv.v, work.data(), work.size()), 0);
        const long double tol = 16 * n * DBL_EPSILON * cond;
        long double xnorm = 0;
        for (const auto& row : lx)
            for (auto v : row) xnorm = std::max(xnorm, std::fabs(v));
        for (uint32_t i = 0; i < n; ++i) {
            for (uint32_t j = 0; j < k; ++j)
                ASSERT_LE(std::fabs(x(i, j) - lx[i][j]), tol * xnorm) << t << " cond " << (double)cond;
            for (uint32_t j = 0; j < n; ++j)
                ASSERT_LE(std::fabs(inv(i, j) - linv[i][j]), tol * inf_norm(linv)) << t;
        }
        ASSERT_TRUE(x.guards_intact() && inv.guards_intact());
    }
}

TEST(MatrixDiff, RankDeficientMatricesAreSingular) {
    Rng rng(0x6d61747269780004);
    std::vector<double> work(CHM_MAT_WORK(8));
    for (int t = 0; t < cases(); ++t) {
        const uint32_t n = rng.dim(7) + 1;
        // Integer rows; one row an integer combination of two others, so the
        // dependence is exact and only the elimination rounds.
        Mat a(n, n), b(n, 1), x(n, 1, {7});
        for (uint32_t i = 0; i < n; ++i) {
            b(i, 0) = rng.small();
            for (uint32_t j = 0; j < n; ++j) a(i, j) = rng.small();
        }
        const uint32_t dst = uint32_t(rng.g() % n), p = (dst + 1) % n, q = (dst + 2) % n;
        const int cp = rng.small(), cq = rng.small();
        for (uint32_t j = 0; j < n; ++j) a(dst, j) = cp * a(p, j) + (n > 2 ? cq * a(q, j) : 0);
        double det = 1;
        ASSERT_EQ(chm_mat_det(&a.v, &det, work.data(), work.size()), 0);
        ASSERT_EQ(det, 0) << t << ": n " << n;
        ASSERT_EQ(chm_mat_solve(&a.v, &b.v, &x.v, work.data(), work.size()), -EDOM) << t;
        ASSERT_EQ(chm_mat_last_code(), CHM_EMAT_SINGULAR);
        ASSERT_EQ(x(0, 0), 7);  // untouched
        ASSERT_EQ(chm_mat_inverse(&a.v, &a.v, work.data(), work.size()), -EDOM) << t;
    }
}

// Brute force: the sets of addresses two views show.
std::set<const double*> elements(const chm_mat_t& m) {
    std::set<const double*> s;
    for (uint32_t i = 0; i < m.rows; ++i)
        for (uint32_t j = 0; j < m.cols; ++j) s.insert(&CHM_MAT_AT(&m, i, j));
    return s;
}

TEST(MatrixDiff, OverlapMatchesTheElementsShared) {
    Rng rng(0x6d61747269780005);
    double buf[96];
    int exact = 0;
    for (int t = 0; t < 20 * cases(); ++t) {
        chm_mat_t v[2];
        for (auto& m : v) {
            m.rows = rng.dim(4);
            m.cols = rng.dim(6);
            m.stride = rng.g() % 3 == 0 ? m.cols + uint32_t(rng.g() % 4) : 6;
            m.data = buf + rng.g() % 40;
        }
        const auto ea = elements(v[0]), eb = elements(v[1]);
        bool shared = false;
        for (auto* p : ea) shared = shared || eb.count(p);
        const bool got = chm::mat::overlap(v[0], v[1]);
        ASSERT_EQ(got, chm::mat::overlap(v[1], v[0])) << t;
        const bool one_grid = v[0].rows == 1 && v[1].rows == 1 ? true
                              : v[0].rows > 1 && v[1].rows > 1
                                  ? v[0].stride == v[1].stride
                                  : (v[0].rows == 1 ? v[0].cols <= v[1].stride
                                                    : v[1].cols <= v[0].stride);
        if (one_grid) {
            ++exact;
            ASSERT_EQ(got, shared) << t;
        } else if (shared) {
            ASSERT_TRUE(got) << t;  // conservative, never a miss
        }
    }
    EXPECT_GT(exact, cases());
}

}  // namespace
}  // namespace chm::test
