/* Chimera device drivers, level 2: a hardware-independent sensor/actuator
 * interface over level-1 devices (chimera/dev.h).
 *
 * A sensor returns a vector of doubles in SI units with a timestamp; an
 * actuator takes a vector, enforces the limits configured when it was
 * opened (per element min/max and optionally a rate), clamps or refuses a
 * command beyond them as configured, counts and reports it, and never
 * passes it through. An actuator has a safe stop (zero output or hold, as
 * the device defines it) that also runs when its descriptor is closed and
 * when its owning task is aborted (chm_dev_task_abort).
 *
 * Timestamps are in the device's own clock (chm_sensor_info.time_domain):
 * CHM_TIME_MONOTONIC is CLOCK_MONOTONIC in ns (the same in every process),
 * CHM_TIME_SIM is the simulated time of a simulated device in ns since its
 * creation. CHM_DEV_IOC_TIME reads that clock.
 *
 * A driver provides level 2 by answering the CHM_SIO_IOC_* requests below;
 * the limit checks, counters and safe-stop bookkeeping are done here, once,
 * for every device. Level-2 descriptors are level-1 descriptors: close
 * them with chm_dev_close. */
#ifndef CHIMERA_SENSOR_H
#define CHIMERA_SENSOR_H

#include "chimera/status.h"

#include <stdint.h>

#include "chimera/dev.h"

