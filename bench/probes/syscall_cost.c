/* chimera-syscall-cost: what one system call costs this host, beside the
 * futex calls a cross-process wake-up makes, to read msgq_wake_rt2 against
 * its POSIX mq peer (one futex call and one switch per direction against
 * two mq calls and one switch). Each figure is the mean of a loop of raw
 * calls that find nothing to do (a wake with no waiter, a wait whose value
 * does not match). Run pinned: taskset -c 0 chimera-syscall-cost */
#define _GNU_SOURCE
#include <fcntl.h>
#include <linux/futex.h>
#include <stdint.h>
#include <stdio.h>
#include <sys/mman.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

enum { kCalls = 200000 };

static double now_ns(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec * 1e9 + (double)t.tv_nsec;
}

static void futex_row(const char* name, uint32_t* word, int op) {
    const double t0 = now_ns();
    for (int i = 0; i < kCalls; ++i) syscall(SYS_futex, word, op, 1, 0, 0, 0);
    printf("%-40s %6.0f ns\n", name, (now_ns() - t0) / kCalls);
}

int main(void) {
    double t0 = now_ns();
    for (int i = 0; i < kCalls; ++i) syscall(SYS_getppid);
    printf("%-40s %6.0f ns\n", "getppid", (now_ns() - t0) / kCalls);

    char path[64];
    snprintf(path, sizeof path, "/dev/shm/chimera-syscall-cost-%d", (int)getpid());
    const int fd = open(path, O_RDWR | O_CREAT | O_EXCL, 0600);
    if (fd < 0 || ftruncate(fd, 4096) != 0) return perror(path), 1;
    uint32_t* shared = mmap(NULL, 4096, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    unlink(path);
    close(fd);
    if (shared == MAP_FAILED) return perror("mmap"), 1;
    static uint32_t private_word;
    futex_row("FUTEX_WAKE, shared word in /dev/shm", shared, FUTEX_WAKE);
    futex_row("FUTEX_WAKE_PRIVATE", &private_word, FUTEX_WAKE_PRIVATE);
    futex_row("FUTEX_WAIT (no match), shared word", shared, FUTEX_WAIT);
    futex_row("FUTEX_WAIT_PRIVATE (no match)", &private_word, FUTEX_WAIT_PRIVATE);
    return 0;
}
