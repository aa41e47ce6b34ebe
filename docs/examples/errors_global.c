/* docs/examples/errors_global.c */
#include <fcntl.h>
#include <stdio.h>
#include <string.h>

#include "chimera/chimera.h"

static int failed = 1;

static chm_err_action_t to_mark(const chm_err_info_t *info, void *arg) {
    (void)arg;
    printf("handler: %s error %d (%s) in %s\n", info->module_name, info->code, info->message,
           info->call ? info->call : "?");
    return CHM_ERR_TO_MARK; /* back to the task's innermost mark */
}

static void reader(void *arg) {
    (void)arg;
    /* Status returns: check, and read chm_err_last() for the details. */
    int fd = chm_unix_open("/no/such/file", O_RDONLY);
    if (fd >= 0) return;
    printf("checked: %s\n", chm_err_last());

    /* Global error handling: failures become error signals. */
    if (chm_err_on_module(CHM_ERR_UNIX, to_mark, NULL) != 0 || chm_err_global(1) < 0) return;
    chm_err_mark_t mark;
    if (chm_err_mark(&mark) == 0) {
        fd = chm_unix_open("/no/such/file", O_RDONLY); /* no check needed */
        printf("never printed: fd %d\n", fd);
    } else {
        printf("back at the mark: %s\n", chm_err_last());
        failed = strstr(chm_err_last(), "/no/such/file") == NULL;
    }
    if (chm_err_unmark(&mark) != 0 || chm_err_global(0) < 0) failed = 1;
}

int main(void) {
    if (chm_kernel_init(NULL) != 0) {
        printf("chm_kernel_init: %s\n", chm_err_last());
        return 1;
    }
    if (chm_task_spawn(NULL, reader, NULL, NULL) != 0) {
        printf("chm_task_spawn: %s\n", chm_err_last());
        return 1;
    }
    int r = chm_kernel_run();
    chm_kernel_fini();
    return r != 0 || failed;
}
