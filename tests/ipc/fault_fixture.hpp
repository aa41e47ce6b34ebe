// Scaffolding the containment tests share (test_ipc_fault.cpp: the fault
// points; test_ipc_fault_paths.cpp: the real paths): a block of memory
// shared with the forked RTPU children, and the private backplane with the
// queue most cases use.
#pragma once

#include <sys/mman.h>

#include <cstdint>
#include <new>

#include "chimera/rsem.h"
#include "chimera/shm.h"
#include "msgq_fixture.hpp"

namespace chm::test {

inline constexpr std::uint32_t kDepth = 4;  // the capacity of queue "fq"

// A T in anonymous shared memory, made before a fork: what a child writes
// there (its failure text, its figures) the parent reads. Unmapped when
// the test ends, however it ends.
template <class T>
class SharedBlock {
public:
    SharedBlock() {
        void* m = mmap(nullptr, sizeof(T), PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
        p_ = m == MAP_FAILED ? nullptr : new (m) T();
    }
    ~SharedBlock() {
        if (!p_) return;
        p_->~T();
        munmap(p_, sizeof(T));
    }
    SharedBlock(const SharedBlock&) = delete;
    SharedBlock& operator=(const SharedBlock&) = delete;
    T* get() const { return p_; }
    T* operator->() const { return p_; }

private:
    T* p_;
};

class FaultTest : public MsgqTest {
protected:
    // A private backplane, this process attached to it as a host, and the
    // queue "fq" (FIFO, 8-byte messages, kDepth deep) in *q. With `xmail`
    // its ring records have room for an express-mail server's replies.
    // Call through ASSERT_NO_FATAL_FAILURE.
    void attach_with_queue(chm_msgq_t** q, bool xmail = false) {
        chm_bp_config_t cfg = small_config();
        if (xmail) cfg.ring_record_size = 1024;
        ASSERT_NO_FATAL_FAILURE(create(cfg));
        ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0) << chm_bp_last_error();
        *q = make_queue("fq", CHM_MSGQ_FIFO, 8, kDepth);
        ASSERT_NE(*q, nullptr);
    }
    // The counting semaphore "fs" at 0 in *s.
    void make_sem(chm_rsem_t** s) {
        ASSERT_EQ(chm_rsem_create("fs", CHM_SEM_COUNTING, 0, CHM_SHM_COMMON, s), 0) << chm_bp_last_error();
    }
};

}  // namespace chm::test
