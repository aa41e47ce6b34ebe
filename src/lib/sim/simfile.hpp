// Simulated devices: the shared-memory file every simulated device keeps
// its state in, and the layout of each kind. Files hold no pointers, only
// plain values, so every process maps them where it likes. One robust,
// process-shared mutex per file guards the state: a process that dies
// holding it leaves it recoverable (EOWNERDEAD), never deadlocked.
#pragma once

#include <pthread.h>

#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "sim.h"

struct chm_sim {
    int fd = -1;
    int irq_fd = -1;          // the FIFO, opened read-write and non-blocking
    void* base = nullptr;
    std::size_t size = 0;
    char path[CHM_SIM_PATH_MAX] = {};
};

namespace chm::sim {

inline constexpr std::uint32_t kMagic = 0x434d5331;  // "CMS1"
inline constexpr std::uint16_t kVersion = 2;  // 2: the arm's gripper and object
inline constexpr std::size_t kPage = 4096;           // the register page's offset

struct Header {
    std::uint32_t magic;
    std::uint16_t version;
    std::uint16_t kind;       // enum chm_sim_kind
    std::uint32_t size;       // file size
    std::uint32_t pad;
    std::uint64_t seq;        // bumped at every change
    pthread_mutex_t mu;
};

struct ArmFile {
    Header h;
    chm_sim_arm_config_t cfg;
    chm_sim_arm_state_t st;
    std::uint64_t wall_anchor_ns;  // CLOCK_MONOTONIC when sim time was 0 (monotonic clock)
    // Kernel clock: the RTPU (process) whose chm_time_now() drives the arm,
    // and which of its times matched which simulated time.
    std::int32_t kernel_pid;
    std::uint64_t kernel_anchor_ns, kernel_sim_anchor_ns;
};

struct FtFile {
    Header h;
    chm_sim_ft_config_t cfg;
    double probe_pos[3], probe_vel[3];
    std::uint32_t in_contact;
    std::uint64_t probe_t_ns;      // CLOCK_MONOTONIC of the last probe write
};

struct AdcFile {
    Header h;
    chm_sim_adc_config_t cfg;
    double in_volts[CHM_SIM_ADC_MAX];  // the analog signal as written
    std::uint64_t in_t_ns;             // CLOCK_MONOTONIC of the last conversion
};

struct SerialFile {
    Header h;
    char peer[CHM_SIM_PATH_MAX];
    std::int32_t owner_pid;
    chm_serial_line_t line;
    std::uint64_t rx_bytes, tx_bytes;
};

static_assert(std::is_standard_layout_v<ArmFile> && std::is_standard_layout_v<FtFile> &&
              std::is_standard_layout_v<AdcFile> && std::is_standard_layout_v<SerialFile>);
static_assert(sizeof(ArmFile) <= kPage && sizeof(FtFile) <= kPage && sizeof(AdcFile) <= kPage &&
              sizeof(SerialFile) <= kPage);

template <class T> T* as(chm_sim_t* s) { return static_cast<T*>(s->base); }
inline Header* header(chm_sim_t* s) { return static_cast<Header*>(s->base); }
// The A/D's register page at kPage (level 1 reads, writes and maps it):
// the input codes, then the output codes, int32 each.
inline std::int32_t* adc_regs(chm_sim_t* s) {
    return reinterpret_cast<std::int32_t*>(static_cast<char*>(s->base) + kPage);
}

// Create `path` atomically (written under a temporary name, then linked in
// place: -EEXIST if it exists) with `bytes` of state from `init` (its
// Header is filled here), and its FIFO.
int file_create(const char* path, chm_sim_kind kind, const void* init, std::size_t bytes,
                std::size_t file_size);

// Lock a file's state; recovers the lock of a process that died holding it.
class Locked {
public:
    explicit Locked(chm_sim_t* s);
    ~Locked();
    Locked(const Locked&) = delete;
    Locked& operator=(const Locked&) = delete;

private:
    chm_sim_t* s_;
};

// Mark a change (state lock held): watchers polling chm_sim_seq see it.
inline void bump(chm_sim_t* s) {
    __atomic_store_n(&header(s)->seq, header(s)->seq + 1, __ATOMIC_RELEASE);
}

// Raise the device's line: one byte into its FIFO (dropped when the FIFO is
// full: the line is already raised).
void raise_line(chm_sim_t* s);

// CLOCK_MONOTONIC in ns (the same clock in every process).
std::uint64_t mono_ns();

// Quantisation of the A/D and D/A.
std::int32_t to_code(double v, double vmin, double vmax, std::uint32_t bits);
double from_code(std::int32_t code, double vmin, double vmax, std::uint32_t bits);

}  // namespace chm::sim
