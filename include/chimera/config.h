/* Chimera configuration files: typed, range-checked reading of TOML
 * documents (state-variable tables, module descriptions, the layout of a
 * system), the error checking done here rather than by every caller.
 *
 * A document is opened from a file or parsed from a string, then read by
 * key path: dotted keys with array indices, e.g. "arm.gain",
 * "module[2].rate_hz", "module[0].inputs[1]", "limits.\"max.speed\"" (a
 * quoted segment may hold dots, not a double quote: there are no escapes;
 * "" is the root table). A getter returns the caller's default when the
 * key is absent; its require_ twin makes an absent key an error. A value
 * of the wrong type or out of range is always an error, never silently
 * replaced by the default.
 *
 * Every function returns 0 (chm_config_type: a type) or a negative
 * errno-style status. After an error, chm_err_last() gives a
 * message naming the place in the document:
 *     system.toml:12:11: module[1].rate_hz: expected an integer in [1, 10000], got integer 0
 *     system.toml:7:1: arm.gain: expected a number, got nothing (table 'arm' has no key 'gain')
 *     system.toml:3:1: unknown key 'gian' in table 'arm' (did you mean 'gain'?)
 * A missing key is placed at the table that should hold it.
 * Statuses: -EINVAL a caller bug (NULL argument, malformed key path,
 * min > max, a default outside its range); -ENOENT a required key is
 * absent (or, for chm_config_open, the file); -EBADMSG the document is
 * wrong: a syntax error, a value of the wrong type or out of range, an
 * unknown key; -ENOMEM out of memory. Exceptions never cross this API.
 *
 * A chm_config_t is read-only once made: any number of threads may read
 * the same one at the same time. The error message is per thread. */
#ifndef CHIMERA_CONFIG_H
#define CHIMERA_CONFIG_H

#include "chimera/status.h"

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct chm_config chm_config_t;

/* Types of values, from chm_config_type. */
enum chm_config_type {
    CHM_CONFIG_NONE = 0,   /* the key is absent */
    CHM_CONFIG_TABLE,
    CHM_CONFIG_ARRAY,
    CHM_CONFIG_STRING,
    CHM_CONFIG_INTEGER,
    CHM_CONFIG_FLOAT,
    CHM_CONFIG_BOOL,
    CHM_CONFIG_DATETIME,   /* a TOML date, time or date-time */
};

/* Read and parse the TOML file at `path` (at most 16 MiB); messages name
 * it by `path`. *out receives the document, to be freed with
 * chm_config_close. Errors: -EINVAL NULL argument; -ENOENT no such file;
 * -EACCES; -EISDIR; -EFBIG larger than 16 MiB; -EBADMSG a syntax error or
 * invalid UTF-8 (the message gives path:line:column and what is wrong);
 * -ENOMEM; other -errno from open/read. */
CHM_CHECK int chm_config_open(const char* path, chm_config_t** out);

/* Parse `len` bytes of TOML at `text` (need not end in NUL) named `name`
 * in messages (NULL: "<string>"). Errors: -EINVAL NULL text or out;
 * -EBADMSG a syntax error (name:line:column and what is wrong); -ENOMEM. */
CHM_CHECK int chm_config_parse(const char* text, size_t len, const char* name, chm_config_t** out);

/* Free a document (NULL: nothing). */
void chm_config_close(chm_config_t* cfg);

/* The name messages give the document: its path or parse name. */
const char* chm_config_name(const chm_config_t* cfg);

/* What the last failing chm_config_* call of this thread said, or "" when
 * none failed yet.
 * chm_err_last() (err.h) gives the same text per task, whatever the
 * subsystem: use it; this call is kept for one release (CHANGELOG.md). */
const char* chm_config_last_error(void);

/* The type of the value at `key` (an enum chm_config_type; CHM_CONFIG_NONE
 * when absent). Errors: -EINVAL NULL argument or malformed path;
 * -EBADMSG a step of the path goes through a value that is not a table
 * (or not an array, for an index). */
CHM_CHECK int chm_config_type(const chm_config_t* cfg, const char* key);

/* *n = the number of elements of the array, or of keys of the table, at
 * `key`; 0 when absent, so a missing [[module]] list is an empty one.
 * Errors: -EINVAL; -EBADMSG the value is neither an array nor a table, or
 * a step of the path is not a container. */
CHM_CHECK int chm_config_count(const chm_config_t* cfg, const char* key, size_t* n);

/* Copy the name of the index-th key of the table at `table` (in document
 * order) into buf (len bytes, NUL included). Errors: -EINVAL;
 * -ENOENT the table is absent or has index keys or fewer; -EBADMSG
 * `table` is not a table; -ENAMETOOLONG the key does not fit (the message
 * names it and its place). */
CHM_CHECK int chm_config_key(const chm_config_t* cfg, const char* table, size_t index, char* buf,
                   size_t len);

