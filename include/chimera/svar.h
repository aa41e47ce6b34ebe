/* Chimera global state-variable table: named, typed state variables that
 * control tasks on every RTPU (and host processes) share, each task
 * working on a local copy of the ones it uses.
 *
 * One global table per backplane, created by the first declaration. A
 * variable has a name, an element type, a shape (scalar, vector of n,
 * rows x cols matrix, row-major) and a unit; it is never removed while
 * the backplane lives, and declaring it again with the same type and
 * shape is a no-op, so every module and configuration may declare what it
 * uses.
 *
 * A task works through a *set*: its input variables and its output
 * variables, with one local copy of each in the task's own memory.
 * Reading and writing the local copy is plain memory access.
 * chm_svar_set_read copies every input in (global -> local) and
 * chm_svar_set_write copies every output out (local -> global), typically
 * at the start and the end of each cycle (the servo framework does both
 * for a module). Each variable moves whole:
 *   - a reader never sees a value mixed from two writes;
 *   - a writer never waits: not for readers, not for anyone;
 *   - readers never block a writer, and a writer preempted or dead in the
 *     middle of a write never blocks a reader (it reads the previous
 *     value): every variable is double-buffered, and a sequence word per
 *     buffer tells a reader whether its copy was overwritten under it.
 * Each variable has at most one writer at a time: creating a set whose
 * outputs include a variable another live set writes is refused, naming
 * the variable and both writers. A writer whose process died, or whose
 * set was destroyed, or whose task ended, no longer counts.
 *
 * The bytes a set moves per cycle are known in advance (chm_svar_set_bytes):
 * the bus bandwidth of a configuration is computed before it runs.
 *
 * Requires this process to be attached to a backplane (chimera/bp.h).
 * Every function returns 0 (or a count) or a negative errno-style status;
 * after an error chm_err_last() says what failed, naming the
 * variable. Failures that mean a bug or a missing resource are raised as
 * error signals of module "ipc" when the calling task has global handling
 * on (chimera/err.h), as for the other backplane calls. */
#ifndef CHIMERA_SVAR_H
#define CHIMERA_SVAR_H

#include "chimera/status.h"

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Element types. A bool element is one byte (0 or 1). */
typedef enum {
    CHM_SVAR_DOUBLE = 1,
    CHM_SVAR_FLOAT = 2,
    CHM_SVAR_INT32 = 3,
    CHM_SVAR_UINT32 = 4,
    CHM_SVAR_BOOL = 5
} chm_svar_type_t;

#define CHM_SVAR_NAME_MAX 31 /* characters of a variable's name */
#define CHM_SVAR_UNIT_MAX 15 /* characters of its unit */
#define CHM_SVAR_ELEMS_MAX 65536 /* elements in one variable */

/* A declaration: rows x cols elements of `type` (1 x 1: a scalar; n x 1: a
 * vector of n); `unit` may be NULL or "" for none. */
typedef struct {
    const char* name;
    chm_svar_type_t type;
    uint32_t rows;
    uint32_t cols;
    const char* unit;
} chm_svar_decl_t;

/* What the table says of one variable. */
typedef struct {
    char name[CHM_SVAR_NAME_MAX + 1];
    chm_svar_type_t type;
    uint32_t rows, cols;
    char unit[CHM_SVAR_UNIT_MAX + 1];
    size_t bytes;           /* one value: rows * cols * element size */
    uint32_t writes;        /* values written since its declaration (wraps) */
    int has_writer;         /* 1 while a live set writes it */
    char writer[CHM_SVAR_NAME_MAX + 1]; /* that set's owner name, "" if none */
} chm_svar_info_t;

/* Declare a variable in the global table, creating the table on first use
 * (CHM_SVAR_CAPACITY variables, CHM_SVAR_DATA_BYTES of values). Its value
 * starts as all zero bytes. Declaring an existing name with the same type
 * and shape returns 0 and changes nothing (the unit too must match).
 * Errors: -EINVAL NULL decl or name, empty name, unknown type, rows or
 * cols 0, more than CHM_SVAR_ELEMS_MAX elements; -ENAMETOOLONG name or
 * unit too long; -EEXIST the name is declared with another type, shape or
 * unit (chm_err_last gives both declarations); -ENOSPC the table is
 * full (variables or value bytes); -ENOMEM no room in common memory for
 * the table; -EBADMSG the table in the file is corrupt (the message names
 * the entry and field); -ETIMEDOUT a live peer held the table past 5 s;
 * -ENOTCONN not attached. */
CHM_CHECK int chm_svar_declare(const chm_svar_decl_t* decl);

#define CHM_SVAR_CAPACITY 256
#define CHM_SVAR_DATA_BYTES (512u * 1024u)

/* Fill *out for the variable `name`. Errors: -EINVAL NULL argument;
 * -ENOENT no such variable (or no table yet); -EBADMSG corrupt entry;
 * -ENOTCONN. */
CHM_CHECK int chm_svar_info(const char* name, chm_svar_info_t* out);

/* The number of declared variables (>= 0), or -EBADMSG / -ENOTCONN.
 * Variables are numbered 0..count-1 in declaration order, for listing. */
CHM_CHECK int chm_svar_count(void);

/* Fill *out for variable number `index` (0..chm_svar_count()-1).
 * Errors: -EINVAL NULL out; -ENOENT no such index; -EBADMSG; -ENOTCONN. */
CHM_CHECK int chm_svar_info_at(int index, chm_svar_info_t* out);

/* Copy the current value of `name` into buf (`size` >= its bytes): one
 * consistent value, as chm_svar_set_read gives. For monitoring and
 * one-off reads; a periodic task uses a set. Errors: -EINVAL NULL
 * argument; -EMSGSIZE size smaller than the value; -ENOENT; -EAGAIN no
 * consistent copy in 20 ms of attempts (a corrupt sequence word, or a
 * writer that laps every copy; a writer that never pauses only delays the
 * call); -EBADMSG; -ENOTCONN. */
