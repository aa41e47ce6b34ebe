/* The chaos soak's worker as a control program of an RTPU: main is a task
 * of chimera-rtpu; it spawns one more task per further worker id, so the
 * RTPU runs its workers side by side (one parked in a backplane wait while
 * another runs). argv: LEDGER INCARNATION SEED ID [ID...] (worker.c). */
#include <chimera/chimera.h>
#include <stdio.h>
#include <stdlib.h>

#include "worker.h"

#define MAX_IDS 4

static const char* g_ledger;
static uint32_t g_inc;
static uint64_t g_seed;

static void worker_task(void* arg) {
    (void)soak_worker_run(g_ledger, (unsigned)(uintptr_t)arg, g_inc, g_seed);
}

int main(int argc, char** argv) {
    if (argc < 5 || argc > 4 + MAX_IDS) return 2;
    g_ledger = argv[1];
    g_inc = (uint32_t)strtoul(argv[2], NULL, 10);
    g_seed = strtoull(argv[3], NULL, 10);
    for (int i = 5; i < argc; ++i) {
        chm_task_attr_t a;
        chm_task_attr_init(&a);
        a.name = "soak-worker";
        a.stack_size = 64 * 1024;
        const int r = chm_task_spawn(NULL, worker_task, (void*)(uintptr_t)atoi(argv[i]), &a);
        if (r) {
            fprintf(stderr, "soak worker %s: spawn: %d\n", argv[i], r);
            return 1;
        }
    }
    return soak_worker_run(g_ledger, (unsigned)atoi(argv[4]), g_inc, g_seed);
}
