// Every row of the report, in report order: Chimera's own rows first (the
// Chimera II paper's Table 1, then the performance-target rows, then the rows the
// port provides today), then the peers, each rt-tests row beside the suite's
// matching peer. A Chimera row names the peer a user would otherwise pick;
// its measurement must use the same pinning as that peer (stated in both
// rows' config). Paper figures are the 25 MHz 68030 of 1991, in ns.
#include "catalog.hpp"


#include "harness.hpp"  // kNull

namespace chm::bench {
namespace {

constexpr double us = 1000.0;
constexpr Target none{};
constexpr Target ratio_le(double b) { return {Target::kRatioAtMost, b}; }

constexpr RowInfo kRows[] = {
    // ---- available today: the port layer
    {"port_switch", "ns", "peer_fiber_switch", kNull, ratio_le(1.5),
     "chm_port_switch between two contexts (callee-saved regs + MXCSR/x87 CW); one switch"},

    // ---- Chimera II Table 1: task management
    {"task_create", "ns", "peer_pthread_create_join", 220 * us, none,
     "spawn a task with default arguments"},
    {"task_destroy", "ns", "peer_pthread_create_join", 99 * us, none, "destroy a task"},
    {"task_set_priority", "ns", "peer_setschedparam", 20 * us, none,
     "change a task's static priority, queues rearranged"},
    // The target is against the host's own timer-signal floor measured the
    // same way (the _vs_floor row below). Signal-to-self is shown beside it
    // for orientation only: no timer is involved, and where the host makes
    // every timer expiry a VM exit (virtual machines of this kind) a timer
    // signal alone costs 8x a signal to self.
    {"timer_resched_noswitch", "ns", "peer_signal_self", 28 * us, none,
     "timer-driven reschedule, the running task stays"},
    {"timer_resched_noswitch_vs_floor", "ns", "peer_timer_signal_busy", kNull, ratio_le(1.5),
     "timer_resched_noswitch beside a POSIX timer signal stealing time from a computing thread"},
    {"context_switch_fpu", "ns", "peer_fiber_switch", 66 * us, none,
     "kernel task-to-task switch including FP state"},
    {"timer_resched_switch", "ns", "peer_thread_sem_pingpong_same_core", 94 * us, none,
     "timer-driven reschedule with a context switch"},
    {"resource_contention_resched", "ns", "peer_thread_sem_pingpong_same_core", 82 * us, none,
     "a task blocks on a resource, the next one runs"},
    {"tick_cpu_locked", "ns", "peer_signal_self", 6 * us, none,
     "timer tick with the CPU locked, no reschedule"},
    // ---- Table 1: local semaphores
    {"local_p_noblock", "ns", "peer_sem_wait", 7 * us, none, "P() that does not block"},
    {"local_p_block", "ns", "peer_thread_sem_pingpong_same_core", 89 * us, none,
     "P() that blocks, until the next task runs"},
    {"local_v_nowake", "ns", "peer_sem_post", 7 * us, none, "V() with nobody waiting"},
    {"local_v_wake", "ns", "peer_thread_sem_pingpong_same_core", 34 * us, none,
     "V() that wakes a blocked task"},
    // ---- Table 1: remote semaphores
    {"remote_semp_noblock", "ns", "peer_sem_wait", 27 * us, none, "remote semP() that does not block"},
    {"remote_semp_block", "ns", "peer_named_sem_pingpong_same_core", 109 * us, none,
     "remote semP() that blocks, with the contention reschedule"},
    {"remote_semv_nowake", "ns", "peer_sem_post", 26 * us, none, "remote semV() with nobody waiting"},
    {"remote_semv_wake_local", "ns", "peer_thread_sem_pingpong_same_core", 64 * us, none,
     "remote semV() waking a task on the caller's RTPU"},
    {"remote_semv_wake_remote", "ns", "peer_futex_pingpong_xcore", 100 * us, none,
     "remote semV() waking a task on another RTPU"},
    // ---- Table 1: priority message passing
    {"msg_put_24b_local", "ns", "peer_bipc_mq_send_24b", 62 * us, none,
     "put a 24-byte message, queue in local memory"},
    {"msg_put_24b_remote_one_process", "ns", "peer_bipc_mq_send_24b", 79 * us, none,
     "put a 24-byte message, queue in remote memory (another RTPU's window; one process)"},
    {"msg_get_24b_local", "ns", "peer_bipc_mq_receive_24b", 64 * us, none,
     "get a 24-byte message, queue in local memory"},
    {"msg_get_24b_remote_one_process", "ns", "peer_bipc_mq_receive_24b", 81 * us, none,
     "get a 24-byte message, queue in remote memory (another RTPU's window; one process)"},
    // ---- Table 1: global shared memory. Value: ns per 8-byte word through an
    // attached segment minus the same code on a local array; ratio relative.
    {"shm_read_overhead", "ns", "peer_array_read", 0, {Target::kRatioAtMost, 0.05},
     "extra ns per 8-byte read through attached global shared memory"},
    {"shm_write_overhead", "ns", "peer_array_write", 0, {Target::kRatioAtMost, 0.05},
     "extra ns per 8-byte write through attached global shared memory"},

    // ---- performance targets (bench/README.md)
    {"yield_switch", "ns", "peer_fiber_switch", kNull, ratio_le(3),
     "yield to an equal-priority task through the scheduler"},
    {"sem_v_wake_switch", "ns", "peer_fiber_switch", kNull, ratio_le(5),
     "V waking a higher-priority task, including the switch"},
    // The same figures beside their in-run floor under the default
    // cpu_accounting 1: a fiber switch that charges CPU time (one cycle
    // counter read per switch). Shown beside the targets above, which stay.
    {"yield_switch_vs_clocked_fiber", "ns", "peer_fiber_switch_clocked", kNull, ratio_le(3),
     "yield_switch beside a fiber switch that charges CPU time at every switch"},
    {"sem_v_wake_switch_vs_clocked_fiber", "ns", "peer_fiber_switch_clocked", kNull, ratio_le(5),
     "sem_v_wake_switch beside a fiber switch that charges CPU time at every switch"},
    {"local_pv_noblock", "ns", "peer_sem_wait_post", 14 * us, ratio_le(1),
     "uncontended local P+V (paper: 7 + 7)"},
    // Like for like: the task is spawned, runs and ends, as the peer's thread
    // is created, runs and is joined (paper: 220 + 99, create + destroy).
    {"task_spawn_run_exit", "ns", "peer_pthread_create_join", 319 * us, ratio_le(0.01),
     "spawn a task that runs at once and ends; target 100x faster than pthread create + join"},
    // Like for like, the first half of the target: <= 2x a fiber's create +
    // run + destroy (the second half is the 100x over pthread above).
    {"task_spawn_run_exit_vs_fiber", "ns", "peer_fiber_create_destroy", kNull, ratio_le(2),
     "task_spawn_run_exit beside a Boost.Context fiber created, run to its end and destroyed"},
    {"task_spawn_run_exit_vs_clocked_fiber", "ns", "peer_fiber_create_destroy_clocked", kNull, ratio_le(2),
     "task_spawn_run_exit beside a fiber created, run and destroyed that charges CPU time at its two switches"},
    {"task_spawn_destroy_never_runs", "ns", "peer_pthread_create_join", kNull, none,
     "spawn + destroy a task that never runs (cheaper than the peer's work: no target)"},
    {"sched_ops_10k_over_10", "x", nullptr, kNull, {Target::kValueAtMost, 2},
     "CPU per job of 10,000 periodic tasks whose releases fire (MUF, EDF) over the same with 10"},
    {"release_lateness_p99_20tasks", "ns", "peer_sigwait_1khz_lateness_p99_alternating", kNull, ratio_le(1.2),
     "1 kHz release lateness p99, 20 periodic tasks on one RTPU, in blocks alternating with its peer's"},
    // Cross-RTPU means a task on one RTPU process and a task on another,
    // each running the Chimera kernel, on two cores: a sender task on RTPU 1
    // and a receiver task on RTPU 2, streaming, against Boost message_queue
    // between two processes pinned the same way.
    // Throughput >= 1 x the peer's: ns per message at most the peer's.
    {"msgq_stream_24b_xrtpu", "ns", "peer_bipc_mq_stream_24b_xcore", kNull, ratio_le(1),
     "cross-RTPU 24-byte messages streamed from a task on RTPU 1 to a task on RTPU 2, per message"},
    {"msgq_stream_64k_xrtpu", "ns", "peer_bipc_mq_stream_64k_xcore", kNull, none,
     "cross-RTPU 64 KiB messages streamed from a task on RTPU 1 to a task on RTPU 2, per message"},
    // One-way with the receiver polling, judged against the cache-line floor
    // between the same two tasks measured run by run in turn with it.
    {"msgq_oneway_polling_xrtpu", "ns", "peer_cacheline_pingpong_msgq_rtpus", kNull, ratio_le(3),
     "cross-RTPU 24-byte message to a task whose RTPU polls, one-way (RT/2)"},
    // Put+get with the queue in RTPU 2's window, both by this one process
    // (no second RTPU runs): not a cross-RTPU figure, so no target.
    {"msgq_putget_24b_remote_one_process", "ns", "peer_bipc_mq_24b_one_thread", 160 * us, none,
     "24-byte put+get by one process, queue in another RTPU's window, no wait (paper: 79 + 81)"},
    // Through RTPU kernels on both ends, the two RTPUs on one core as the
    // peer's two processes.
    {"msgq_wake_rt2", "ns", "peer_posix_mq_24b_rt2_same_core", kNull, ratio_le(0.8),
     "cross-RTPU 24-byte message that wakes the receiving task (kernels on both ends), RT/2"},
    {"msgq_wake_rt2_host_processes", "ns", "peer_posix_mq_24b_rt2_same_core", kNull, none,
     "24-byte message round trip between two host processes (no kernel) sleeping in receive, RT/2"},
    // The same figure beside the least any message that sleeps in receive
    // costs on the host: how much of msgq_wake_rt2 is Chimera's own work.
    {"msgq_wake_rt2_vs_floor", "ns", "peer_futex_handoff_rt2_same_core", kNull, ratio_le(1.1),
     "msgq_wake_rt2's figure beside the bare futex hand-off it is built on"},
    // Through RTPU kernels on both ends (doorbell, grant, task switch), the
    // two RTPUs on one core as the peer's two processes.
    {"rsem_handoff_sleeping", "ns", "peer_futex_pingpong_same_core", kNull, ratio_le(1.1),
     "remote semaphore hand-off between tasks on two RTPUs (kernels) on one core, each "
     "sleeping, RT/2"},
    {"rsem_handoff_sleeping_host_processes", "ns", "peer_futex_pingpong_same_core", kNull, none,
     "remote semaphore hand-off between two host processes (no kernel) on one core, RT/2"},
    {"rsem_handoff_polling", "ns", "peer_cacheline_pingpong_rtpus", kNull, ratio_le(3),
     "remote semaphore hand-off to a polling RTPU, RT/2"},
    // ---- state variables (issue 18): a set with one input and one output
    // of N doubles; one operation = chm_svar_set_read + chm_svar_set_write,
    // judged beside memcpy of the same bytes (2 x N x 8), measured in turn.
    {"svar_copy_in_out_64d", "ns", "peer_memcpy_1kib", kNull, {Target::kRatioPlusAtMost, 1.5, 100},
     "copy-in + copy-out of a 64-double input and a 64-double output (1 KiB in all)"},
    {"svar_copy_in_out_1024d", "ns", "peer_memcpy_16kib", kNull, {Target::kRatioPlusAtMost, 1.5, 100},
     "copy-in + copy-out of a 1024-double input and a 1024-double output (16 KiB in all)"},
    // ---- servo task control (issue 18), real chimera-rtpu processes
    {"module_cycle_cpu", "ns", "peer_task_cycle_cpu", kNull, ratio_le(2),
     "CPU of one cycle of an empty module (copy-in, copy-out of one double) at 1 kHz"},
    {"servo_switch_4_modules_periods", "x", nullptr, kNull, {Target::kValueAtMost, 2},
     "a switch of 4 modules on 2 RTPUs: call to effect, in periods of the slowest module"},
    {"module_spawn", "ns", "task_spawn_run_exit", kNull, none,
     "spawn a module on an RTPU from a host (load, checks, init in a task)"},
    // ---- the host server (issue 19): a task on an RTPU, chimera-rtpu
    // --host-server in slot 0, both in their default configuration
    {"xfs_read_64k", "ns", "peer_pread_64k", kNull, ratio_le(2),
     "extended file system: sequential chm_xfs_read of 64 KiB blocks by a task (>= 0.5 x pread's throughput); "
     "page-cached blocks of a file on a local disk file system are read by the task itself (preadv2 RWF_NOWAIT)"},
    {"xfs_read_64k_server", "ns", "peer_pread_64k_tmpfs", kNull, none,
     "the same where the direct way is refused (tmpfs): every block through the host server, read ahead"},
    {"host_call_rt", "ns", nullptr, kNull, none,
     "host procedure call round trip (chm_host_getcwd) from a task"},
    {"console_line_latency", "ns", nullptr, kNull, none,
     "a task's printf of a line to its arrival at the console (through the host server)"},
    // ---- the matrix library (issue 18 item 5), at a control loop's size
    {"mat_mul_6x6", "ns", "peer_eigen_mul_6x6", kNull, none,
     "chm_mat_mul of two 6x6 views into a third"},
    {"mat_solve_6x6", "ns", "peer_eigen_lu_solve_6x6", kNull, none,
     "chm_mat_solve of a 6x6 system, one right-hand side (partial pivoting, caller workspace)"},
    // ---- scaling (issue 6 item 5): the curves are in scaling_rtpus.png and
    // scaling_msg_size.png; one figure of each is a row
    {"msgq_putget_64k_remote_one_process", "ns", "peer_bipc_mq_64k_one_thread", kNull, none,
     "64 KiB put+get by one process, queue in another RTPU's window, no wait (the largest size "
     "of the message-size scaling)"},
    {"sched_fixed_ops_10k_over_10", "x", nullptr, kNull, none,
     "ready-heap operations (FIXED) with 10,000 ready tasks that never run over 10 (scaling_tasks.png)"},
    {"rsem_handoff_8rtpus_over_2", "x", nullptr, kNull, none,
     "cross-RTPU remote semaphore hand-off with 8 RTPUs running over its cost with 2"},
    {"idle_rtpu_cpu", "%", nullptr, kNull, {Target::kValueBelow, 1}, "CPU used by an idle RTPU"},
    // ---- predictability (issue 6 item 4)
    {"release_lateness_p99_1task", "ns", "peer_sigwait_1khz_lateness_p99", kNull, none,
     "1 kHz release lateness p99, 1 periodic task"},
    {"release_lateness_p99_200tasks", "ns", "peer_sigwait_1khz_lateness_p99", kNull, none,
     "1 kHz release lateness p99, 200 periodic tasks"},
    {"control_cpu_share_1khz", "%", nullptr, 90, {Target::kValueAtLeast, 90},
     "CPU share left to control tasks running at 1000 Hz (paper: over 90 %)"},
    // ---- the MUF overload experiment at 150 % utilisation (issue 6 item 4):
    // % of jobs missing their deadline; the whole ramp is in muf_overload.png
    {"overload_critical_miss_pct_150_rm", "%", nullptr, kNull, none,
     "RM at 150 % load: critical jobs missed"},
    {"overload_noncritical_miss_pct_150_rm", "%", nullptr, kNull, none,
     "RM at 150 % load: non-critical jobs missed"},
    {"overload_critical_miss_pct_150_edf", "%", nullptr, kNull, none,
     "EDF at 150 % load: critical jobs missed"},
    {"overload_noncritical_miss_pct_150_edf", "%", nullptr, kNull, none,
     "EDF at 150 % load: non-critical jobs missed"},
    {"overload_critical_miss_pct_150_mlf", "%", nullptr, kNull, none,
     "MLF at 150 % load: critical jobs missed"},
    {"overload_noncritical_miss_pct_150_mlf", "%", nullptr, kNull, none,
     "MLF at 150 % load: non-critical jobs missed"},
    {"overload_critical_miss_pct_150_muf", "%", nullptr, kNull, {Target::kValueAtMost, 0},
     "MUF at 150 % load: critical jobs missed (must be none)"},
    {"overload_noncritical_miss_pct_150_muf", "%", nullptr, kNull, none,
     "MUF at 150 % load: non-critical jobs missed"},

    // ---- peers: user-space switching
    {"peer_fiber_switch", "ns", nullptr, kNull, none, "Boost.Context fiber resume; one switch"},
    {"peer_ucontext_switch", "ns", nullptr, kNull, none, "swapcontext; one switch"},
    {"peer_fiber_create_destroy", "ns", nullptr, kNull, none,
     "Boost.Context fiber created, run to its end, destroyed (pooled 64 KiB stacks)"},
    {"peer_fiber_switch_clocked", "ns", nullptr, kNull, none,
     "Boost.Context fiber resume charging CPU time (a cycle counter read and an add at every switch); one switch"},
    {"peer_fiber_create_destroy_clocked", "ns", nullptr, kNull, none,
     "Boost.Context fiber create + run + destroy, charging CPU time at its two switches"},
    // ---- peers: threads and their synchronisation
    {"peer_pthread_create_join", "ns", nullptr, kNull, none,
     "pthread_create of an empty thread + pthread_join"},
    {"peer_sem_wait_post", "ns", nullptr, kNull, none, "uncontended sem_wait + sem_post"},
    {"peer_sem_wait", "ns", nullptr, kNull, none, "uncontended sem_wait on a positive count"},
    {"peer_sem_post", "ns", nullptr, kNull, none, "sem_post with nobody waiting"},
    {"peer_mutex_lock_unlock", "ns", nullptr, kNull, none, "uncontended pthread_mutex lock + unlock"},
    {"peer_setschedparam", "ns", nullptr, kNull, none,
     "pthread_setschedparam of the calling thread (a system call)"},
    {"peer_thread_sem_pingpong_same_core", "ns", nullptr, kNull, none,
     "two threads on one core hand a sem_t back and forth; RT/2"},
    {"peer_rt_ptsematest_same_core", "ns", nullptr, kNull, none,
     "rt-tests ptsematest: mutex hand-off latency between threads, one core"},
    {"peer_rt_ptsematest_xcore", "ns", nullptr, kNull, none,
     "rt-tests ptsematest: mutex hand-off latency between threads, across cores"},
    // ---- peers: waking another process
    {"peer_futex_pingpong_same_core", "ns", nullptr, kNull, none,
     "raw shared futex ping-pong between two processes on one core; RT/2"},
    {"peer_futex_pingpong_xcore", "ns", nullptr, kNull, none,
     "raw shared futex ping-pong between two processes across cores; RT/2"},
    // Its ratio to POSIX mq is the best msgq_wake_rt2 can reach on the host.
    {"peer_futex_handoff_rt2_same_core", "ns", "peer_posix_mq_24b_rt2_same_core", kNull, none,
     "shared futex hand-off between two processes on one core, waking only a sleeping side "
     "(the floor of a message that sleeps in receive); RT/2"},
    {"peer_named_sem_pingpong_same_core", "ns", nullptr, kNull, none,
     "POSIX named semaphore ping-pong between two processes on one core; RT/2"},
    {"peer_named_sem_pingpong_xcore", "ns", nullptr, kNull, none,
     "POSIX named semaphore ping-pong between two processes across cores; RT/2"},
    {"peer_rt_svsematest_same_core", "ns", nullptr, kNull, none,
     "rt-tests svsematest -f: SysV semaphore wake latency between processes, one core"},
    {"peer_rt_svsematest_xcore", "ns", nullptr, kNull, none,
     "rt-tests svsematest -f: SysV semaphore wake latency between processes, across cores"},
    {"peer_pipe_pingpong_same_core", "ns", nullptr, kNull, none,
     "1-byte pipe ping-pong between two processes on one core; RT/2"},
    {"peer_pipe_pingpong_xcore", "ns", nullptr, kNull, none,
     "1-byte pipe ping-pong between two processes across cores; RT/2"},
    {"peer_cacheline_pingpong_xcore", "ns", nullptr, kNull, none,
     "two spinning threads on two cores pass a cache line; one hand-off (the floor)"},
    // Measured run by run in turn with rsem_handoff_polling, between its two
    // tasks: the floor under the vCPU placement of that moment.
    {"peer_cacheline_pingpong_rtpus", "ns", nullptr, kNull, none,
     "the two tasks of rsem_handoff_polling pass a cache line, spinning; one hand-off (its floor)"},
    {"peer_cacheline_pingpong_msgq_rtpus", "ns", nullptr, kNull, none,
     "the two tasks of msgq_oneway_polling_xrtpu pass a cache line, spinning; one hand-off (its floor)"},
    // ---- peers: messages
    {"peer_posix_mq_24b_rt2_same_core", "ns", nullptr, kNull, none,
     "POSIX mq 24-byte round trip between two processes on one core; RT/2"},
    {"peer_posix_mq_24b_rt2_xcore", "ns", nullptr, kNull, none,
     "POSIX mq 24-byte round trip between two processes across cores; RT/2"},
    {"peer_rt_pmqtest_same_core", "ns", nullptr, kNull, none,
     "rt-tests pmqtest: POSIX mq wake latency between threads, one core"},
    {"peer_rt_pmqtest_xcore", "ns", nullptr, kNull, none,
     "rt-tests pmqtest: POSIX mq wake latency between threads, across cores"},
    {"peer_posix_mq_24b_one_thread", "ns", nullptr, kNull, none,
     "POSIX mq 24-byte mq_send + mq_receive in one thread"},
    {"peer_bipc_mq_24b_one_thread", "ns", nullptr, kNull, none,
     "Boost.Interprocess message_queue 24-byte send + receive in one thread"},
    {"peer_bipc_mq_stream_24b_xcore", "ns", nullptr, kNull, none,
     "Boost.Interprocess message_queue: 24-byte messages streamed from one process to another "
     "on the other core, per message"},
    {"peer_bipc_mq_stream_64k_xcore", "ns", nullptr, kNull, none,
     "Boost.Interprocess message_queue: 64 KiB messages streamed from one process to another "
     "on the other core, per message (8 slots)"},
    {"peer_bipc_mq_64k_one_thread", "ns", nullptr, kNull, none,
     "Boost.Interprocess message_queue 64 KiB send + receive in one thread"},
    {"peer_bipc_mq_send_24b", "ns", nullptr, kNull, none,
     "Boost.Interprocess message_queue 24-byte send alone (queue not full)"},
    {"peer_bipc_mq_receive_24b", "ns", nullptr, kNull, none,
     "Boost.Interprocess message_queue 24-byte receive alone (queue not empty)"},
    {"peer_bipc_mq_24b_rt2_same_core", "ns", nullptr, kNull, none,
     "Boost.Interprocess message_queue 24-byte round trip, two processes, one core; RT/2"},
    {"peer_bipc_mq_24b_rt2_xcore", "ns", nullptr, kNull, none,
     "Boost.Interprocess message_queue 24-byte round trip, two processes, across cores; RT/2"},
    // ---- peers: memory
    {"peer_mmap_stack_64k_untouched", "ns", nullptr, kNull, none,
     "mmap + munmap of a 64 KiB stack, never touched"},
    {"peer_mmap_stack_64k_touched", "ns", nullptr, kNull, none,
     "mmap + munmap of a 64 KiB stack, its top page touched"},
    {"peer_array_read", "ns", nullptr, kNull, none, "sum of a 64 KiB local array, per 8-byte word"},
    {"peer_array_write", "ns", nullptr, kNull, none, "fill of a 64 KiB local array, per 8-byte word"},
    {"peer_pread_64k", "ns", nullptr, kNull, none, "pread(2) of a 64 KiB block of a page-cached file"},
    {"peer_pread_64k_tmpfs", "ns", nullptr, kNull, none, "pread(2) of a 64 KiB block of a file on tmpfs"},
    {"peer_memcpy_1kib", "ns", nullptr, kNull, none, "memcpy of 512 B, twice (1 KiB in all), cache-resident"},
    {"peer_memcpy_16kib", "ns", nullptr, kNull, none, "memcpy of 8 KiB, twice (16 KiB in all), cache-resident"},
    {"peer_task_cycle_cpu", "ns", nullptr, kNull, none,
     "CPU of one cycle of a periodic task that does nothing, 1 kHz, on an RTPU"},
    // ---- peers: matrix arithmetic
    {"peer_eigen_mul_6x6", "ns", nullptr, kNull, none,
     "Eigen fixed-size 6x6 product, c.noalias() = a * b"},
    {"peer_eigen_lu_solve_6x6", "ns", nullptr, kNull, none,
     "Eigen PartialPivLU of a fixed-size 6x6 matrix, compute + solve of one right-hand side"},
    // ---- peers: timers and signals
    {"peer_timer_settime", "ns", nullptr, kNull, none, "timer_settime re-arming a POSIX timer"},
    {"peer_signal_self", "ns", nullptr, kNull, none,
     "tgkill to the calling thread, handler runs, returns"},
    {"peer_timer_signal_busy", "ns", nullptr, kNull, none,
     "POSIX timer signal to a computing thread, empty handler: time stolen per expiry"},
    {"peer_rt_sigwaittest_same_core", "ns", nullptr, kNull, none,
     "rt-tests sigwaittest -f: signal wake latency between processes, one core"},
    {"peer_rt_sigwaittest_xcore", "ns", nullptr, kNull, none,
     "rt-tests sigwaittest -f: signal wake latency between processes, across cores"},
    {"peer_sigwait_1khz_lateness_p50", "ns", nullptr, kNull, none,
     "timer_create + sigwaitinfo 1 kHz loop: release lateness, median"},
    {"peer_sigwait_1khz_lateness_p99", "ns", nullptr, kNull, none,
     "timer_create + sigwaitinfo 1 kHz loop: release lateness, 99th percentile"},
    {"peer_sigwait_1khz_lateness_p99_alternating", "ns", nullptr, kNull, none,
     "timer_create + sigwaitinfo 1 kHz loop, 99th percentile, in blocks alternating with release_lateness_p99_20tasks"},
    {"peer_sigwait_1khz_lateness_p999", "ns", nullptr, kNull, none,
     "timer_create + sigwaitinfo 1 kHz loop: release lateness, 99.9th percentile"},
    {"peer_sigwait_1khz_lateness_max", "ns", nullptr, kNull, none,
     "timer_create + sigwaitinfo 1 kHz loop: release lateness, maximum"},
    {"peer_rt_cyclictest_1khz", "ns", nullptr, kNull, none,
     "rt-tests cyclictest: clock_nanosleep 1 kHz wake-up latency"},
};

}  // namespace

std::span<const RowInfo> catalog() { return kRows; }

std::size_t row_index(std::string_view name) {
    for (std::size_t i = 0; i < std::size(kRows); ++i)
        if (name == kRows[i].name) return i;
    return std::size(kRows);
}

const RowInfo* find_row(std::string_view name) {
    const std::size_t i = row_index(name);
    return i < std::size(kRows) ? &kRows[i] : nullptr;
}

}  // namespace chm::bench
