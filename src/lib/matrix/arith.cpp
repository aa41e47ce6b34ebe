// Element-wise arithmetic, products, transpose and norms over views. Every
// expression is evaluated coefficient by coefficient into the output: no
// Eigen temporary, no blocked product with scratch buffers.
#include <algorithm>
#include <cmath>
#include <limits>

#include "lib/matrix/matrix.hpp"

using chm::mat::check;
using chm::mat::fail;
using chm::mat::map;

namespace {

using VecMap = Eigen::Map<Eigen::VectorXd, Eigen::Unaligned, Eigen::InnerStride<>>;

bool is_vector(const chm_mat_t& v) { return v.rows == 1 || v.cols == 1; }
uint32_t length(const chm_mat_t& v) { return v.cols == 1 ? v.rows : v.cols; }

// A vector view (n x 1 or 1 x n) as an Eigen vector of its elements.
VecMap vec(const chm_mat_t& v) {
    return VecMap(v.data, length(v), Eigen::InnerStride<>(v.cols == 1 ? v.stride : 1));
}

enum class Op { add, sub, scale };

int elementwise(const char* call, Op op, const chm_mat_t* a, const chm_mat_t* b, double s,
                const chm_mat_t* out) {
    if (const int rc = check(call, "a", a)) return rc;
    if (op != Op::scale)
        if (const int rc = check(call, "b", b)) return rc;
    if (const int rc = check(call, "out", out)) return rc;
    const bool shape_b = op == Op::scale || (b->rows == a->rows && b->cols == a->cols);
    if (!shape_b || out->rows != a->rows || out->cols != a->cols) {
        if (op == Op::scale)
            return fail(call, CHM_EMAT_DIM, "%ux%u scaled into %ux%u: dimensions differ",
                        unsigned(a->rows), unsigned(a->cols), unsigned(out->rows),
                        unsigned(out->cols));
        return fail(call, CHM_EMAT_DIM, "%ux%u %s %ux%u into %ux%u: dimensions differ",
                    unsigned(a->rows), unsigned(a->cols), op == Op::add ? "plus" : "minus",
                    unsigned(b->rows), unsigned(b->cols), unsigned(out->rows),
                    unsigned(out->cols));
    }
    if (!chm::mat::elementwise_ok(*a, *out) || (op != Op::scale && !chm::mat::elementwise_ok(*b, *out)))
        return fail(call, CHM_EMAT_ALIAS, "%ux%u: out overlaps %s without being the same view",
                    unsigned(a->rows), unsigned(a->cols),
                    chm::mat::elementwise_ok(*a, *out) ? "b" : "a");
    // Each output coefficient is computed from the inputs' coefficients at
    // the same place, so out may be exactly an input.
    switch (op) {
    case Op::add: map(*out) = map(*a) + map(*b); break;
    case Op::sub: map(*out) = map(*a) - map(*b); break;
    case Op::scale: map(*out) = s * map(*a); break;
    }
    return 0;
}

// The Frobenius norm, scaled by the largest magnitude so that squaring
// neither overflows nor underflows.
double frobenius(const chm::mat::Map& m) {
    const double big = m.cwiseAbs().maxCoeff();
    if (big == 0 || !std::isfinite(big)) return big;
    return big * (m * (1.0 / big)).norm();
}

}  // namespace

