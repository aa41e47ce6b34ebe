/* Chimera control programs: "writing code for Chimera is as simple as
 * writing a C program for UNIX". A control program is a shared object with
 * an ordinary `int main(int argc, char** argv)`; the RTPU loads it and
 * spawns its main as a task. Its code is preemptible like the RTPU's own.
 *
 * Build one against the headers only, without linking libchimera: the
 * RTPU process (chimera-rtpu) carries libchimera and resolves every chm_*
 * call of the program against itself, and the loader refuses an object
 * that names libchimera among the libraries it needs (a second copy would
 * be a second kernel nobody initialised):
 *
 *   cc -shared -fPIC -Wall -Wextra myprog.c $(pkg-config --cflags chimera) -o myprog.so
 *
 * or with meson: shared_module('myprog', 'myprog.c', name_prefix : '',
 * dependencies : dependency('chimera').partial_dependency(compile_args :
 * true, includes : true)).
 *
 * A standalone program may instead link the kernel directly and call
 * chm_kernel_init / chm_task_spawn / chm_kernel_run itself. */
#ifndef CHIMERA_PROGRAM_H
#define CHIMERA_PROGRAM_H

#include "chimera/status.h"

#include "chimera/task.h"

#ifdef __cplusplus
extern "C" {
#endif

#define CHM_PROGRAM_MAX 32

/* Load the shared object at `path` and spawn its main(argc, argv) as a task
 * with `attr` (NULL: priority 0, default stack, named after the file). The
 * arguments are copied; argv[argc] is NULL for main. On success *out_main
 * (if not NULL) is main's task and the return value is the program's
 * number (>= 0). Call from the kernel thread before chm_kernel_run or from
 * a task.
 * Errors (nothing stays loaded; chm_err_last() names the file and the
 * cause, once): -EINVAL path NULL or empty, argc < 0, or argv NULL with
 * argc > 0; -EPERM the kernel is not initialised; -ENOENT no such file;
 * -EACCES the file is not trusted (see below); -ENOEXEC not a loadable
 * shared object (the dynamic loader's words), one linked against
 * libchimera (see above), or one without a main of its own; -ENOSPC
 * CHM_PROGRAM_MAX programs loaded; -ENOMEM; chm_task_spawn's errors.
 *
 * Which files load: the path is resolved (every symbolic link followed) and
 * the resolved file is loaded only when no one but this process's user or
 * root could have changed it: the file and every directory above it are
 * owned by the user or root and writable by no one else (group write
 * counts unless the group is the owner's personal group: same name, no
 * other members, as with umask 002 on Debian or Fedora), except that a
 * sticky directory such as /tmp is fine above an entry the user or root
 * owns (others can neither rename nor delete it). When directories were
 * given with chm_program_trust_dir, the file must instead lie under one of
 * them (and nothing else loads). A control program runs with the RTPU's
 * privileges, and load requests come over the backplane (chm_rtpu_spawn). */
CHM_CHECK int chm_program_load(const char* path, int argc, const char* const* argv,
                     const chm_task_attr_t* attr, chm_tid_t* out_main);

/* Let programs load from under `dir` (resolved now, links followed), and
 * from nowhere else: the directories given replace the ownership rule of
 * chm_program_load. At most 8; NULL forgets them all (the ownership rule
 * again). chimera-rtpu --programs DIR calls it.
 * Errors: -ENOSPC 8 already; -ENOTDIR not a directory; -errno from
 * realpath/stat (-ENOENT no such directory). */
CHM_CHECK int chm_program_trust_dir(const char* dir);

/* The exit status main returned, once it has: 0 with *status set, -EAGAIN
 * while main still runs, -ECHILD main was destroyed before it returned,
 * -EINVAL no such program. */
CHM_CHECK int chm_program_status(int program, int* status);

/* The last loading error's text, "FILE: cause" (for a file the dynamic
 * loader refused, its own words), or "" after a load that succeeded.
 * chm_err_last() (err.h) gives the same text per task, whatever the
 * subsystem: use it; this call is kept for one release (CHANGELOG.md). */
const char* chm_program_error(void);

#ifdef __cplusplus
}
#endif
#endif
