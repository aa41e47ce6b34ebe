/* docs/examples/bp_ipc.c */
#define _POSIX_C_SOURCE 200809L /* mkdtemp */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

#include "chimera/chimera.h"

#define MS 1000000

struct shared {        /* what the segment holds */
    chm_spin_t lock;
    double setpoint;
};

static int fail(const char *what, int r) {
    printf("%s: %d %s\n", what, r, chm_err_last());
    return 1;
}

static int shm_and_spin(void) {
    struct shared *sh;
    int r = chm_shm_create("guide.shared", sizeof *sh, CHM_SHM_COMMON, (void **)&sh);
    if (r != 0) return fail("chm_shm_create", r);
    if ((r = chm_spin_init(&sh->lock)) == 0 && (r = chm_spin_lock(&sh->lock, 0, MS)) == 0) {
        sh->setpoint = 0.25; /* plain memory while the lock is held */
        r = chm_spin_unlock(&sh->lock);
    }
    if (r == 0) r = chm_shm_detach(sh);
    if (r == 0) r = chm_shm_destroy("guide.shared");
    return r != 0 ? fail("shared memory", r) : 0;
}

static int remote_semaphore(void) {
    chm_rsem_t *s;
    int r = chm_rsem_create("guide.ready", CHM_SEM_BINARY, 0, CHM_SHM_COMMON, &s);
    if (r != 0) return fail("chm_rsem_create", r);
    if ((r = chm_rsem_try_p(s)) != -EAGAIN) return fail("chm_rsem_try_p", r);
    if ((r = chm_rsem_v(s)) == 0) r = chm_rsem_p_timed(s, 10 * MS);
    if (r == 0) r = chm_rsem_close(s);
    if (r == 0) r = chm_rsem_destroy("guide.ready");
    return r != 0 ? fail("remote semaphore", r) : 0;
}

static int message_queue(void) {
    chm_msgq_attr_t attr;
    chm_msgq_attr_init(&attr);
    attr.order = CHM_MSGQ_PRIORITY; /* most urgent first */
    attr.max_msg = 64;
    chm_msgq_t *q;
    int r = chm_msgq_create("guide.cmds", &attr, CHM_MSGQ_COMMON, &q);
    if (r != 0) return fail("chm_msgq_create", r);
    const char slow[] = "slow", halt[] = "halt";
    if ((r = chm_msgq_send(q, 1, 0, slow, sizeof slow)) == 0)
        r = chm_msgq_send_timed(q, 2, 9, halt, sizeof halt, 10 * MS);
    char buf[64];
    chm_msgq_msg_info_t info;
    for (int i = 0; r == 0 && i < 2; ++i) {
        int len = chm_msgq_receive_timed(q, buf, sizeof buf, &info, 10 * MS);
        if (len < 0) r = len;
        else printf("message type %u prio %u: %s\n", info.type, info.prio, buf);
    }
    if (r == 0 && (r = chm_msgq_try_receive(q, buf, sizeof buf, NULL)) == -EAGAIN) r = 0;
    if (r == 0) r = chm_msgq_close(q);
    if (r == 0) r = chm_msgq_destroy("guide.cmds");
    return r != 0 ? fail("message queue", r) : 0;
}

static int state_variables(void) {
    const chm_svar_decl_t q = {"arm.q", CHM_SVAR_DOUBLE, 2, 1, "rad"};
    const char *outs[] = {"arm.q"};
    chm_svar_set_t *set;
    int r = chm_svar_declare(&q); /* declaring it again is a no-op */
    if (r == 0) r = chm_svar_set_create("guide", NULL, 0, outs, 1, &set);
    if (r != 0) return fail("state variables", r);
    double *local = chm_svar_set_local(set, "arm.q"), now[2] = {0, 0};
    if (local == NULL) {
        r = -ENOENT;
    } else {
        local[0] = 0.5; /* work on the local copy... */
        local[1] = -0.5;
        r = chm_svar_set_write(set); /* ...and publish it whole */
    }
    if (r == 0) r = chm_svar_get("arm.q", now, sizeof now);
    if (r == 0) r = chm_svar_set_destroy(set);
    if (r != 0) return fail("state variables", r);
    printf("arm.q = [%.1f %.1f]\n", now[0], now[1]);
    return 0;
}

int main(void) {
    char dir[] = "/dev/shm/chm-guide-XXXXXX", path[64];
    if (!mkdtemp(dir)) return fail("mkdtemp", -errno);
    snprintf(path, sizeof path, "%s/guide.bp", dir);
    chm_bp_config_t cfg;
    chm_bp_config_init(&cfg);
    cfg.rtpu_slots = 4;
    cfg.ring_records = 8;
    cfg.local_window_size = 64 * 1024;
    cfg.common_size = 2 * 1024 * 1024;
    cfg.registry_capacity = 16;
    int slot, failed = 1;
    int r = chm_bp_create(path, &cfg);
    if (r == 0 && (r = chm_bp_attach_host(path, "guide", &slot)) == 0) {
        printf("attached in slot %d\n", slot);
        failed = shm_and_spin() || remote_semaphore() || message_queue() || state_variables();
        if ((r = chm_bp_leave()) != 0) failed = fail("chm_bp_leave", r);
    } else {
        fail("backplane", r);
    }
    if (unlink(path) != 0 || rmdir(dir) != 0) failed = fail("clean up", -errno);
    return failed;
}
