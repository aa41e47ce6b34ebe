/* Chimera: the whole public API in one include (every header of
 * include/chimera/). */
#ifndef CHIMERA_H
#define CHIMERA_H

#include "chimera/bp.h"
#include "chimera/cmdi.h"
#include "chimera/config.h"
#include "chimera/dev.h"
#include "chimera/err.h"
#include "chimera/host.h"
#include "chimera/io.h"
#include "chimera/irq.h"
#include "chimera/kernel.h"
#include "chimera/matrix.h"
#include "chimera/mem.h"
#include "chimera/module.h"
#include "chimera/msgq.h"
#include "chimera/program.h"
#include "chimera/rsem.h"
#include "chimera/rtpu.h"
#include "chimera/sched.h"
#include "chimera/sem.h"
#include "chimera/sensor.h"
#include "chimera/servo.h"
#include "chimera/shm.h"
#include "chimera/spin.h"
#include "chimera/status.h"
#include "chimera/svar.h"
#include "chimera/task.h"
#include "chimera/usig.h"
#include "chimera/xfs.h"

#endif
