// Helpers of the matrix suite: matrices that own their storage, laid out
// inside a larger buffer whose margins are checked afterwards (a call must
// never write outside its views).
#pragma once

#include <gtest/gtest.h>

#include <cstdint>
#include <initializer_list>
#include <vector>

#include "chimera/matrix.h"

namespace chm::test {

inline constexpr double kGuard = -12345.678;

// rows x cols doubles at row stride `stride`, with `pad` guard doubles
// before and after, and the stride's slack filled with guards too.
struct Mat {
    std::vector<double> buf;
    chm_mat_t v{};
    uint32_t pad;

    Mat(uint32_t rows, uint32_t cols, uint32_t stride = 0, uint32_t pad_ = 3) : pad(pad_) {
        if (stride == 0) stride = cols;
        buf.assign(size_t(rows) * stride + 2 * pad, kGuard);
        v = chm_mat_t{buf.data() + pad, rows, cols, stride};
        for (uint32_t i = 0; i < rows; ++i)
            for (uint32_t j = 0; j < cols; ++j) (*this)(i, j) = 0;
    }
    Mat(uint32_t rows, uint32_t cols, std::initializer_list<double> vals, uint32_t stride = 0)
        : Mat(rows, cols, stride) {
        auto it = vals.begin();
        for (uint32_t i = 0; i < rows; ++i)
            for (uint32_t j = 0; j < cols && it != vals.end(); ++j) (*this)(i, j) = *it++;
    }
    // v points into buf: a copy would show the original's elements. A move
    // keeps buf's storage, so v stays right.
    Mat(const Mat&) = delete;
    Mat& operator=(const Mat&) = delete;
    Mat(Mat&&) = default;
    double& operator()(uint32_t i, uint32_t j) { return CHM_MAT_AT(&v, i, j); }
    double operator()(uint32_t i, uint32_t j) const { return CHM_MAT_AT(&v, i, j); }

    // Every double outside the view still holds the guard value.
    bool guards_intact() const {
        for (size_t k = 0; k < buf.size(); ++k) {
            const long off = long(k) - long(pad);
            const bool inside = off >= 0 && off < long(v.rows) * long(v.stride) &&
                                uint32_t(off % v.stride) < v.cols;
            if (!inside && buf[k] != kGuard) return false;
        }
        return true;
    }
};

inline ::testing::AssertionResult equal(const Mat& m, std::initializer_list<double> want,
                                        double tol = 0) {
    auto it = want.begin();
    for (uint32_t i = 0; i < m.v.rows; ++i)
        for (uint32_t j = 0; j < m.v.cols; ++j, ++it) {
            if (it == want.end()) return ::testing::AssertionFailure() << "too few values";
            const double d = m(i, j) - *it;
            if (!(d <= tol && -d <= tol))
                return ::testing::AssertionFailure()
                       << "(" << i << ", " << j << ") is " << m(i, j) << ", want " << *it;
        }
    if (!m.guards_intact()) return ::testing::AssertionFailure() << "a guard was overwritten";
    return ::testing::AssertionSuccess();
}

}  // namespace chm::test
