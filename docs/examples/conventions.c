/* docs/examples/conventions.c */
#include <errno.h>
#include <stdio.h>

#include "chimera/chimera.h"

int main(void) {
    chm_sem_t sem;
    /* Every call returns 0 or a negative errno-style status. */
    int r = chm_sem_init(&sem, CHM_SEM_BINARY, 2, 0); /* binary: 0 or 1 */
    if (r != -EINVAL) {
        printf("expected -EINVAL, got %d\n", r);
        return 1;
    }
    printf("refused: %d (%s)\n", r, chm_err_last());

    r = chm_sem_init(&sem, CHM_SEM_COUNTING, 1, 0);
    if (r != 0) {
        printf("chm_sem_init: %s\n", chm_err_last());
        return 1;
    }
    /* _try_ never waits: -EAGAIN when it cannot succeed at once. */
    if ((r = chm_sem_try_p(&sem)) != 0 || (r = chm_sem_try_p(&sem)) != -EAGAIN) {
        printf("chm_sem_try_p: %d\n", r);
        return 1;
    }
    if ((r = chm_sem_v(&sem)) != 0 || (r = chm_sem_destroy(&sem)) != 0) {
        printf("%s\n", chm_err_last());
        return 1;
    }
    printf("CHM_NO_WAIT = %llu, CHM_FOREVER = %llu\n", (unsigned long long)CHM_NO_WAIT,
           (unsigned long long)CHM_FOREVER);
    return 0;
}
