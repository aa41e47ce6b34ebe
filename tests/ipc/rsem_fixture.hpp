// A private backplane with remote semaphores in common memory: the helpers
// the remote-semaphore, wake-up and spin tests share.
#pragma once

#include <cstdint>

#include "chimera/rsem.h"
#include "chimera/shm.h"
#include "ipc_fixture.hpp"

namespace chm::test {

class RsemTest : public IpcTest {
protected:
    chm_rsem_t* make(const char* name, chm_sem_kind kind = CHM_SEM_COUNTING, std::uint32_t initial = 0) {
        chm_rsem_t* s = nullptr;
        EXPECT_EQ(chm_rsem_create(name, kind, initial, CHM_SHM_COMMON, &s), 0) << chm_bp_last_error();
        return s;
    }
    // Wait (bounded) until `n` tasks or threads wait on `s`.
    bool until_waiting(chm_rsem_t* s, int n, int timeout_ms = 10000) {
        const std::uint64_t end = now_ns() + std::uint64_t(timeout_ms) * 1000000u;
        while (now_ns() < end) {
            if (chm_rsem_waiting(s) == n) return true;
            sleep_us(200);
        }
        return false;
    }
};

// Open `name` (in a child or a task); nullptr when it fails.
inline chm_rsem_t* open_sem(const char* name) {
    chm_rsem_t* s = nullptr;
    return chm_rsem_open(name, &s) == 0 ? s : nullptr;
}

}  // namespace chm::test
