/* The chaos soak's worker as a host process (no kernel: its waits sleep on
 * futexes). argv: BACKPLANE LEDGER ID INCARNATION SEED. It attaches as a
 * host, runs worker.c's loop until told to quit and leaves. */
#include <chimera/bp.h>
#include <stdio.h>
#include <stdlib.h>

#include "worker.h"

int main(int argc, char** argv) {
    if (argc != 6) {
        fprintf(stderr, "usage: chimera-soak-host BACKPLANE LEDGER ID INCARNATION SEED\n");
        return 2;
    }
    char name[32];
    snprintf(name, sizeof name, "soak-host%s", argv[3]);
    const int r = chm_bp_attach_host(argv[1], name, NULL);
    if (r) {
        fprintf(stderr, "chimera-soak-host: attach %s: %d %s\n", argv[1], r, chm_bp_last_error());
        return 1;
    }
    const int st = soak_worker_run(argv[2], (unsigned)atoi(argv[3]), (uint32_t)strtoul(argv[4], NULL, 10),
                                   strtoull(argv[5], NULL, 10));
    const int l = chm_bp_leave();
    if (l) fprintf(stderr, "chimera-soak-host: leave: %d %s\n", l, chm_bp_last_error());
    return st ? st : (l ? 1 : 0);
}
