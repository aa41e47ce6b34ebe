/* A control program the stdio tests load: argv[1] tasks each print argv[2]
 * lines "<tag> task K line I of N <padding>" with printf, in three pieces,
 * yielding between pieces every third line (so lines of several tasks are
 * in progress at once: what the per-task line assembly must keep apart),
 * then "<tag> task K finished". */
#include <chimera/chimera.h>
#include <stdio.h>
#include <stdlib.h>

static const char *g_tag;
static int g_lines;

static void body(void *arg) {
    const int k = (int)(long)arg;
    for (int i = 0; i < g_lines; ++i) {
        printf("%s task %d ", g_tag, k);
        /* Give the CPU away mid-line now and then: the other printers then
         * write their pieces between this line's (stdio shared by all tasks
         * of the RTPU would tear the lines). */
        if (i % 3 == 0) chm_task_yield();
        printf("line %d of %d ", i, g_lines);
        printf("%.*s\n", 10 + (i * 7 + k) % 40, "----------------------------------------------------");
    }
    printf("%s task %d finished\n", g_tag, k);
}

int main(int argc, char **argv) {
    if (argc < 4) return 2;
    const int tasks = atoi(argv[1]);
    g_lines = atoi(argv[2]);
    g_tag = argv[3];
    for (int k = 0; k < tasks; ++k) {
        chm_task_attr_t a;
        chm_task_attr_init(&a);
        a.name = "printer";
        a.priority = 10;
        chm_tid_t t;
        if (chm_task_spawn(&t, body, (void *)(long)k, &a) != 0) return 1;
    }
    return 0;
}
