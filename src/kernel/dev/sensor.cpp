// Device drivers, level 2: sensors and actuators over level-1 descriptors.
//
// Drivers only answer the CHM_SIO_IOC_* requests; everything a control
// program relies on for safety is here, once for every device: the limit
// check (min/max and rate, clamp or refuse), the counters, the latched safe
// stop and the stop at close. A command the checks reject never reaches the
// driver.
#include <pthread.h>

#include <cmath>
#include <cstring>
#include <new>

#include "kernel/dev/dev.hpp"

namespace chm::dev {

struct Actuator {
    pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
    chm_sio_info_t info{};
    chm_actuator_limits_t lim{};
    chm_actuator_stats_t st{};
    bool stopped = false;
    std::uint64_t last_t = 0;  // device time of the last applied value (rate limit)
};

namespace {

struct Lock {
    pthread_mutex_t* m;
    explicit Lock(pthread_mutex_t* mu) : m(mu) { pthread_mutex_lock(m); }
    ~Lock() { pthread_mutex_unlock(m); }
};

int drv_ioctl(Use& u, unsigned long req, void* arg) {
    return u.ops->ioctl ? u.ops->ioctl(u.slot->inst, req, arg) : CHM_EDEV_NOTTY;
}

bool any_rate(const chm_actuator_limits_t& l) {
    for (std::uint32_t i = 0; i < l.n; ++i)
        if (l.max_rate[i] > 0) return true;
    return false;
}

int check_limits(Use& u, const chm_sio_info_t& info, const chm_actuator_limits_t* l) {
    const char* call = u.call;
    if (!l) return fail(CHM_ESIO_INVAL, call, "%s: NULL limits", u.name);
    if (l->n != info.n)
        return fail(CHM_ESIO_INVAL, call, "%s: limits for %u elements, the actuator has %u", u.name,
                    l->n, info.n);
    if (l->mode != CHM_LIMIT_CLAMP && l->mode != CHM_LIMIT_REFUSE)
        return fail(CHM_ESIO_INVAL, call, "%s: unknown limit mode %u", u.name, l->mode);
    for (std::uint32_t i = 0; i < l->n; ++i) {
        if (!(l->min[i] <= l->max[i]))
            return fail(CHM_ESIO_INVAL, call, "%s: element %u: min %g > max %g", u.name, i, l->min[i],
                        l->max[i]);
        if (l->min[i] < info.min[i] || l->max[i] > info.max[i])
            return fail(CHM_ESIO_INVAL, call, "%s: element %u: [%g, %g] outside the device's range [%g, %g]",
                        u.name, i, l->min[i], l->max[i], info.min[i], info.max[i]);
        if (!(l->max_rate[i] >= 0))
            return fail(CHM_ESIO_INVAL, call, "%s: element %u: bad rate %g", u.name, i, l->max_rate[i]);
    }
    return 0;
}

// The device's clock for the rate limit; 0 when it has none.
std::uint64_t device_time(Use& u) {
    std::uint64_t t = 0;
    return drv_ioctl(u, CHM_DEV_IOC_TIME, &t) < 0 ? 0 : t;
}

// Level-2 state of a descriptor, or a reported refusal.
int actuator_of(Use& u, Actuator** out) {
    if (!u.ok()) return u.status;
    if (!u.slot->act)
        return fail(CHM_ESIO_NOTSUP, u.call, "%s: descriptor %d was not opened with chm_actuator_open",
                    u.name, u.dd);
    *out = u.slot->act;
    return 0;
}

int sio_info(int dd, unsigned long req, chm_sio_info_t* info, const char* call, const char* what) {
    Use u(dd, call);
    if (!u.ok()) return u.status;
    if (!info) return fail(CHM_ESIO_INVAL, call, "%s: NULL info", u.name);
    const int r = drv_ioctl(u, req, info);
    if (r == CHM_EDEV_NOTTY) return fail(CHM_ESIO_NOTSUP, call, "%s is not %s", u.name, what);
    if (r < 0) return fail(r, call, "%s: %s", u.name, chm_dev_strerror(r));
    return 0;
}

}  // namespace

void actuator_stop_for_close(Slot* s, const chm_dev_ops_t* ops) {
    Actuator* a = s->act;
    if (!a || !ops->ioctl) return;
    Lock l(&a->mu);
    if (!a->stopped) {
        ops->ioctl(s->inst, CHM_SIO_IOC_ACT_STOP, nullptr);
        a->stopped = true;
        a->st.stops++;
    }
}

void actuator_free(Actuator* a) { delete a; }

}  // namespace chm::dev

using namespace chm::dev;

