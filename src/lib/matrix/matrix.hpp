// The matrix library's internals (chimera/matrix.h): Eigen maps over views,
// the checks every call makes, the overlap test behind the aliasing rules,
// and the one reporting point.
#pragma once

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>

#include "chimera/matrix.h"

namespace chm::mat {

// Row-major like the views; the stride is the outer one, the inner is 1.
using Dense = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using Map = Eigen::Map<Dense, Eigen::Unaligned, Eigen::OuterStride<>>;

inline Map map(const chm_mat_t& m) {
    return Map(m.data, m.rows, m.cols, Eigen::OuterStride<>(m.stride));
}

// Records "call: message" for chm_mat_last_error() and the code, raises the
// error signal when the calling task has global handling on, and returns
// the status of `code` (-EINVAL or -EDOM). Called as a call's last act, so
// a handler may abort the task or jump to a mark: nothing is held.
int fail(const char* call, int code, const char* fmt, ...) __attribute__((format(printf, 3, 4)));

// 0, or fail() with CHM_EMAT_ARG naming `what` ("a", "out") when `m` is
// NULL or not a valid view.
int check(const char* call, const char* what, const chm_mat_t* m);

// Whether a and b share an element: exact for equal strides, by address
// range otherwise (a conservative answer).
bool overlap(const chm_mat_t& a, const chm_mat_t& b);

// The same data, dimensions and stride: the elements are the same ones.
inline bool same(const chm_mat_t& a, const chm_mat_t& b) {
    return a.data == b.data && a.rows == b.rows && a.cols == b.cols &&
           (a.rows == 1 || a.stride == b.stride);
}

// An output `out` an element-wise operation may write while reading `in`:
// the same elements, or none shared.
inline bool elementwise_ok(const chm_mat_t& in, const chm_mat_t& out) {
    return same(in, out) || !overlap(in, out);
}

// Whether m shares an element with the len doubles at p (a workspace).
bool overlap(const chm_mat_t& m, const double* p, std::size_t len);

}  // namespace chm::mat