CHM_CHECK int chm_svar_get(const char* name, void* buf, size_t size);

/* ------------------------------------------------------------------ sets */

typedef struct chm_svar_set chm_svar_set_t;

/* Create a set for the calling task: `inputs` (n_in names) are copied in
 * by chm_svar_set_read, `outputs` (n_out names) copied out by
 * chm_svar_set_write, and this set becomes the one writer of each output.
 * `owner` (1..CHM_SVAR_NAME_MAX chars, e.g. the module's name) is what a
 * refused second writer is told. Every local copy starts with the
 * variable's current global value. When created inside a Chimera task,
 * the set's writer claims end with the task (however it ends); the set's
 * memory is freed by chm_svar_set_destroy.
 * Errors: -EINVAL NULL out or owner, NULL names with a count, a name
 * listed twice (in either list); -ENAMETOOLONG owner too long; -ENOENT a
 * name is not declared; -EBUSY an output has a live writer already
 * (chm_err_last names the variable, that writer and this owner);
 * -ENOMEM no memory for the local copies; -EBADMSG a corrupt entry;
 * -EAGAIN an input gave no consistent copy in 20 ms of attempts (as
 * chm_svar_get); -ETIMEDOUT; -ENOTCONN. */
CHM_CHECK int chm_svar_set_create(const char* owner, const char* const* inputs, size_t n_in,
                        const char* const* outputs, size_t n_out, chm_svar_set_t** out);

/* As chm_svar_set_create, but the set claims nothing yet: it can read,
 * and writes only after chm_svar_set_claim. A module's set is opened when
 * it is spawned and claims its outputs when it is switched on.
 * Errors: those of chm_svar_set_create but -EBUSY. */
CHM_CHECK int chm_svar_set_open(const char* owner, const char* const* inputs, size_t n_in,
                      const char* const* outputs, size_t n_out, chm_svar_set_t** out);

/* Claim every output of the set, all or none. A live writer whose owner
 * name is one of `displace` (n_displace names; may be NULL/0) is displaced:
 * the claim passes to this set (a switch hands a variable from the module
 * going off to the one coming on; the old one may still finish the cycle
 * it is in). Claiming again takes back any output another set took
 * (displacing only the names given); outputs it holds stay as they are. Errors: -EINVAL NULL set or
 * names; -EBUSY an output has another live writer (chm_err_last
 * names the variable, that writer and this owner); -ETIMEDOUT; -ENOTCONN
 * the set's attachment is gone. */
CHM_CHECK int chm_svar_set_claim(chm_svar_set_t* set, const char* const* displace, size_t n_displace);

/* Would chm_svar_set_claim(set, displace, n_displace) succeed now? Changes
 * nothing. 0, or the errors of chm_svar_set_claim (-EBUSY naming the
 * variable and its writer). */
CHM_CHECK int chm_svar_set_check_claim(chm_svar_set_t* set, const char* const* displace, size_t n_displace);

/* chm_svar_set_claim for a switch at instant `at_ns` (monotonic ns): the
 * claim is recorded as holding from then on, and a displaced set learns it
 * through chm_svar_set_displaced. Errors: those of chm_svar_set_claim. */
CHM_CHECK int chm_svar_set_claim_at(chm_svar_set_t* set, const char* const* displace, size_t n_displace, uint64_t at_ns);

/* 1 when another set has taken one of this set's outputs with a hand-over
 * instant at or before `release_ns` (the writer must stop writing from the
 * cycle released then), else 0 (also for a NULL set, or one that holds no
 * claim). A few atomic loads per output: cheap enough for every cycle.
 * Never fails. */
int chm_svar_set_displaced(const chm_svar_set_t* set, uint64_t release_ns);

/* Give up the set's claims (those still naming it); the set stays open
 * for reading. Errors: -EINVAL NULL; -ETIMEDOUT. */
CHM_CHECK int chm_svar_set_release(chm_svar_set_t* set);

/* The local copy of `name` in the set (an input or an output), 16-byte
 * aligned, `bytes` long: read and write it directly. NULL when `name` is
 * not in the set (or set/name is NULL). */
void* chm_svar_set_local(const chm_svar_set_t* set, const char* name);

/* Copy-in: every input's current global value into its local copy, each
 * variable whole. Never blocks. Returns 0; -EAGAIN an input changed under
 * 64 attempts in a row (its local copy keeps the previous value, the
 * other inputs are copied; chm_err_last names it); -EINVAL NULL. */
CHM_CHECK int chm_svar_set_read(chm_svar_set_t* set);

/* Copy-out: every output's local copy into the global table, each
 * variable whole. Never blocks, never waits for readers. Returns 0;
 * -EINVAL NULL; -EPERM the set holds no claim (opened and never claimed,
 * or released; a set displaced by a switch still writes until released);
 * -ENOTCONN its attachment is gone. */
CHM_CHECK int chm_svar_set_write(chm_svar_set_t* set);

/* Bytes the set copies per cycle: *in_bytes by chm_svar_set_read,
 * *out_bytes by chm_svar_set_write (either may be NULL). Errors: -EINVAL
 * NULL set. */
CHM_CHECK int chm_svar_set_bytes(const chm_svar_set_t* set, size_t* in_bytes, size_t* out_bytes);

/* Give up the set's writer claims and free it. Errors: -EINVAL NULL;
 * -ETIMEDOUT the table was held past 5 s (the set is freed anyway; its
 * claims end with its process). */
CHM_CHECK int chm_svar_set_destroy(chm_svar_set_t* set);

#ifdef __cplusplus
}
#endif
#endif
