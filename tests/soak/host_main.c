/* The chaos soak's worker as a host process (no kernel: its waits sleep on
 * futexes). argv: BACKPLANE LEDGER ID INCARNATION SEED. It attaches as a
 * host, runs worker.c's loop until told to quit and leaves. SIGTERM is its
 * graceful stop: the operation under way (a bounded call) finishes, then
 * it leaves the backplane and exits 0, as at quit. */
#include <chimera/bp.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>

#include "worker.h"

static void on_term(int sig) {
    (void)sig;
    soak_worker_stop = 1;
}

int main(int argc, char** argv) {
    if (argc != 6) {
        fprintf(stderr, "usage: chimera-soak-host BACKPLANE LEDGER ID INCARNATION SEED\n");
        return 2;
    }
    struct sigaction sa;
    sa.sa_handler = on_term;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = 0; /* no SA_RESTART: a sleep between operations ends at once */
    sigaction(SIGTERM, &sa, NULL);
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
