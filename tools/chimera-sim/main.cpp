// chimera-sim: create, drive and watch simulated devices from a shell or a
// test in another process. Every command works on a device's shared-state
// file; a name without '/' is a file in the simulation directory
// ($CHIMERA_SIM_DIR or /dev/shm/chimera-sim-<uid>). Output is one line of
// key=value fields per reading, easy to read and to parse.
#include <dirent.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "sim.h"

namespace {

const char* const kUsage =
    "usage: chimera-sim [--dir DIR] <device> <command> <file> [args]\n"
    "  arm create <file> [--joints N] [--clock monotonic|manual|kernel] [--dt S]\n"
    "                    [--gravity G] [--hold] [--surface Z] [--k K] [--c C] [--q0 a,b,..]\n"
    "                    [--gripper] [--object X (needs --surface)]\n"
    "  arm get|watch <file>          state: t, q, qd, tau, tip, contact force\n"
    "  arm step <file> <steps>       integrate steps (manual clock)\n"
    "  arm torque <file> t1 [t2..]   set the amplifiers' input (N*m)\n"
    "  arm stop|resume <file>        safe stop / leave it\n"
    "  arm grip <file> <opening>     command the gripper's opening (m)\n"
    "  ft create <file> [--arm ARMFILE] [--surface Z] [--k K] [--c C]\n"
    "  ft probe <file> x y z [vz]    move the probe (m, m/s)\n"
    "  ft get|watch <file>           wrench\n"
    "  adc create <file> [--in N] [--out N] [--bits B] [--bits-out B] [--min V] [--max V]\n"
    "  adc set <file> <ch> <volts>   drive an analog input\n"
    "  adc get|watch <file>          inputs and outputs (volts, codes)\n"
    "  serial create <file>\n"
    "  serial peer <file>            the pseudo-terminal to talk to\n"
    "  list                          device files in the directory\n"
    "  rm <file>                     remove a device file\n"
    "watch options: --count N (0 = forever, default) --interval-ms M (default 100)\n";

int usage() {
    std::fputs(kUsage, stderr);
    return 2;
}

int fail(const char* what, int r) {
    std::fprintf(stderr, "chimera-sim: %s: %s\n", what, std::strerror(-r));
    return 1;
}

// A value that is not what its option or argument wants: main says which
// and exits 2, before anything is created or changed.
struct BadValue {
    std::string why;
};

// `text` as a finite number; `what` names the option or argument.
double num(const std::string& what, const std::string& text) {
    char* end = nullptr;
    errno = 0;
    const double v = std::strtod(text.c_str(), &end);
    if (text.empty() || *end || errno == ERANGE || !std::isfinite(v))
        throw BadValue{what + ": \"" + text + "\" is not a number"};
    return v;
}

// `text` as a whole number in [0, hi].
unsigned long whole(const std::string& what, const std::string& text, unsigned long hi) {
    char* end = nullptr;
    errno = 0;
    const unsigned long v = std::strtoul(text.c_str(), &end, 10);
    if (text.empty() || text[0] == '-' || *end || errno == ERANGE || v > hi)
        throw BadValue{what + ": \"" + text + "\" is not a whole number in 0.." + std::to_string(hi)};
    return v;
}

// Options after the positional arguments: --name value (or a lone flag).
struct Opts {
    std::vector<std::string> pos;
    std::vector<std::pair<std::string, std::string>> kv;
    const char* get(const char* k, const char* def = nullptr) const {
        for (const auto& p : kv)
            if (p.first == k) return p.second.c_str();
        return def;
    }
    bool has(const char* k) const { return get(k) != nullptr; }
    double number(const char* k, const char* def) const { return num(std::string("--") + k, get(k, def)); }
    unsigned long count(const char* k, const char* def, unsigned long hi) const {
        return whole(std::string("--") + k, get(k, def), hi);
    }
};

Opts parse(int argc, char** argv, int from) {
    Opts o;
    for (int i = from; i < argc; ++i) {
        std::string a = argv[i];
        if (a.rfind("--", 0) == 0 && a.size() > 2 && !(a[2] >= '0' && a[2] <= '9')) {
            const bool flag = a == "--hold" || a == "--gripper";
            o.kv.emplace_back(a.substr(2), flag || i + 1 >= argc ? "1" : argv[++i]);
        } else {
            o.pos.push_back(a);
        }
    }
    return o;
}

void print_vec(const char* key, const double* v, int n) {
    std::printf(" %s=", key);
    for (int i = 0; i < n; ++i) std::printf(i ? ",%.9g" : "%.9g", v[i]);
}

int attach(const std::string& name, chm_sim_t** s, chm_sim_kind want) {
    char path[CHM_SIM_PATH_MAX];
    if (int r = chm_sim_path(name.c_str(), path, sizeof path); r < 0) return fail(name.c_str(), r);
    if (int r = chm_sim_attach(path, s); r < 0) return fail(path, r);
    if (chm_sim_kind_of(*s) != want) {
        std::fprintf(stderr, "chimera-sim: %s is a different kind of device\n", path);
        chm_sim_detach(*s);
        return 1;
    }
    return 0;
}

int print_once(chm_sim_t* s, chm_sim_kind kind) {
    switch (kind) {
    case CHM_SIM_ARM: {
        chm_sim_arm_state_t st;
        if (int r = chm_sim_arm_read(s, &st); r < 0) return fail("read", r);
        const int n = int(st.joints);
        std::printf("t=%.6f", double(st.t_ns) * 1e-9);
        print_vec("q", st.q, n);
        print_vec("qd", st.qd, n);
        print_vec("tau", st.tau, n);
        print_vec("tip", st.tip, 2);
        print_vec("F", st.wrench, 3);
        std::printf(" contact=%u stopped=%u energy=%.9g", st.in_contact, st.stopped, st.kinetic + st.potential);
        if (st.grip_cmd > 0 || st.grip_opening > 0 || st.held) {  // a gripper
            std::printf(" grip=%.4f Fgrip=%.3f held=%u", st.grip_opening, st.grip_force, st.held);
            print_vec("object", st.object, 2);
        }
        std::printf("\n");
        break;
    }
    case CHM_SIM_FT: {
        double w[6];
        std::uint64_t t = 0;
        if (int r = chm_sim_ft_read(s, w, &t); r < 0) return fail("read", r);
        std::printf("t=%.6f", double(t) * 1e-9);
        print_vec("F", w, 3);
        print_vec("T", w + 3, 3);
        std::printf("\n");
        break;
    }
    case CHM_SIM_ADC: {
        std::printf("seq=%llu", (unsigned long long)chm_sim_seq(s));
        std::vector<double> v;
        std::vector<int> c;
        for (int out = 0; out < 2; ++out) {
            v.clear();
            c.clear();
            for (std::uint32_t ch = 0;; ++ch) {
                double x;
                int32_t code;
                const int r = out ? chm_sim_adc_get_output(s, ch, &x, &code) : chm_sim_adc_get_input(s, ch, &x, &code);
                if (r < 0) break;
                v.push_back(x);
                c.push_back(code);
            }
            print_vec(out ? "out" : "in", v.data(), int(v.size()));
            std::printf(" %s=", out ? "out_code" : "in_code");
            for (std::size_t i = 0; i < c.size(); ++i) std::printf(i ? ",%d" : "%d", c[i]);
        }
        std::printf("\n");
        break;
    }
    default: return 1;
    }
    std::fflush(stdout);
    return 0;
}

int watch(chm_sim_t* s, chm_sim_kind kind, const Opts& o) {
    const unsigned long count = o.count("count", "0", 1000000000);
    const unsigned long ms = o.count("interval-ms", "100", 3600000);
    for (unsigned long i = 0; count == 0 || i < count; ++i) {
        if (i) usleep(useconds_t(ms > 0 ? ms : 1) * 1000);
        if (int r = print_once(s, kind); r) return r;
    }
    return 0;
}

// A comma-separated list of numbers (--q0).
std::vector<double> numbers(const std::string& what, const std::string& csv) {
    std::vector<double> v;
    for (std::size_t from = 0; from < csv.size();) {
        const std::size_t comma = std::min(csv.find(',', from), csv.size());
        v.push_back(num(what, csv.substr(from, comma - from)));
        from = comma + 1;
    }
    return v;
}

int create(const std::string& dev, const char* path, const Opts& o) {
    int r = -EINVAL;
    if (dev == "arm") {
        chm_sim_arm_config_t c;
        chm_sim_arm_config_init(&c, std::uint32_t(o.count("joints", "2", CHM_SIM_ARM_MAX)));
        const std::string clock = o.get("clock", "monotonic");
        c.clock = clock == "manual" ? CHM_SIM_CLOCK_MANUAL : clock == "kernel" ? CHM_SIM_CLOCK_KERNEL : CHM_SIM_CLOCK_MONOTONIC;
        if (clock != "manual" && clock != "kernel" && clock != "monotonic")
            throw BadValue{"--clock: \"" + clock + "\" is not monotonic, manual or kernel"};
        c.dt_s = o.number("dt", "0.0005");
        c.gravity = o.number("gravity", "9.81");
        if (o.has("hold")) c.stop_mode = CHM_SIM_STOP_HOLD;
        if (o.has("surface")) {
            c.contact = 1;
            c.surface_z = o.number("surface", nullptr);
        }
        c.contact_k = o.number("k", "1e4");
        c.contact_c = o.number("c", "50");
        const std::vector<double> q0 = numbers("--q0", o.get("q0", ""));
        for (std::size_t i = 0; i < q0.size() && i < CHM_SIM_ARM_MAX; ++i) c.q0[i] = q0[i];
        c.gripper = o.has("gripper") || o.has("object");
        if (o.has("object")) {
            if (!o.has("surface")) throw BadValue{"--object needs --surface (the object rests on it)"};
            c.object = 1;
            c.object_x = o.number("object", nullptr);
        }
        r = chm_sim_arm_create(path, &c);
    } else if (dev == "ft") {
        chm_sim_ft_config_t c;
        chm_sim_ft_config_init(&c);
        if (o.has("arm") && chm_sim_path(o.get("arm"), c.arm_path, sizeof c.arm_path) < 0) return usage();
        c.surface_z = o.number("surface", "0");
        c.contact_k = o.number("k", "1e4");
        c.contact_c = o.number("c", "50");
        r = chm_sim_ft_create(path, &c);
    } else if (dev == "adc") {
        chm_sim_adc_config_t c;
        chm_sim_adc_config_init(&c);
        c.n_in = std::uint32_t(o.count("in", "8", 1024));
        c.n_out = std::uint32_t(o.count("out", "4", 1024));
        c.bits_in = std::uint32_t(o.count("bits", "12", 32));
        c.bits_out = std::uint32_t(o.count("bits-out", o.get("bits", "12"), 32));
        c.vmin = o.number("min", "-10");
        c.vmax = o.number("max", "10");
        r = chm_sim_adc_create(path, &c);
    } else if (dev == "serial") {
        r = chm_sim_serial_create(path);
    } else {
        return usage();
    }
    if (r < 0) return fail(path, r);
    std::printf("%s\n", path);
    return 0;
}

int list(const char* dir) {
    DIR* d = opendir(dir);
    if (!d) return fail(dir, -errno);
    static const char* const kinds[] = {"?", "arm", "ft", "adc", "serial"};
    while (const dirent* e = readdir(d)) {
        if (e->d_name[0] == '.' || std::strchr(e->d_name, '.')) continue;
        std::string p = std::string(dir) + "/" + e->d_name;
        chm_sim_t* s = nullptr;
        if (chm_sim_attach(p.c_str(), &s) < 0) continue;
        std::printf("%s %s\n", e->d_name, kinds[chm_sim_kind_of(s)]);
        chm_sim_detach(s);
    }
    closedir(d);
    return 0;
}

}  // namespace