/* Refuse keys of the table at `table` that are not among the n names in
 * `allowed`: a misspelt key is a common bug that would otherwise leave a
 * setting silently at its default. Absent table: 0. The first unknown key
 * in document order is reported with its line and column, and the closest
 * allowed name when one is near. Errors: -EINVAL; -EBADMSG an unknown key,
 * or `table` is not a table. */
CHM_CHECK int chm_config_check_keys(const chm_config_t* cfg, const char* table, const char* const* allowed,
                          size_t n);

/* Write "name:line:column" of the value at `key` into buf; for an absent
 * key, of the table (or array) that should hold it. For callers that find
 * a document wrong in ways only they can judge. Errors: -EINVAL;
 * -EBADMSG a step of the path is not a container; -ENAMETOOLONG. */
CHM_CHECK int chm_config_where(const chm_config_t* cfg, const char* key, char* buf, size_t len);

/* Report a caller's own finding about the value at `key` in the house
 * format: sets chm_err_last() to "name:line:column: key: " and
 * the printf-formatted message, and returns -EBADMSG (or -EINVAL for a
 * NULL or malformed argument). */
CHM_CHECK int chm_config_error(const chm_config_t* cfg, const char* key, const char* fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

/* Booleans: TOML true or false, nothing else (no 0/1, no "yes"). *out is
 * 1 or 0. get: `def` (0 or 1) when absent. Errors: -EINVAL; -EBADMSG
 * another type; require: -ENOENT when absent. */
CHM_CHECK int chm_config_get_bool(const chm_config_t* cfg, const char* key, int def, int* out);
CHM_CHECK int chm_config_require_bool(const chm_config_t* cfg, const char* key, int* out);

/* Integers in [min, max]. A float, even 2.0, is refused: where an integer
 * is wanted a fraction is a mistake. Errors: -EINVAL (also min > max, or
 * def outside [min, max]); -EBADMSG another type or out of range;
 * require: -ENOENT when absent. */
CHM_CHECK int chm_config_get_int64(const chm_config_t* cfg, const char* key, int64_t def, int64_t min,
                         int64_t max, int64_t* out);
CHM_CHECK int chm_config_require_int64(const chm_config_t* cfg, const char* key, int64_t min, int64_t max,
                             int64_t* out);

/* Numbers in [min, max] (pass -INFINITY/INFINITY for no bound): a TOML
 * float or integer (an integer beyond 2^53 must be exact as a double).
 * NaN is always refused. Errors: -EINVAL (also NaN or min > max bounds, a
 * def outside them); -EBADMSG another type, NaN, or out of range;
 * require: -ENOENT when absent. */
CHM_CHECK int chm_config_get_double(const chm_config_t* cfg, const char* key, double def, double min,
                          double max, double* out);
CHM_CHECK int chm_config_require_double(const chm_config_t* cfg, const char* key, double min, double max,
                              double* out);

/* Strings, copied with their NUL into buf (len bytes): a string longer
 * than len - 1 bytes, or holding a NUL, is an error in the document (the
 * field's size is part of its type). get: `def` (NULL: "") when absent,
 * which must fit too. Errors: -EINVAL (NULL buf, len 0, def too long);
 * -EBADMSG another type, too long, or a NUL inside; require: -ENOENT. */
CHM_CHECK int chm_config_get_string(const chm_config_t* cfg, const char* key, const char* def, char* buf,
                          size_t len);
CHM_CHECK int chm_config_require_string(const chm_config_t* cfg, const char* key, char* buf, size_t len);

/* A string that must be one of the n names in `choices`: *out receives its
 * index. get: `def` (an index below n) when absent. Errors: -EINVAL (also
 * n == 0, a NULL choice, def >= n); -EBADMSG another type or another
 * string (the message lists the choices); require: -ENOENT. */
CHM_CHECK int chm_config_get_choice(const chm_config_t* cfg, const char* key, const char* const* choices,
                          size_t n, size_t def, size_t* out);
CHM_CHECK int chm_config_require_choice(const chm_config_t* cfg, const char* key,
                              const char* const* choices, size_t n, size_t* out);

/* A flat array of min_n..max_n numbers (integers or floats), each in
 * [lo, hi], into out (room for max_n); *n receives the count. An absent
 * key is an empty array: an error (-ENOENT) unless min_n is 0. Nothing
 * is written to out unless all is well. Errors: -EINVAL (NULL out or n,
 * min_n > max_n, bad bounds); -EBADMSG not an array, too few or too many
 * elements, an element of another type or out of range (the message
 * names the element, e.g. gains[3], and its place); -ENOENT. */
CHM_CHECK int chm_config_get_doubles(const chm_config_t* cfg, const char* key, double lo, double hi,
                           size_t min_n, size_t max_n, double* out, size_t* n);

/* The same for integers in [lo, hi] (floats refused). Errors: as
 * chm_config_get_doubles. */
CHM_CHECK int chm_config_get_int64s(const chm_config_t* cfg, const char* key, int64_t lo, int64_t hi,
                          size_t min_n, size_t max_n, int64_t* out, size_t* n);

#ifdef __cplusplus
}
#endif

#endif
