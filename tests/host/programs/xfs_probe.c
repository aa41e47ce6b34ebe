/* A control program the host tests start on an RTPU: it uses the extended
 * file system and host calls from a task while a 1 kHz periodic task (the
 * "ticker") runs on the same RTPU, and writes one result line per step to
 * argv[1] (a local file) that the test reads.
 *
 *   xfs_probe OUT read PATH      read PATH whole in 64 KiB calls: bytes, byte
 *                                sum, stat size, ticker cycles during the read
 *   xfs_probe OUT block PATH     read 1 byte from PATH (a FIFO the test fills
 *                                late): ticker cycles while the read waited
 *   xfs_probe OUT stdio PATH     fprintf 1000 lines through chm_xfs_fopen,
 *                                read them back with fgets
 *   xfs_probe OUT run ARG...     chm_host_run(ARG...): its status
 *   xfs_probe OUT open PATH...   chm_xfs_open of each PATH: status and error */
#include <chimera/chimera.h>
#include <fcntl.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static const char *g_out;
static volatile unsigned long long g_ticks;

static void note(const char *fmt, ...) {
    char line[512];
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(line, sizeof line - 1, fmt, ap);
    va_end(ap);
    if (n > (int)sizeof line - 2) n = (int)sizeof line - 2;
    line[n++] = '\n';
    int fd = open(g_out, O_WRONLY | O_CREAT | O_APPEND, 0644);
    if (fd < 0) return;
    (void)!write(fd, line, (size_t)n);
    close(fd);
}

static void ticker(void *arg) {
    (void)arg;
    for (;;) {
        ++g_ticks;
        chm_task_wait_period();
    }
}

static chm_tid_t start_ticker(void) {
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "ticker";
    a.period_ns = 1000000;
    a.priority = 100;
    chm_tid_t t = CHM_TID_NONE;
    if (chm_task_spawn(&t, ticker, NULL, &a) != 0) note("ticker: cannot spawn");
    return t;
}

static unsigned long long misses_of(chm_tid_t t) {
    chm_task_status_t st;
    return chm_task_status(t, &st) == 0 ? (unsigned long long)st.misses : 0;
}

int main(int argc, char **argv) {
    if (argc < 3) return 1;
    g_out = argv[1];
    const char *what = argv[2];
    if (!strcmp(what, "read") && argc == 4) {
        chm_tid_t t = start_ticker();
        chm_task_pause_until(chm_time_now() + 20000000);
        int fd = chm_xfs_open(argv[3], CHM_XFS_RDONLY, 0);
        if (fd < 0) {
            note("read error %d %s", fd, chm_xfs_last_error());
            return 1;
        }
        static char buf[65536];
        unsigned long long total = 0, sum = 0, calls = 0;
        const unsigned long long t0 = g_ticks, m0 = misses_of(t);
        for (;;) {
            long long r = chm_xfs_read(fd, buf, sizeof buf);
            if (r < 0) {
                note("read error %lld %s", r, chm_xfs_last_error());
                return 1;
            }
            if (r == 0) break;
            ++calls;
            total += (unsigned long long)r;
            for (long long i = 0; i < r; ++i) sum += (unsigned char)buf[i];
        }
        const unsigned long long ticks = g_ticks - t0, misses = misses_of(t) - m0;
        chm_xfs_stat_t st;
        int sr = chm_xfs_fstat(fd, &st);
        (void)!chm_xfs_close(fd);
        note("read bytes=%llu sum=%llu size=%llu stat=%d calls=%llu ticks=%llu misses=%llu", total, sum,
             (unsigned long long)st.size, sr, calls, ticks, misses);
        return 0;
    }
    if (!strcmp(what, "block") && argc == 4) {
        start_ticker();
        chm_task_pause_until(chm_time_now() + 20000000);
        int fd = chm_xfs_open(argv[3], CHM_XFS_RDONLY, 0);
        if (fd < 0) {
            note("block error %d %s", fd, chm_xfs_last_error());
            return 1;
        }
        note("block opened");
        const unsigned long long t0 = g_ticks;
        char c = 0;
        long long r = chm_xfs_read(fd, &c, 1);
        note("block read=%lld byte=%c ticks=%llu", r, c, g_ticks - t0);
        (void)!chm_xfs_close(fd);
        return 0;
    }
    if (!strcmp(what, "stdio") && argc == 4) {
        FILE *f = chm_xfs_fopen(argv[3], "w+");
        if (!f) {
            note("stdio error %s", chm_xfs_last_error());
            return 1;
        }
        for (int i = 0; i < 1000; ++i) fprintf(f, "line %d of the stdio probe\n", i);
        fflush(f);
        rewind(f);
        char line[128];
        int n = 0, good = 0;
        while (fgets(line, sizeof line, f)) {
            char want[64];
            snprintf(want, sizeof want, "line %d of the stdio probe\n", n);
            good += !strcmp(line, want);
            ++n;
        }
        fclose(f);
        note("stdio lines=%d good=%d", n, good);
        return 0;
    }
    if (!strcmp(what, "run") && argc >= 4) {
        int status = -1;
        int r = chm_host_run(argc - 3, (const char *const *)argv + 3, &status);
        note("run r=%d status=%d %s", r, status, r < 0 ? chm_xfs_last_error() : "");
        return 0;
    }
    if (!strcmp(what, "open")) {
        for (int i = 3; i < argc; ++i) {
            int fd = chm_xfs_open(argv[i], CHM_XFS_RDONLY, 0);
            note("open %s -> %d %s", argv[i], fd, fd < 0 ? chm_xfs_last_error() : "");
            if (fd >= 0) (void)!chm_xfs_close(fd);
        }
        return 0;
    }
    note("usage");
    return 2;
}