int run(int argc, char** argv) {
    int i = 1;
    if (i + 1 < argc && std::strcmp(argv[i], "--dir") == 0) {
        setenv("CHIMERA_SIM_DIR", argv[i + 1], 1);
        i += 2;
    }
    if (i >= argc) return usage();
    const std::string dev = argv[i];
    if (dev == "list") return list(chm_sim_dir());
    if (i + 2 >= argc) return usage();
    const std::string cmd = argv[i + 1];
    char path[CHM_SIM_PATH_MAX];
    if (dev == "rm") {
        if (int r = chm_sim_path(argv[i + 1], path, sizeof path); r < 0) return fail(argv[i + 1], r);
        const int r = chm_sim_remove(path);
        return r < 0 ? fail(path, r) : 0;
    }
    if (int r = chm_sim_path(argv[i + 2], path, sizeof path); r < 0) return fail(argv[i + 2], r);
    const Opts o = parse(argc, argv, i + 3);
    if (cmd == "create") return create(dev, path, o);

    const chm_sim_kind kind = dev == "arm" ? CHM_SIM_ARM : dev == "ft" ? CHM_SIM_FT
                            : dev == "adc" ? CHM_SIM_ADC : dev == "serial" ? CHM_SIM_SERIAL : chm_sim_kind(0);
    if (!kind) return usage();
    chm_sim_t* s = nullptr;
    if (int r = attach(argv[i + 2], &s, kind); r) return r;
    struct Detach {  // also when a bad value throws below
        chm_sim_t*& s;
        ~Detach() {
            if (s) chm_sim_detach(s);
        }
    } detach{s};
    int rc = 0, r = 0;
    if (cmd == "get") {
        rc = print_once(s, kind);
    } else if (cmd == "watch") {
        rc = watch(s, kind, o);
    } else if (kind == CHM_SIM_ARM && cmd == "step" && o.pos.size() == 1) {
        r = chm_sim_arm_step(s, whole("steps", o.pos[0], 1000000000));
    } else if (kind == CHM_SIM_ARM && cmd == "torque" && !o.pos.empty()) {
        std::vector<double> tau;
        for (const auto& p : o.pos) tau.push_back(num("torque", p));
        r = chm_sim_arm_set_torque(s, tau.data(), std::uint32_t(tau.size()));
    } else if (kind == CHM_SIM_ARM && cmd == "grip" && o.pos.size() == 1) {
        r = chm_sim_arm_set_grip(s, num("opening", o.pos[0]));
    } else if (kind == CHM_SIM_ARM && (cmd == "stop" || cmd == "resume")) {
        r = cmd == "stop" ? chm_sim_arm_stop(s) : chm_sim_arm_resume(s);
    } else if (kind == CHM_SIM_FT && cmd == "probe" && o.pos.size() >= 3) {
        const double pos[3] = {num("x", o.pos[0]), num("y", o.pos[1]), num("z", o.pos[2])};
        const double vel[3] = {0, 0, o.pos.size() > 3 ? num("vz", o.pos[3]) : 0.0};
        r = chm_sim_ft_set_probe(s, pos, vel);
    } else if (kind == CHM_SIM_ADC && cmd == "set" && o.pos.size() == 2) {
        r = chm_sim_adc_set_input(s, std::uint32_t(whole("channel", o.pos[0], 1023)), num("volts", o.pos[1]));
    } else if (kind == CHM_SIM_SERIAL && cmd == "peer") {
        char peer[CHM_SIM_PATH_MAX];
        r = chm_sim_serial_peer(s, peer, sizeof peer);
        if (r == 0 && !peer[0]) {
            std::fprintf(stderr, "chimera-sim: %s: no RTPU has registered the port yet\n", path);
            rc = 1;
        } else if (r == 0) {
            std::printf("%s\n", peer);
        }
    } else {
        rc = usage();
    }
    if (r < 0) return fail(cmd.c_str(), r);
    return rc;
}

int main(int argc, char** argv) {
    try {
        return run(argc, argv);
    } catch (const BadValue& e) {
        std::fprintf(stderr, "chimera-sim: %s\n", e.why.c_str());
        return 2;
    }
}
