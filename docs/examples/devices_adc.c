/* docs/examples/devices_adc.c */
#define _POSIX_C_SOURCE 200809L /* mkdtemp */
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

#include "chimera/chimera.h"
#include "sim.h" /* the simulated devices (src/lib/sim), not installed */

static int fail(const char *what, int r) {
    printf("%s: %d %s\n", what, r, chm_err_last());
    return 1;
}

/* Read the A/D inputs, command the D/A output through limits. */
static int use_device(const char *name) {
    int sd = chm_sensor_open(name);
    if (sd < 0) return fail("chm_sensor_open", sd);
    chm_sio_info_t info;
    chm_sensor_sample_t s;
    int r = chm_sensor_info(sd, &info);
    if (r == 0) r = chm_sensor_read(sd, &s);
    int c = chm_dev_close(sd);
    if (r != 0 || c != 0) return fail("sensor", r != 0 ? r : c);
    printf("%s = %.3f %s (of %u inputs)\n", info.name[0], s.v[0], info.unit[0], info.n);

    int ad = chm_actuator_open(name, NULL); /* the device's range for now */
    if (ad < 0) return fail("chm_actuator_open", ad);
    chm_actuator_limits_t lim;
    chm_actuator_stats_t st;
    r = chm_actuator_info(ad, &info);
    if (r == 0) {
        chm_actuator_limits_init(&lim, &info);
        lim.max[0] = 2.0; /* never more than 2 V on this output */
        r = chm_actuator_set_limits(ad, &lim);
    }
    double cmd = 3.0;
    if (r == 0 && (r = chm_actuator_write(ad, &cmd, 1)) == CHM_ACT_CLAMPED)
        r = chm_actuator_stats(ad, &st);
    c = chm_dev_close(ad); /* closing an actuator stops it safely */
    if (r != 0 || c != 0) return fail("actuator", r != 0 ? r : c);
    printf("asked 3.0 V, applied %.1f V (%llu clamped)\n", st.last[0],
           (unsigned long long)st.clamped);
    return 0;
}

int main(void) {
    /* Without hardware: an A/D-D/A simulated in a file of a private dir. */
    char dir[] = "/dev/shm/chm-guide-XXXXXX", file[64];
    if (!mkdtemp(dir)) return fail("mkdtemp", -1);
    snprintf(file, sizeof file, "%s/adc0", dir);
    chm_sim_adc_config_t c;
    chm_sim_adc_config_init(&c);
    c.n_in = 2;
    c.n_out = 1;
    c.vmin = 0.0;
    c.vmax = 5.0;
    chm_sim_t *sim = NULL;
    int r = chm_sim_adc_create(file, &c);
    if (r == 0) r = chm_sim_register("adc0", file);
    if (r == 0) r = chm_sim_attach(file, &sim);
    if (r == 0) r = chm_sim_adc_set_input(sim, 0, 1.25); /* the plant's side */
    int failed = r != 0 ? fail("simulated A/D", r) : use_device("adc0");

    if (sim) chm_sim_detach(sim);
    if (chm_sim_unregister("adc0") != 0 || chm_sim_remove(file) != 0 || rmdir(dir) != 0)
        failed = fail("clean up", -1);
    return failed;
}
