/* The public allocator header compiled as strict C99 and used from C:
 * every declaration must be valid C, and the basic contract must hold when
 * called from a C program. Exit status 0 means every check passed. */
#include <chimera/mem.h>

#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

static int failures = 0;

#define CHECK(cond)                                                   \
    do {                                                              \
        if (!(cond)) {                                                \
            fprintf(stderr, "%s:%d: %s\n", __FILE__, __LINE__, #cond); \
            ++failures;                                               \
        }                                                             \
    } while (0)

int main(void) {
    struct chm_mem_stats before, after;
    char *p;
    char *q;
    void *a;

    CHECK(chm_mem_stats(&before) == 0);
    p = (char *)chm_malloc(1000);
    CHECK(p != NULL);
    memset(p, 'x', 1000);
    CHECK(chm_mem_stats(&after) == 0);
    CHECK(after.used_blocks == before.used_blocks + 1);
    CHECK(after.used_bytes >= before.used_bytes + 1000);
    CHECK(chm_malloc_usable_size(p) >= 1000);

    q = (char *)chm_realloc(p, 20000);
    CHECK(q != NULL && q[999] == 'x');
    chm_free(q);

    q = (char *)chm_calloc(100, 10);
    CHECK(q != NULL && q[0] == 0 && q[999] == 0);
    chm_free(q);

    errno = 0;
    CHECK(chm_memalign(12, 10) == NULL && errno == EINVAL);
    a = chm_memalign(4096, 10);
    CHECK(a != NULL && ((uintptr_t)a % 4096) == 0);
    chm_free(a);

    CHECK(chm_mem_check() == 0);
    CHECK(chm_mem_stats(NULL) == -EINVAL);
    CHECK(chm_mem_stats(&after) == 0 && after.used_blocks == before.used_blocks);
    return failures == 0 ? 0 : 1;
}
