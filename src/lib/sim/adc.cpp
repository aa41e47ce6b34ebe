// Simulated A/D and D/A converter. Another process writes the analog input
// voltages (chm_sim_adc_set_input, `chimera-sim adc set`); the converter
// quantises them at once into the input registers. The RTPU writes output
// codes (level 1) or volts (level 2, quantised here); another process reads
// them. Level-1 register space (int32 codes, mappable): inputs 0..n_in-1
// (read-only), then outputs 0..n_out-1.
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>

#include "drivers.hpp"

namespace chm::sim {
namespace {

bool is_adc(chm_sim_t* s) { return s && chm_sim_kind_of(s) == CHM_SIM_ADC; }

std::int32_t top(std::uint32_t bits) { return std::int32_t((1u << bits) - 1); }

// The safe output: the code nearest 0 V.
void outputs_safe_locked(chm_sim_t* s) {
    const AdcFile* f = as<AdcFile>(s);
    const std::int32_t z = to_code(0.0, f->cfg.vmin, f->cfg.vmax, f->cfg.bits_out);
    for (std::uint32_t j = 0; j < f->cfg.n_out; ++j) adc_regs(s)[f->cfg.n_in + j] = z;
    bump(s);
}

int adc_open(void* ctx, int flags, void** inst, std::uint64_t* range) {
    chm_sim_t* s = static_cast<DevCtx*>(ctx)->sim;
    const AdcFile* f = as<AdcFile>(s);
    *range = (f->cfg.n_in + f->cfg.n_out) * sizeof(std::int32_t);
    if (!*range) return CHM_EDEV_INVAL;
    return generic_open(ctx, flags, inst);
}

int64_t adc_read(void* inst, void* buf, std::size_t n, std::uint64_t off) {
    chm_sim_t* s = static_cast<Inst*>(inst)->ctx->sim;
    Locked l(s);
    std::memcpy(buf, reinterpret_cast<char*>(adc_regs(s)) + off, n);
    return int64_t(n);
}

int64_t adc_write(void* inst, const void* buf, std::size_t n, std::uint64_t off) {
    chm_sim_t* s = static_cast<Inst*>(inst)->ctx->sim;
    Locked l(s);
    const AdcFile* f = as<AdcFile>(s);
    const std::uint64_t lo = f->cfg.n_in * sizeof(std::int32_t);
    if (off < lo) return CHM_EDEV_ACCES;  // the input registers are read-only
    if (off % 4 || n % 4) return CHM_EDEV_INVAL;
    std::int32_t codes[CHM_SIM_ADC_MAX];
    std::memcpy(codes, buf, n);
    for (std::size_t k = 0; k < n / 4; ++k)
        if (codes[k] < 0 || codes[k] > top(f->cfg.bits_out)) return -ERANGE;  // beyond the D/A's bits
    std::memcpy(reinterpret_cast<char*>(adc_regs(s)) + off, codes, n);
    bump(s);
    return int64_t(n);
}

int adc_ioctl(void* inst, unsigned long req, void* arg) {
    Inst* in = static_cast<Inst*>(inst);
    chm_sim_t* s = in->ctx->sim;
    if (!arg && req != CHM_SIO_IOC_ACT_STOP && req != CHM_SIO_IOC_ACT_RESUME) return CHM_EDEV_INVAL;
    if (req == CHM_DEV_IOC_EVENT_FD) {
        *static_cast<int*>(arg) = s->irq_fd;
        return s->irq_fd >= 0 ? 0 : -ENODEV;
    }
    if (req == CHM_DEV_IOC_TIME) {
        *static_cast<std::uint64_t*>(arg) = mono_ns();
        return 0;
    }
    Locked l(s);
    const AdcFile* f = as<AdcFile>(s);
    const chm_sim_adc_config_t& c = f->cfg;
    std::int32_t* regs = adc_regs(s);
    switch (req) {
    case CHM_SIO_IOC_SENSOR_INFO:
    case CHM_SIO_IOC_ACT_INFO: {
        const bool out = req == CHM_SIO_IOC_ACT_INFO;
        if ((out ? c.n_out : c.n_in) == 0) return CHM_EDEV_NOTTY;  // no such side
        auto* info = static_cast<chm_sio_info_t*>(arg);
        std::memset(info, 0, sizeof *info);
        info->n = out ? c.n_out : c.n_in;
        info->time_domain = CHM_TIME_MONOTONIC;
        char nm[16];
        for (std::uint32_t i = 0; i < info->n; ++i) {
            std::snprintf(nm, sizeof nm, out ? "ao%u" : "ai%u", i);
            sio_set(info, i, nm, "V", c.vmin, c.vmax);
        }
        return 0;
    }
    case CHM_SIO_IOC_SENSOR_READ: {
        if (!c.n_in) return CHM_EDEV_NOTTY;
        auto* smp = static_cast<chm_sensor_sample_t*>(arg);
        smp->t_ns = mono_ns();  // sampled now: the registers hold the latest conversion
        smp->n = c.n_in;
        for (std::uint32_t i = 0; i < c.n_in; ++i) smp->v[i] = from_code(regs[i], c.vmin, c.vmax, c.bits_in);
        return 0;
    }
    case CHM_SIO_IOC_ACT_WRITE: {
        if (!c.n_out) return CHM_EDEV_NOTTY;
        if (!(in->flags & CHM_DEV_WRITE)) return CHM_EDEV_ACCES;
        const double* v = static_cast<const double*>(arg);
        for (std::uint32_t j = 0; j < c.n_out; ++j) regs[c.n_in + j] = to_code(v[j], c.vmin, c.vmax, c.bits_out);
        bump(s);
        return 0;
    }
    case CHM_SIO_IOC_ACT_STOP:
    case CHM_SIO_IOC_ACT_RESUME:
        if (!c.n_out) return CHM_EDEV_NOTTY;
        if (req == CHM_SIO_IOC_ACT_RESUME && !(in->flags & CHM_DEV_WRITE)) return CHM_EDEV_ACCES;
        outputs_safe_locked(s);
        return 0;
    default: return CHM_EDEV_NOTTY;
    }
}

// The register page mapped from the file itself: the same memory every
// process sees, no copy.
int adc_mmap(void* inst, std::uint64_t off, std::size_t len, int prot, void** addr) {
    chm_sim_t* s = static_cast<Inst*>(inst)->ctx->sim;
    const int p = ((prot & CHM_DEV_PROT_READ) ? PROT_READ : 0) | ((prot & CHM_DEV_PROT_WRITE) ? PROT_WRITE : 0);
    void* m = mmap(nullptr, std::size_t(off) + len, p, MAP_SHARED, s->fd, off_t(kPage));
    if (m == MAP_FAILED) return -errno;
    *addr = static_cast<char*>(m) + off;
    return 0;
}

int adc_munmap(void*, void* addr, std::size_t len) {
    const std::uintptr_t a = reinterpret_cast<std::uintptr_t>(addr);
    const std::uintptr_t base = a & ~std::uintptr_t(kPage - 1);
    return munmap(reinterpret_cast<void*>(base), len + (a - base)) == 0 ? 0 : -errno;
}

int check_channel(chm_sim_t* s, std::uint32_t ch, bool out) {
    if (!is_adc(s)) return -EINVAL;
    const AdcFile* f = as<AdcFile>(s);
    return ch < (out ? f->cfg.n_out : f->cfg.n_in) ? 0 : -ERANGE;
}

}  // namespace

const chm_dev_ops_t kAdcOps = {adc_open, generic_close, adc_read, adc_write, adc_ioctl, adc_mmap, adc_munmap};

}  // namespace chm::sim

