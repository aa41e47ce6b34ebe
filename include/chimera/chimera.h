/* Chimera: everything a control program needs, in one include. */
#ifndef CHIMERA_H
#define CHIMERA_H

#include "chimera/err.h"
#include "chimera/io.h"
#include "chimera/irq.h"
#include "chimera/kernel.h"
#include "chimera/msgq.h"
#include "chimera/program.h"
#include "chimera/rsem.h"
#include "chimera/sched.h"
#include "chimera/sem.h"
#include "chimera/task.h"
#include "chimera/usig.h"

#endif