extern "C" {

static int impl_sensor_open(const char* name) {
    const int dd = open_quiet(name, CHM_DEV_READ);
    if (dd < 0) return dd;
    chm_sio_info_t info;
    const int r = sio_info(dd, CHM_SIO_IOC_SENSOR_INFO, &info, "chm_sensor_open", "a sensor");
    if (r < 0) {
        close_quiet(dd);
        return r;
    }
    return dd;
}

static int impl_sensor_info(int sd, chm_sio_info_t* info) {
    return sio_info(sd, CHM_SIO_IOC_SENSOR_INFO, info, "chm_sensor_info", "a sensor");
}

static int impl_sensor_read(int sd, chm_sensor_sample_t* out) {
    const char* call = "chm_sensor_read";
    Use u(sd, call);
    if (!u.ok()) return u.status;
    if (!out) return fail(CHM_ESIO_INVAL, call, "%s: NULL sample", u.name);
    const int r = drv_ioctl(u, CHM_SIO_IOC_SENSOR_READ, out);
    if (r == CHM_EDEV_NOTTY) return fail(CHM_ESIO_NOTSUP, call, "%s is not a sensor", u.name);
    if (r < 0) return fail(r, call, "%s: %s", u.name, chm_dev_strerror(r));
    return 0;
}

void chm_actuator_limits_init(chm_actuator_limits_t* lim, const chm_sio_info_t* info) {
    std::memset(lim, 0, sizeof *lim);
    lim->n = info->n;
    lim->mode = CHM_LIMIT_CLAMP;
    for (std::uint32_t i = 0; i < info->n && i < CHM_SIO_MAX; ++i) {
        lim->min[i] = info->min[i];
        lim->max[i] = info->max[i];
    }
}

static int impl_actuator_info(int ad, chm_sio_info_t* info) {
    return sio_info(ad, CHM_SIO_IOC_ACT_INFO, info, "chm_actuator_info", "an actuator");
}

static int impl_actuator_open(const char* name, const chm_actuator_limits_t* lim) {
    const char* call = "chm_actuator_open";
    const int dd = open_quiet(name, CHM_DEV_RDWR);
    if (dd < 0) return dd;
    Actuator* a = new (std::nothrow) Actuator;
    int r = a ? 0 : fail(-ENOMEM, call, "%s: no memory", name);
    if (r == 0) {
        Use u(dd, call);
        r = u.status;
        if (r == 0) r = drv_ioctl(u, CHM_SIO_IOC_ACT_INFO, &a->info);
        if (r == CHM_EDEV_NOTTY) r = fail(CHM_ESIO_NOTSUP, call, "%s is not an actuator", name);
        else if (r < 0) r = fail(r, call, "%s: %s", name, chm_dev_strerror(r));
        if (r == 0) {
            if (lim) a->lim = *lim;
            else chm_actuator_limits_init(&a->lim, &a->info);
            r = check_limits(u, a->info, &a->lim);
        }
        if (r == 0) {
            r = drv_ioctl(u, CHM_SIO_IOC_ACT_RESUME, nullptr);  // output 0, no latched stop
            if (r < 0) r = fail(r, call, "%s: %s", name, chm_dev_strerror(r));
        }
        if (r == 0) a->last_t = device_time(u);
    }
    if (r == 0 && !attach_actuator(dd, a))
        r = fail(CHM_EDEV_BADF, call, "%s: descriptor %d closed while opening", name, dd);
    if (r < 0) {
        delete a;
        close_quiet(dd);
        return r;
    }
    return dd;
}

static int impl_actuator_set_limits(int ad, const chm_actuator_limits_t* lim) {
    Use u(ad, "chm_actuator_set_limits");
    Actuator* a = nullptr;
    if (int r = actuator_of(u, &a); r < 0) return r;
    if (int r = check_limits(u, a->info, lim); r < 0) return r;
    Lock l(&a->mu);
    a->lim = *lim;
    a->last_t = device_time(u);  // the rate is measured from here
    return 0;
}

static int impl_actuator_write(int ad, const double* v, uint32_t n) {
    const char* call = "chm_actuator_write";
    Use u(ad, call);
    Actuator* a = nullptr;
    if (int r = actuator_of(u, &a); r < 0) return r;
    if (!v || n != a->info.n)
        return fail(CHM_ESIO_INVAL, call, "%s: %s vector of %u elements (the actuator has %u)", u.name,
                    v ? "a" : "NULL", n, a->info.n);
    for (std::uint32_t i = 0; i < n; ++i)
        if (std::isnan(v[i])) return fail(CHM_ESIO_INVAL, call, "%s: element %u is NaN", u.name, i);
    Lock l(&a->mu);
    if (a->stopped)
        return fail(CHM_EACT_STOPPED, call, "%s: in safe stop; chm_actuator_resume first", u.name);
    const chm_actuator_limits_t& lim = a->lim;
    const bool rate = any_rate(lim);
    const std::uint64_t t = rate ? device_time(u) : 0;
    const double dt = rate && t > a->last_t ? double(t - a->last_t) * 1e-9 : 0.0;
    double out[CHM_SIO_MAX];
    int first_bad = -1;
    bool rate_hit = false;
    for (std::uint32_t i = 0; i < n; ++i) {
        double x = v[i];
        if (x < lim.min[i]) x = lim.min[i];
        if (x > lim.max[i]) x = lim.max[i];
        if (lim.max_rate[i] > 0) {
            const double step = lim.max_rate[i] * dt, prev = a->st.last[i];
            if (x > prev + step) { x = prev + step; rate_hit = true; }
            if (x < prev - step) { x = prev - step; rate_hit = true; }
        }
        if (x != v[i] && first_bad < 0) first_bad = int(i);
        out[i] = x;
    }
    if (first_bad >= 0 && lim.mode == CHM_LIMIT_REFUSE) {
        a->st.refused++;
        const int i = first_bad;
        return fail(CHM_EACT_LIMIT, call, "%s: element %d = %g beyond its limits [%g, %g]%s (refused)",
                    u.name, i, v[i], lim.min[i], lim.max[i], rate_hit ? " or rate" : "");
    }
    const int r = drv_ioctl(u, CHM_SIO_IOC_ACT_WRITE, out);
    if (r < 0) return fail(r, call, "%s: %s", u.name, chm_dev_strerror(r));
    a->st.writes++;
    std::memcpy(a->st.last, out, n * sizeof(double));
    if (rate) a->last_t = t;
    if (first_bad < 0) return 0;
    a->st.clamped++;
    if (rate_hit) a->st.rate_limited++;
    const int i = first_bad;
    return fail(CHM_ACT_CLAMPED, call, "%s: element %d = %g clamped to %g (limits [%g, %g]%s)", u.name, i,
                v[i], out[i], lim.min[i], lim.max[i], rate_hit ? ", rate" : "");
}

static int impl_actuator_stop(int ad) {
    const char* call = "chm_actuator_stop";
    Use u(ad, call);
    Actuator* a = nullptr;
    if (int r = actuator_of(u, &a); r < 0) return r;
    Lock l(&a->mu);
    const int r = drv_ioctl(u, CHM_SIO_IOC_ACT_STOP, nullptr);
    if (r < 0) return fail(r, call, "%s: safe stop failed: %s", u.name, chm_dev_strerror(r));
    a->stopped = true;
    a->st.stops++;
    std::memset(a->st.last, 0, sizeof a->st.last);
    return 0;
}

static int impl_actuator_resume(int ad) {
    const char* call = "chm_actuator_resume";
    Use u(ad, call);
    Actuator* a = nullptr;
    if (int r = actuator_of(u, &a); r < 0) return r;
    Lock l(&a->mu);
    const int r = drv_ioctl(u, CHM_SIO_IOC_ACT_RESUME, nullptr);
    if (r < 0) return fail(r, call, "%s: %s", u.name, chm_dev_strerror(r));
    a->stopped = false;
    std::memset(a->st.last, 0, sizeof a->st.last);
    a->last_t = device_time(u);
    return 0;
}

static int impl_actuator_stats(int ad, chm_actuator_stats_t* out) {
    const char* call = "chm_actuator_stats";
    Use u(ad, call);
    Actuator* a = nullptr;
    if (int r = actuator_of(u, &a); r < 0) return r;
    if (!out) return fail(CHM_ESIO_INVAL, call, "%s: NULL stats", u.name);
    Lock l(&a->mu);
    *out = a->st;
    return 0;
}

int chm_dev_safe_stop_all(void) {
    int dds[CHM_DEV_MAX_OPEN];
    const int n = list_open(dds, CHM_DEV_MAX_OPEN, true, CHM_TID_NONE, true);
    int stopped = 0;
    for (int i = 0; i < n; ++i)
        if (impl_actuator_stop(dds[i]) == 0) ++stopped;
    return stopped;
}


// The public entry points: one error signal, at the exit (see leave()).
int chm_sensor_open(const char* name) { return int(leave(impl_sensor_open(name))); }
int chm_sensor_info(int sd, chm_sio_info_t* info) { return int(leave(impl_sensor_info(sd, info))); }
int chm_sensor_read(int sd, chm_sensor_sample_t* out) { return int(leave(impl_sensor_read(sd, out))); }
int chm_actuator_info(int ad, chm_sio_info_t* info) { return int(leave(impl_actuator_info(ad, info))); }
int chm_actuator_open(const char* name, const chm_actuator_limits_t* lim) { return int(leave(impl_actuator_open(name, lim))); }
int chm_actuator_set_limits(int ad, const chm_actuator_limits_t* lim) { return int(leave(impl_actuator_set_limits(ad, lim))); }
int chm_actuator_write(int ad, const double* v, uint32_t n) { return int(leave(impl_actuator_write(ad, v, n))); }
int chm_actuator_stop(int ad) { return int(leave(impl_actuator_stop(ad))); }
int chm_actuator_resume(int ad) { return int(leave(impl_actuator_resume(ad))); }
int chm_actuator_stats(int ad, chm_actuator_stats_t* out) { return int(leave(impl_actuator_stats(ad, out))); }

}  // extern "C"
