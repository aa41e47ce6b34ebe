/* A control program the stop tests start on an RTPU: it blocks in one kind
 * of backplane wait so that the test can stop the RTPU under it.
 * argv: FILE KIND WHAT, KIND one of
 *   send NAME   send "second" to queue NAME (the test filled it)
 *   recv NAME   receive from queue NAME (the test left it empty)
 *   p NAME      P the remote semaphore NAME (count 0)
 *   mail N      ping RTPU N (the test stopped its process), 30 s timeout
 * It appends "waiting" to FILE before the call and, should the call ever
 * return, what it got ("sent", "got TEXT", "got unit", "answered R"), so
 * the test can account for every message and unit. */
#include <chimera/chimera.h>
#include <chimera/msgq.h>
#include <chimera/rsem.h>
#include <chimera/rtpu.h>
#include <fcntl.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
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

int main(int argc, char **argv) {
    if (argc < 4) return 1;
    g_file = argv[1];
    const char *kind = argv[2], *what = argv[3];
    if (!strcmp(kind, "send") || !strcmp(kind, "recv")) {
        chm_msgq_t *q;
        int r = chm_msgq_open(what, &q);
        if (r) return note("error open %d", r), 1;
        note("waiting");
        if (kind[0] == 's') {
            r = chm_msgq_send(q, 2, 0, "second", 7);
            note(r ? "error send %d" : "sent", r);
        } else {
            char buf[64] = {0};
            r = chm_msgq_receive(q, buf, sizeof buf - 1, NULL);
            if (r < 0) note("error receive %d", r);
            else note("got %s", buf);
        }
    } else if (!strcmp(kind, "p")) {
        chm_rsem_t *s;
        int r = chm_rsem_open(what, &s);
        if (r) return note("error open %d", r), 1;
        note("waiting");
        r = chm_rsem_p(s);
        note(r ? "error p %d" : "got unit", r);
    } else if (!strcmp(kind, "mail")) {
        chm_rtpu_timeout_set(30000000000ull);
        note("waiting");
        note("answered %d", chm_rtpu_ping(atoi(what), NULL));
    } else {
        note("error kind %s", kind);
        return 1;
    }
    return 0;
}
