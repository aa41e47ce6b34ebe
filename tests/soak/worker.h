/* The chaos soak's worker loop (worker.c), shared by the RTPU control
 * program (worker_prog.c) and the host process (host_main.c). */
#ifndef CHM_SOAK_WORKER_H
#define CHM_SOAK_WORKER_H

#include <chimera/spin.h>
#include <signal.h>
#include <stdint.h>

#include "ledger.h"

/* The segment soak.shm: a seqlock-protected block whose words all hold
 * the number of writes made. Writers take `lock` (robust: a dead holder's
 * lock is taken over with -EOWNERDEAD and the half-made write finished);
 * readers take nothing and retry while `seq` is odd or moved. */
typedef struct soak_shm {
    chm_spin_t lock;
    uint32_t seq;
    uint32_t reserved;
    uint64_t word[SOAK_SHM_WORDS];
} soak_shm_t;

/* Set (from a signal handler) to end the loop after the operation under
 * way, as the ledger's quit does: a host process's graceful stop. */
extern volatile sig_atomic_t soak_worker_stop;

/* Run worker `id`, incarnation `inc`, until the ledger says quit. The
 * process must already be attached to the soak's backplane. Returns 0
 * after a quit (or soak_worker_stop), 1 when the ledger or an object could not be opened. */
int soak_worker_run(const char* ledger_path, unsigned id, uint32_t inc, uint64_t seed);

#endif