#ifdef __cplusplus
extern "C" {
#endif

#define CHM_SIO_MAX 32          /* elements of one vector */
#define CHM_SIO_NAME_MAX 15     /* element name, e.g. "q1", "Fz" */
#define CHM_SIO_UNIT_MAX 11     /* SI unit name, e.g. "rad", "N*m", "V" */

/* Status codes of level 2 (besides those of chimera/dev.h). */
#define CHM_ACT_CLAMPED   1              /* written, but clamped into its limits */
#define CHM_EACT_LIMIT    (-ERANGE)      /* refused: beyond limits (refuse mode) */
#define CHM_EACT_STOPPED  (-ESHUTDOWN)   /* refused: safe stop latched; resume first */
#define CHM_ESIO_NOTSUP   (-ENOTTY)      /* the device is not a sensor / not an actuator */
#define CHM_ESIO_INVAL    (-EINVAL)      /* wrong vector length, NULL, bad limits */

enum chm_time_domain { CHM_TIME_MONOTONIC = 0, CHM_TIME_SIM = 1 };

/* The shape of a sensor's or actuator's vector. */
typedef struct chm_sio_info {
    uint32_t n;                                  /* elements */
    uint32_t time_domain;                        /* enum chm_time_domain */
    char name[CHM_SIO_MAX][CHM_SIO_NAME_MAX + 1];
    char unit[CHM_SIO_MAX][CHM_SIO_UNIT_MAX + 1];
    double min[CHM_SIO_MAX];   /* actuators: the hardware's range (the
                                * widest limits allowed); sensors: range */
    double max[CHM_SIO_MAX];
} chm_sio_info_t;

/* One sensor reading. */
typedef struct chm_sensor_sample {
    uint64_t t_ns;             /* when it was taken, in the device's clock */
    uint32_t n;
    double v[CHM_SIO_MAX];
} chm_sensor_sample_t;

enum chm_limit_mode {
    CHM_LIMIT_CLAMP = 0,       /* clamp into the limits, apply, return CHM_ACT_CLAMPED */
    CHM_LIMIT_REFUSE = 1       /* apply nothing, return CHM_EACT_LIMIT */
};

/* Limits of an actuator. min/max: per element (must lie inside the
 * device's range). max_rate: per element, units per second of the device's
 * clock, 0 = no rate limit; the first command after open (or resume) is
 * measured from 0. */
typedef struct chm_actuator_limits {
    uint32_t n;
    uint32_t mode;             /* enum chm_limit_mode */
    double min[CHM_SIO_MAX];
    double max[CHM_SIO_MAX];
    double max_rate[CHM_SIO_MAX];
} chm_actuator_limits_t;

typedef struct chm_actuator_stats {
    uint64_t writes;           /* commands accepted (clamped ones included) */
    uint64_t clamped;          /* commands clamped (some element changed) */
    uint64_t refused;          /* commands refused for limits */
    uint64_t rate_limited;     /* commands in which the rate limit acted */
    uint64_t stops;            /* safe stops */
    double last[CHM_SIO_MAX];  /* what was last applied */
} chm_actuator_stats_t;

/* Level-2 driver requests (level-1 ioctl numbers). */
#define CHM_SIO_IOC_SENSOR_INFO 0x1001 /* arg chm_sio_info_t* */
#define CHM_SIO_IOC_SENSOR_READ 0x1002 /* arg chm_sensor_sample_t* */
#define CHM_SIO_IOC_ACT_INFO    0x1003 /* arg chm_sio_info_t* */
#define CHM_SIO_IOC_ACT_WRITE   0x1004 /* arg const double[n] (already within limits) */
#define CHM_SIO_IOC_ACT_STOP    0x1005 /* arg NULL: safe stop */
#define CHM_SIO_IOC_ACT_RESUME  0x1006 /* arg NULL: leave safe stop, output 0 */

/* Open `name` as a sensor (read-only). Returns a descriptor.
 * Errors: those of chm_dev_open; CHM_ESIO_NOTSUP not a sensor (the
 * descriptor is closed again). */
CHM_CHECK int chm_sensor_open(const char* name);

/* Describe the sensor's vector. Errors: CHM_EDEV_BADF, CHM_ESIO_NOTSUP,
 * CHM_ESIO_INVAL (NULL). */
CHM_CHECK int chm_sensor_info(int sd, chm_sio_info_t* info);

/* Take one reading. Errors: CHM_EDEV_BADF, CHM_ESIO_NOTSUP, CHM_ESIO_INVAL,
 * or the driver's status. */
CHM_CHECK int chm_sensor_read(int sd, chm_sensor_sample_t* out);

/* Fill `lim` with the device's full range, clamp mode, no rate limit. */
void chm_actuator_limits_init(chm_actuator_limits_t* lim, const chm_sio_info_t* info);

/* Open `name` as an actuator with limits `lim` (NULL: the device's range,
 * clamp mode). The output starts at 0 (the device's safe value).
 * Errors: those of chm_dev_open; CHM_ESIO_NOTSUP not an actuator;
 * CHM_ESIO_INVAL limits of the wrong length, min > max, outside the
 * device's range, a negative rate or unknown mode. Nothing stays open on
 * error. */
CHM_CHECK int chm_actuator_open(const char* name, const chm_actuator_limits_t* lim);

/* Describe the actuator's vector (range = the device's hardware range).
 * Errors: CHM_EDEV_BADF not an open descriptor; CHM_ESIO_NOTSUP not an
 * actuator; CHM_ESIO_INVAL NULL info; the driver's error. */
CHM_CHECK int chm_actuator_info(int ad, chm_sio_info_t* info);

/* Replace the limits (same checks as at open); the old ones stay on error.
 * Errors: CHM_EDEV_BADF; CHM_ESIO_NOTSUP not opened with
 * chm_actuator_open; CHM_ESIO_INVAL as chm_actuator_open's limits. */
CHM_CHECK int chm_actuator_set_limits(int ad, const chm_actuator_limits_t* lim);

/* Command the actuator with v[0..n-1] (n must be the device's length).
 * Returns 0 applied as given; CHM_ACT_CLAMPED applied after clamping
 * (clamp mode); CHM_EACT_LIMIT nothing applied (refuse mode, some element
 * beyond min/max or the rate); CHM_EACT_STOPPED safe stop latched;
 * CHM_EDEV_BADF; CHM_ESIO_NOTSUP (not opened with chm_actuator_open);
 * CHM_ESIO_INVAL (NULL, wrong n, a NaN: never applied, in either mode). */
CHM_CHECK int chm_actuator_write(int ad, const double* v, uint32_t n);

/* Safe stop now, and latch it: commands are refused with CHM_EACT_STOPPED
 * until chm_actuator_resume. Errors: CHM_EDEV_BADF, CHM_ESIO_NOTSUP. */
CHM_CHECK int chm_actuator_stop(int ad);

/* Leave a safe stop; the output is 0 until the next command. Errors:
 * CHM_EDEV_BADF; CHM_ESIO_NOTSUP not opened with chm_actuator_open; the
 * driver's error (the stop stays latched). */
CHM_CHECK int chm_actuator_resume(int ad);

/* Counters and the last applied vector. Errors: CHM_EDEV_BADF,
 * CHM_ESIO_NOTSUP, CHM_ESIO_INVAL. */
CHM_CHECK int chm_actuator_stats(int ad, chm_actuator_stats_t* out);

#ifdef __cplusplus
}
#endif
#endif
