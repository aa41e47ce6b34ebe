/* A control program with one periodic task for the status tests: main
 * spawns "cycler" (period argv[1] microseconds, critical in MUF, declared
 * CPU per cycle argv[2] microseconds), which spins about half of that
 * each cycle, then main waits until the RTPU stops. */
#include <chimera/chimera.h>
#include <stdlib.h>

static uint64_t g_spin_ns;

static void cycler(void *arg) {
    (void)arg;
    for (;;) {
        const uint64_t end = chm_time_now() + g_spin_ns;
        while (chm_time_now() < end) {
        }
        chm_task_wait_period();
    }
}

int main(int argc, char **argv) {
    if (argc < 3) return 1;
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "cycler";
    a.period_ns = strtoull(argv[1], NULL, 10) * 1000ull;
    a.wcet_ns = strtoull(argv[2], NULL, 10) * 1000ull;
    a.critical = 1;
    g_spin_ns = a.wcet_ns / 2;
    if (chm_task_spawn(NULL, cycler, NULL, &a) != 0) return 2;
    for (;;) chm_task_pause_until(chm_time_now() + 1000000000ull);
}
