/* Chimera: what every public header shares about status returns.
 *
 * Every call that can fail returns 0 (or a count, a length, a handle) on
 * success and a negative errno-style status on failure; chm_err_last()
 * (err.h) says what went wrong. Such calls are declared CHM_CHECK: with
 * GCC and Clang, a caller that drops the status gets a warning
 * (warn_unused_result), since an unchecked failure is how a control
 * program goes on with a half-done step. A program that uses global error
 * handling (chm_err_global, err.h), where a failure becomes an error
 * signal and needs no check, may define CHM_ALLOW_UNCHECKED before the
 * first include; a single call may be cast to (void).
 *
 * Not marked: calls that never fail (counts, settings), the loop's own
 * timing calls chm_task_wait_period and chm_task_pause_until (their only
 * failures are a user signal's -EINTR and a bug, which global handling
 * raises), and chm_err_invoke (called to raise, not for its status). */
#ifndef CHIMERA_STATUS_H
#define CHIMERA_STATUS_H

/* C++17 and C23 [[nodiscard]] (a cast to (void) silences it); older C with
 * GCC or Clang, warn_unused_result (GCC then wants the status tested, or
 * `(void)!call`). */
#if defined(CHM_ALLOW_UNCHECKED)
#define CHM_CHECK
#elif defined(__cplusplus) && __cplusplus >= 201703L
#define CHM_CHECK [[nodiscard]]
#elif !defined(__cplusplus) && defined(__STDC_VERSION__) && __STDC_VERSION__ > 201710L
#define CHM_CHECK [[nodiscard]]
#elif defined(__GNUC__) || defined(__clang__)
#define CHM_CHECK __attribute__((warn_unused_result))
#else
#define CHM_CHECK
#endif

#endif /* CHIMERA_STATUS_H */
