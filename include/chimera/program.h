/* Chimera control programs: "writing code for Chimera is as simple as
 * writing a C program for UNIX". A control program is a shared object with
 * an ordinary `int main(int argc, char** argv)`; the RTPU loads it and
 * spawns its main as a task. Its code is preemptible like the RTPU's own.
 *
 * Build one with meson: shared_module('myprog', 'myprog.c',
 * dependencies : dependency('chimera')), or with
 * cc -shared -fPIC myprog.c $(pkg-config --cflags --libs chimera).
 *
 * A standalone program may instead link the kernel directly and call
 * chm_kernel_init / chm_task_spawn / chm_kernel_run itself. */
#ifndef CHIMERA_PROGRAM_H
#define CHIMERA_PROGRAM_H

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
 * Errors (nothing stays loaded): -EINVAL path NULL or argc < 0 or argv
 * NULL with argc > 0; -EPERM the kernel is not initialised; -ENOENT no such
 * file; -ENOEXEC not a loadable shared object (the loader's message is in
 * chm_program_error()); -ESRCH the object has no `main`; -ENOSPC
 * CHM_PROGRAM_MAX programs loaded; -ENOMEM; chm_task_spawn's errors. */
int chm_program_load(const char* path, int argc, const char* const* argv,
                     const chm_task_attr_t* attr, chm_tid_t* out_main);

/* The exit status main returned, once it has: 0 with *status set, -EAGAIN
 * while main still runs, -ECHILD main was destroyed before it returned,
 * -EINVAL no such program. */
int chm_program_status(int program, int* status);

/* The last loading error's text (the dynamic loader's own words), or "". */
const char* chm_program_error(void);

#ifdef __cplusplus
}
#endif
#endif
