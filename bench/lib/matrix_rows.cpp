// The matrix library (chimera/matrix.h) at a control loop's size, 6x6 (a
// six-joint arm's Jacobian), beside plain Eigen on fixed-size matrices
// doing the same work in the same run: the product, and a solve with
// partial pivoting (chm_mat_solve's LU into the caller's workspace and
// substitution, vs Eigen's PartialPivLU compute + solve). A compiler
// barrier per iteration keeps the loop-invariant work in the loop.
#include <Eigen/Core>
#include <Eigen/LU>

#include <stdexcept>
#include <string>

#include "../harness.hpp"
#include "chimera/matrix.h"

namespace chm::bench {
namespace {

using M6 = Eigen::Matrix<double, 6, 6, Eigen::RowMajor>;
using V6 = Eigen::Matrix<double, 6, 1>;

inline void barrier(const void* p) { asm volatile("" : : "r"(p) : "memory"); }

void check(int rc, const char* call) {
    if (rc != 0) throw std::runtime_error(std::string(call) + ": " + chm_mat_last_error());
}

void matrix_rows(Session& s) {
    Session::pin(s.cpu(0));
    M6 a, b, c;
    for (int i = 0; i < 6; ++i)
        for (int j = 0; j < 6; ++j) {
            a(i, j) = (i == j ? 10 : 0) + double((i * 7 + j * 3) % 5) - 2;
            b(i, j) = double((i * 5 + j * 11) % 7) - 3;
        }
    V6 rhs = V6::LinSpaced(-1, 1), x;
    double work[CHM_MAT_WORK(6)];
    chm_mat_t va, vb, vc, vr, vx;
    check(chm_mat_view(&va, a.data(), 6, 6), "chm_mat_view");
    check(chm_mat_view(&vb, b.data(), 6, 6), "chm_mat_view");
    check(chm_mat_view(&vc, c.data(), 6, 6), "chm_mat_view");
    check(chm_mat_vector(&vr, rhs.data(), 6), "chm_mat_vector");
    check(chm_mat_vector(&vx, x.data(), 6), "chm_mat_vector");
    const std::string where = "pinned " + s.cpu_name(0) + ", 6x6 doubles, row-major, cache-resident";

    s.time_ops("mat_mul_6x6", where + "; chm_mat_mul over views", [&](std::uint64_t n) {
        for (std::uint64_t i = 0; i < n; ++i) {
            check(chm_mat_mul(&va, &vb, &vc), "chm_mat_mul");
            barrier(c.data());
        }
    });
    s.time_ops("peer_eigen_mul_6x6", where + "; Eigen fixed-size c.noalias() = a * b",
               [&](std::uint64_t n) {
                   for (std::uint64_t i = 0; i < n; ++i) {
                       c.noalias() = a * b;
                       barrier(c.data());
                   }
               });
    s.time_ops("mat_solve_6x6", where + "; chm_mat_solve, one right-hand side", [&](std::uint64_t n) {
        for (std::uint64_t i = 0; i < n; ++i) {
            check(chm_mat_solve(&va, &vr, &vx, work, CHM_MAT_WORK(6)), "chm_mat_solve");
            barrier(x.data());
        }
    });
    s.time_ops("peer_eigen_lu_solve_6x6", where + "; Eigen PartialPivLU<6x6> compute + solve",
               [&](std::uint64_t n) {
                   for (std::uint64_t i = 0; i < n; ++i) {
                       barrier(a.data());
                       x.noalias() = Eigen::PartialPivLU<M6>(a).solve(rhs);
                       barrier(x.data());
                   }
               });
}
CHM_BENCH_MEASUREMENT(matrix_rows, "mat_mul_6x6", "peer_eigen_mul_6x6", "mat_solve_6x6",
                      "peer_eigen_lu_solve_6x6");

}  // namespace
}  // namespace chm::bench
