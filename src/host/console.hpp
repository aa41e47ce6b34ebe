// Concurrent stdio of an RTPU's tasks, carried to the console through the
// host server (console_io.cpp; docs/architecture.md, "Console").
#pragma once

#include "host/hostio.hpp"

namespace chm::host::console {

// On the kernel thread of an RTPU, after chm_kernel_init and the
// express-mail server: route the tasks' stdout, stderr and stdin through
// the host server, with a drainer task of `priority`. Errors: -EBUSY
// started; -EMSGSIZE ring records too small for a line; -ENOMEM;
// chm_task_spawn's errors. `drop_orphans`: lines no console owns (the
// host server answers -ENOTCONN) are dropped instead of written to the
// log; with no host server at all they go to the log either way.
int start(int priority, bool drop_orphans = false);
// After chm_kernel_run: what is still queued goes to the log; stdio is
// the process's own again.
void stop();

}  // namespace chm::host::console