extern "C" {

int chm_mat_add(const chm_mat_t* a, const chm_mat_t* b, const chm_mat_t* out) {
    return elementwise("chm_mat_add", Op::add, a, b, 0, out);
}

int chm_mat_sub(const chm_mat_t* a, const chm_mat_t* b, const chm_mat_t* out) {
    return elementwise("chm_mat_sub", Op::sub, a, b, 0, out);
}

int chm_mat_scale(const chm_mat_t* a, double s, const chm_mat_t* out) {
    return elementwise("chm_mat_scale", Op::scale, a, nullptr, s, out);
}

int chm_mat_mul(const chm_mat_t* a, const chm_mat_t* b, const chm_mat_t* out) {
    static const char* const call = "chm_mat_mul";
    if (const int rc = check(call, "a", a)) return rc;
    if (const int rc = check(call, "b", b)) return rc;
    if (const int rc = check(call, "out", out)) return rc;
    if (a->cols != b->rows)
        return fail(call, CHM_EMAT_DIM, "%ux%u times %ux%u: inner dimensions differ",
                    unsigned(a->rows), unsigned(a->cols), unsigned(b->rows), unsigned(b->cols));
    if (out->rows != a->rows || out->cols != b->cols)
        return fail(call, CHM_EMAT_DIM, "%ux%u times %ux%u is %ux%u, out is %ux%u",
                    unsigned(a->rows), unsigned(a->cols), unsigned(b->rows), unsigned(b->cols),
                    unsigned(a->rows), unsigned(b->cols), unsigned(out->rows),
                    unsigned(out->cols));
    if (chm::mat::overlap(*a, *out) || chm::mat::overlap(*b, *out))
        return fail(call, CHM_EMAT_ALIAS, "%ux%u times %ux%u: out overlaps %s", unsigned(a->rows),
                    unsigned(a->cols), unsigned(b->rows), unsigned(b->cols),
                    chm::mat::overlap(*a, *out) ? "a" : "b");
    // lazyProduct: a dot product per coefficient. Eigen's default product
    // would switch to its blocked kernel past small sizes, with scratch
    // buffers on the stack or the heap.
    map(*out).noalias() = map(*a).lazyProduct(map(*b));
    return 0;
}

int chm_mat_transpose(const chm_mat_t* a, const chm_mat_t* out) {
    static const char* const call = "chm_mat_transpose";
    if (const int rc = check(call, "a", a)) return rc;
    if (const int rc = check(call, "out", out)) return rc;
    if (out->rows != a->cols || out->cols != a->rows)
        return fail(call, CHM_EMAT_DIM, "%ux%u transposed is %ux%u, out is %ux%u",
                    unsigned(a->rows), unsigned(a->cols), unsigned(a->cols), unsigned(a->rows),
                    unsigned(out->rows), unsigned(out->cols));
    if (chm::mat::same(*a, *out)) {  // square, in place: swap across the diagonal
        auto m = map(*a);
        for (Eigen::Index i = 0; i < m.rows(); ++i)
            for (Eigen::Index j = i + 1; j < m.cols(); ++j) std::swap(m(i, j), m(j, i));
        return 0;
    }
    if (chm::mat::overlap(*a, *out))
        return fail(call, CHM_EMAT_ALIAS, "%ux%u: out overlaps a without being the same view",
                    unsigned(a->rows), unsigned(a->cols));
    map(*out) = map(*a).transpose();
    return 0;
}

int chm_mat_dot(const chm_mat_t* a, const chm_mat_t* b, double* out) {
    static const char* const call = "chm_mat_dot";
    if (const int rc = check(call, "a", a)) return rc;
    if (const int rc = check(call, "b", b)) return rc;
    if (!out) return fail(call, CHM_EMAT_ARG, "NULL result");
    if (!is_vector(*a) || !is_vector(*b))
        return fail(call, CHM_EMAT_DIM, "%s is %ux%u, not a vector", is_vector(*a) ? "b" : "a",
                    unsigned(is_vector(*a) ? b->rows : a->rows),
                    unsigned(is_vector(*a) ? b->cols : a->cols));
    if (length(*a) != length(*b))
        return fail(call, CHM_EMAT_DIM, "%ux%u dot %ux%u: lengths %u and %u differ",
                    unsigned(a->rows), unsigned(a->cols), unsigned(b->rows), unsigned(b->cols),
                    unsigned(length(*a)), unsigned(length(*b)));
    *out = vec(*a).dot(vec(*b));
    return 0;
}

int chm_mat_cross(const chm_mat_t* a, const chm_mat_t* b, const chm_mat_t* out) {
    static const char* const call = "chm_mat_cross";
    if (const int rc = check(call, "a", a)) return rc;
    if (const int rc = check(call, "b", b)) return rc;
    if (const int rc = check(call, "out", out)) return rc;
    const chm_mat_t* const v[3] = {a, b, out};
    static const char* const name[3] = {"a", "b", "out"};
    for (int i = 0; i < 3; ++i)
        if (!is_vector(*v[i]) || length(*v[i]) != 3)
            return fail(call, CHM_EMAT_DIM, "%s is %ux%u, not a three-element vector", name[i],
                        unsigned(v[i]->rows), unsigned(v[i]->cols));
    // Read everything first: out may overlap a or b in any way.
    const Eigen::Vector3d x = vec(*a), y = vec(*b);
    const Eigen::Vector3d z(x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2],
                            x[0] * y[1] - x[1] * y[0]);
    vec(*out) = z;
    return 0;
}

int chm_mat_norm(const chm_mat_t* a, enum chm_mat_norm_kind kind, double* out) {
    static const char* const call = "chm_mat_norm";
    if (const int rc = check(call, "a", a)) return rc;
    if (!out) return fail(call, CHM_EMAT_ARG, "NULL result");
    const auto m = map(*a);
    double r = 0;
    switch (kind) {
    case CHM_MAT_NORM_FRO: r = frobenius(m); break;
    case CHM_MAT_NORM_ONE:
        for (Eigen::Index j = 0; j < m.cols(); ++j) r = std::max(r, m.col(j).cwiseAbs().sum());
        break;
    case CHM_MAT_NORM_INF:
        for (Eigen::Index i = 0; i < m.rows(); ++i) r = std::max(r, m.row(i).cwiseAbs().sum());
        break;
    case CHM_MAT_NORM_MAX: r = m.cwiseAbs().maxCoeff(); break;
    default: return fail(call, CHM_EMAT_ARG, "unknown norm %d", int(kind));
    }
    // max() and maxCoeff() drop a NaN depending on where it stands.
    if (m.hasNaN()) r = std::numeric_limits<double>::quiet_NaN();
    *out = r;
    return 0;
}

}  // extern "C"