using namespace chm::sim;

extern "C" {

void chm_sim_adc_config_init(chm_sim_adc_config_t* c) {
    std::memset(c, 0, sizeof *c);
    c->n_in = 8;
    c->n_out = 4;
    c->bits_in = 12;
    c->bits_out = 12;
    c->vmin = -10.0;
    c->vmax = 10.0;
}

int chm_sim_adc_create(const char* path, const chm_sim_adc_config_t* c) {
    if (!path || !c || c->n_in > CHM_SIM_ADC_MAX || c->n_out > CHM_SIM_ADC_MAX || c->n_in + c->n_out == 0 ||
        c->bits_in < 1 || c->bits_in > 24 || c->bits_out < 1 || c->bits_out > 24 || !(c->vmin < c->vmax))
        return -EINVAL;
    AdcFile f{};
    f.cfg = *c;
    const int r = file_create(path, CHM_SIM_ADC, &f, sizeof f, 2 * kPage);
    if (r < 0) return r;
    // Inputs at 0 V, outputs at their safe value.
    chm_sim_t* s = nullptr;
    if (chm_sim_attach(path, &s) == 0) {
        {
            Locked l(s);
            for (std::uint32_t i = 0; i < c->n_in; ++i) adc_regs(s)[i] = to_code(0.0, c->vmin, c->vmax, c->bits_in);
            outputs_safe_locked(s);
        }
        chm_sim_detach(s);
    }
    return 0;
}

int chm_sim_adc_set_input(chm_sim_t* s, uint32_t ch, double volts) {
    if (int r = check_channel(s, ch, false); r < 0) return r;
    {
        Locked l(s);
        AdcFile* f = as<AdcFile>(s);
        f->in_volts[ch] = volts;
        f->in_t_ns = mono_ns();
        adc_regs(s)[ch] = to_code(volts, f->cfg.vmin, f->cfg.vmax, f->cfg.bits_in);
        bump(s);
    }
    raise_line(s);
    return 0;
}

int chm_sim_adc_get_output(chm_sim_t* s, uint32_t ch, double* volts, int32_t* code) {
    if (int r = check_channel(s, ch, true); r < 0) return r;
    Locked l(s);
    const AdcFile* f = as<AdcFile>(s);
    const std::int32_t c = adc_regs(s)[f->cfg.n_in + ch];
    if (code) *code = c;
    if (volts) *volts = from_code(c, f->cfg.vmin, f->cfg.vmax, f->cfg.bits_out);
    return 0;
}

int chm_sim_adc_get_input(chm_sim_t* s, uint32_t ch, double* volts, int32_t* code) {
    if (int r = check_channel(s, ch, false); r < 0) return r;
    Locked l(s);
    const AdcFile* f = as<AdcFile>(s);
    const std::int32_t c = adc_regs(s)[ch];
    if (code) *code = c;
    if (volts) *volts = from_code(c, f->cfg.vmin, f->cfg.vmax, f->cfg.bits_in);
    return 0;
}

}  // extern "C"
