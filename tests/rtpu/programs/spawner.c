/* A control program that uses express mail from a task: on its RTPU it
 * asks RTPU argv[1] to start argv[2] with the single argument argv[3],
 * lists that RTPU's tasks, signals the new task with signal 9, and writes
 * what happened to the file argv[4]:
 *   "spawn <status> <tid>", "tasks <count> <found>", "signal <status>",
 * and "self <status>" for a ping of its own RTPU (served by a task of the
 * same kernel while this one is parked). */
#include <chimera/bp.h>
#include <chimera/chimera.h>
#include <chimera/rtpu.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int main(int argc, char **argv) {
    if (argc < 5) return 1;
    const int rtpu = atoi(argv[1]);
    const char *args[2] = {argv[2], argv[3]};
    chm_tid_t tid = CHM_TID_NONE;
    const int r = chm_rtpu_spawn(rtpu, argv[2], 2, args, &tid);
    static chm_rtpu_task_t tasks[64];
    int total = 0, found = 0;
    const int n = chm_rtpu_tasks(rtpu, tasks, 64, &total);
    for (int i = 0; i < n; ++i)
        if (tasks[i].id == tid) found = 1;
    chm_task_pause_until(chm_time_now() + 100000000ull);  /* let its main install handlers */
    const int s = chm_rtpu_signal(rtpu, tid, 9);
    const int self = chm_rtpu_ping(chm_bp_self(), NULL);
    FILE *f = fopen(argv[4], "w");
    if (!f) return 1;
    fprintf(f, "spawn %d %lld\ntasks %d %d\nsignal %d\nself %d\n", r, (long long)tid, n, found, s, self);
    fclose(f);
    return 0;
}
