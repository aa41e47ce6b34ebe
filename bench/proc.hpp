// Helpers for peers that span two processes or two threads: memory shared
// across fork without a name to clean up, a child process that dies with us
// and is always reaped, a partner thread that is always joined, and the
// futex calls the raw ping-pongs use.
#pragma once

#include <sys/types.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <new>
#include <string>
#include <thread>

#include "harness.hpp"

namespace chm::bench {

void* map_shared(std::size_t bytes);  // MAP_SHARED | MAP_ANONYMOUS, zeroed
void unmap_shared(void* p, std::size_t bytes);

// A T in anonymous shared memory: a child forked after construction sees
// the same object. T must be usable from two processes (plain data, atomics
// that are lock-free, pshared primitives).
template <class T>
class SharedObj {
public:
    SharedObj() : p_(new (map_shared(sizeof(T))) T{}) {}
    ~SharedObj() {
        p_->~T();
        unmap_shared(p_, sizeof(T));
    }
    SharedObj(const SharedObj&) = delete;
    SharedObj& operator=(const SharedObj&) = delete;
    T* operator->() const { return p_; }
    T& operator*() const { return *p_; }

private:
    T* p_;
};

// A forked child running `body` pinned to `cpu` (-1: unpinned). The child
// gets SIGKILL when the parent dies (PR_SET_PDEATHSIG), so no orphan spins
// on; the destructor kills and reaps it on every path out of a measurement.
// Its death interrupts the parent's blocking waits (see abort_reason()).
class Child {
public:
    Child(int cpu, const std::function<int()>& body);
    ~Child();
    Child(const Child&) = delete;
    Child& operator=(const Child&) = delete;
    pid_t pid() const { return pid_; }

private:
    pid_t pid_ = -1;
};

// A helper thread pinned to `cpu`. The destructor calls `stop` (which must
// make `body` return, e.g. by setting a flag and posting a semaphore) and
// joins.
class Partner {
public:
    Partner(int cpu, std::function<void()> body, std::function<void()> stop);
    ~Partner();
    Partner(const Partner&) = delete;
    Partner& operator=(const Partner&) = delete;

private:
    std::function<void()> stop_;
    std::thread t_;
};

// Shared (not process-private) futex operations on a 32-bit word.
// futex_wait returns 0, or -1 with errno (EAGAIN: value differed; EINTR).
int futex_wait(std::atomic<std::uint32_t>* w, std::uint32_t expected);
void futex_wake(std::atomic<std::uint32_t>* w);

// Where the two ends of a ping-pong run: both on s.cpu(0) ("same_core") or on
// s.cpu(0) and s.cpu(1) ("xcore"); `text` states it for the row's config.
struct Pinning {
    int self, other;
    std::string text;
};

// Run `fn` for `<stem>_same_core` and then `<stem>_xcore`, the measuring
// thread pinned to p.self each time; the xcore row is skipped on one CPU.
void for_both_pinnings(Session& s, const std::string& stem, const char* ends,
                       const std::function<void(const std::string& row, const Pinning& p)>& fn);

// A name for a POSIX IPC object unique to this process and purpose.
std::string ipc_name(const char* what);

}  // namespace chm::bench
