/* The chaos soak's worker as a control program of an RTPU: main is a task
 * of chimera-rtpu. argv: LEDGER ID INCARNATION SEED (worker.c). */
#include <stdlib.h>

#include "worker.h"

int main(int argc, char** argv) {
    if (argc != 5) return 2;
    return soak_worker_run(argv[1], (unsigned)atoi(argv[2]), (uint32_t)strtoul(argv[3], NULL, 10),
                           strtoull(argv[4], NULL, 10));
}
