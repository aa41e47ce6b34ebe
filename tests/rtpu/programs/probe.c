/* A control program the rtpu tests start on an RTPU. argv[1] is a file it
 * appends lines to: "main <pid>" when main starts, "signal <n>" for each
 * user signal 1..31 it receives, "hook" when the RTPU's shutdown hooks
 * run. Then it waits, a second at a time, until the RTPU stops. */
#include <chimera/chimera.h>
#include <fcntl.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

static const char *g_file;

static void note(const char *fmt, ...) {
    char line[128];
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(line, sizeof line - 1, fmt, ap);
    va_end(ap);
    line[n++] = '\n';
    int fd = open(g_file, O_WRONLY | O_CREAT | O_APPEND, 0644);
    if (fd < 0) return;
    (void)!write(fd, line, (size_t)n);
    close(fd);
}

static void on_signal(int signo, void *arg) {
    (void)arg;
    note("signal %d", signo);
}

static void on_shutdown(void *arg) {
    (void)arg;
    note("hook");
}

int main(int argc, char **argv) {
    if (argc < 2) return 1;
    g_file = argv[1];  /* the program's own copy of its arguments */
    for (int s = 1; s <= CHM_USIG_MAX; ++s) (void)!chm_usig_handle(s, on_signal, NULL);
    (void)!chm_kernel_on_shutdown(on_shutdown, NULL);
    note("main %d", (int)getpid());
    for (;;) chm_task_pause_until(chm_time_now() + 1000000000ull);
}
