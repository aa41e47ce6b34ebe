# The entry point for people: `make demo`, `make test`, `make bench`.
# Each target installs the Debian packages it needs (only those missing),
# configures with meson, builds and runs.

BUILD       ?= build
BUILD_BENCH ?= build-release
BUILD_FUZZ  ?= build-fuzz
BUILD_ASAN  ?= build-asan
BUILD_TSAN  ?= build-tsan
# The suites make test-asan runs under AddressSanitizer + UBSan. The others
# say in their meson.build why they cannot (rtpu, bench).
ASAN_SUITES = kernel port ipc svar servo config matrix devices errors host
# ThreadSanitizer: the backplane and the host library between real threads
# and processes (tests/ipc/meson.build says which cases it leaves out, why).
TSAN_SUITES = ipc host
FUZZ_SECONDS ?= 300
SOAK_SECONDS ?= 600
SOAK_SEED   ?= 0
MESON_TEST  ?= meson test --print-errorlogs --num-processes 2

PKGS_BUILD = meson ninja-build g++ pkg-config python3 libgtest-dev libgmock-dev \
             libboost-dev libboost-context-dev libeigen3-dev libtomlplusplus-dev libedit-dev
PKGS_CROSS = g++-m68k-linux-gnu libc6-dev-m68k-cross \
             g++-aarch64-linux-gnu libc6-dev-arm64-cross qemu-user
PKGS_BENCH = libbenchmark-dev rt-tests python3-matplotlib
# clang's -fsanitize=fuzzer links libclang_rt.fuzzer, which Debian 12
# ships in libclang-rt-14-dev (libfuzzer-14-dev is the standalone copy).
PKGS_FUZZ  = clang libclang-rt-14-dev
FUZZ_TARGETS = fuzz_backplane fuzz_msgq fuzz_xmail fuzz_args fuzz_config fuzz_servo fuzz_cmdi fuzz_host

.PHONY: all deps deps-cross deps-bench deps-fuzz build demo demo-loop demo-multi stress soak test test-native test-m68k \
        test-aarch64 test-fuzz test-asan test-tsan fuzz fuzz-seeds bench clean

all: build

deps:
	@tools/install-deps.sh $(PKGS_BUILD)

deps-cross:
	@tools/install-deps.sh $(PKGS_CROSS)

deps-bench:
	@tools/install-deps.sh $(PKGS_BUILD) $(PKGS_BENCH)

deps-fuzz:
	@tools/install-deps.sh $(PKGS_BUILD) $(PKGS_FUZZ)

$(BUILD)/build.ninja:
	meson setup $(BUILD)

build: deps $(BUILD)/build.ninja
	meson compile -C $(BUILD)

# The pick-and-place arm on the default backplane (in the user's own
# directory: `chimera path`): control modules on two RTPUs switched live per
# phase by a job program, figures printed once a second, a PNG plot at the
# end (arm-demo.png; needs python3-matplotlib); checks that the object was
# placed within tolerance and no critical deadline was missed; stops and
# removes everything at the end or on Ctrl-C (examples/arm/demo.sh).
demo: build
	@sh examples/arm/demo.sh $(BUILD)

# A control loop closed across two RTPUs, its figures printed by a host
# process once a second for ~10 s (examples/loop/demo.sh).
demo-loop: build
	@sh examples/loop/demo.sh $(BUILD)

# Three RTPUs sharing memory, a spin-lock, a remote semaphore and express
# mail, ~15 s (examples/multi/demo.sh).
demo-multi: build
	@sh examples/multi/demo.sh $(BUILD)

test: test-native test-m68k test-aarch64 test-fuzz test-asan test-tsan

# The core suites again with AddressSanitizer and UndefinedBehaviorSanitizer
# (the kernel tells them of every stack switch: src/kernel/core/fiber_asan.hpp);
# any report fails the test. Only what those suites need is built.
$(BUILD_ASAN)/build.ninja:
	meson setup $(BUILD_ASAN) -Db_sanitize=address,undefined -Db_lundef=false

test-asan: deps $(BUILD_ASAN)/build.ninja
	ninja -C $(BUILD_ASAN) build.ninja  # regenerated first: the target list comes from it
	ninja -C $(BUILD_ASAN) $$(python3 tools/check/suite_targets.py $(BUILD_ASAN) $(ASAN_SUITES))
	ASAN_OPTIONS=handle_segv=0:handle_sigbus=0:handle_sigfpe=0:handle_sigill=0 \
	UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1 $(MESON_TEST) -C $(BUILD_ASAN) --no-rebuild \
	    $(foreach s,$(ASAN_SUITES),--suite $(s))
	@# A stack switch the sanitizer was not told of only warns ("false positive
	@# error reports may follow"): here it fails.
	@! grep -m3 'WARNING: ASan' $(BUILD_ASAN)/meson-logs/testlog.txt || \
	    (echo 'test-asan: AddressSanitizer was not told of a stack switch (above)'; exit 1)

# The backplane and host suites again with ThreadSanitizer (gcc's): any
# report fails the test (exit status 66). Only what they need is built.
$(BUILD_TSAN)/build.ninja:
	meson setup $(BUILD_TSAN) -Db_sanitize=thread -Db_lundef=false

test-tsan: deps $(BUILD_TSAN)/build.ninja
	ninja -C $(BUILD_TSAN) build.ninja
	ninja -C $(BUILD_TSAN) $$(python3 tools/check/suite_targets.py $(BUILD_TSAN) $(TSAN_SUITES))
	TSAN_OPTIONS=halt_on_error=1 $(MESON_TEST) -C $(BUILD_TSAN) --no-rebuild \
	    $(foreach s,$(TSAN_SUITES),--suite $(s))

# The kill-at-a-named-point tests with 2000 kills per point, not 100, the
# fault injection inside every backplane call with 2000 runs per point and
# action (ipc_fault), and the differential scheduler test with 20,000 sets
# per policy, random seed.
stress: deps $(BUILD)/build.ninja
	meson compile -C $(BUILD)
	CHM_KILL_REPEATS=2000 CHM_FAULT_REPEATS=2000 $(MESON_TEST) -C $(BUILD) --timeout-multiplier 30 \
	    ipc_recovery ipc_msgq_robust ipc_fault ipc_fault_kill
	CHM_DIFF_SEED=0 CHM_DIFF_SETS=20000 $(BUILD)/tests/kernel/test_kernel_sched_diff --gtest_filter='Policies/*'

# The chaos soak (tests/soak, docs/backplane.md "Chaos soak"): 3 RTPUs and
# 2 host processes exchanging messages, semaphore units, a seqlock block,
# state variables and express mail on a private backplane, and a servo
# controller switching control modules on the RTPUs, while they are killed,
# stopped/continued, terminated and restarted at random for SOAK_SECONDS (600); then the
# accounting, the checker and a search for anything left. SOAK_SEED=0 takes
# a seed from the clock; the seed is printed, and the same seed replays the
# same sequence of actions (their timing follows the machine).
soak: deps $(BUILD)/build.ninja
	meson compile -C $(BUILD) chimera-soak chimera-soak-host soak_worker chimera-soak-servo soak_mod_hand soak_mod_solo \
	    chimera-rtpu chimera-bpcheck
	$(BUILD)/tests/soak/chimera-soak --seconds $(SOAK_SECONDS) --seed $(SOAK_SEED)

test-native: deps deps-bench $(BUILD)/build.ninja
	meson compile -C $(BUILD)
	$(MESON_TEST) -C $(BUILD)

build-m68k/build.ninja:
	meson setup build-m68k --cross-file cross/m68k.ini

build-aarch64/build.ninja:
	meson setup build-aarch64 --cross-file cross/aarch64.ini

# Under qemu: the port, kernel, backplane and other suites that say so
# (suite m68k / aarch64). Only what those tests need is cross-compiled
# (the benchmark, tools and examples are not run there).
test-m68k test-aarch64: test-%: deps deps-cross build-%/build.ninja
	ninja -C build-$* build.ninja
	ninja -C build-$* $$(python3 tools/check/suite_targets.py build-$* $*)
	$(MESON_TEST) -C build-$* --no-rebuild --suite $*

# The libFuzzer harnesses (tests/fuzz, issue 15 item 4) in their own clang
# build, so the gcc builds above are untouched. Only the harnesses are
# compiled there, not the rest of the project (ninja by output path: it
# regenerates the build first when a meson.build changed).
$(BUILD_FUZZ)/build.ninja:
	CC=clang CXX=clang++ meson setup $(BUILD_FUZZ) -Dfuzz=true

# Each harness briefly (suite fuzz: 60 + 20 + 15 + 10 + 20 + 15 + 15 s, two at a time).
test-fuzz: deps-fuzz $(BUILD_FUZZ)/build.ninja
	ninja -C $(BUILD_FUZZ) $(FUZZ_TARGETS:%=tests/fuzz/%)
	$(MESON_TEST) -C $(BUILD_FUZZ) --suite fuzz --no-rebuild

# Each harness for FUZZ_SECONDS (default 300), one after the other; a
# crash stops the run and leaves its input in fuzz-artifacts/.
fuzz: deps-fuzz $(BUILD_FUZZ)/build.ninja
	ninja -C $(BUILD_FUZZ) $(FUZZ_TARGETS:%=tests/fuzz/%)
	for t in $(FUZZ_TARGETS); do \
	    r=tests/fuzz/regress/$${t#fuzz_}; [ -d $$r ] || r=; \
	    d=tests/fuzz/$${t#fuzz_}.dict; [ -f $$d ] && d=-dict=$$d || d=; \
	    tests/fuzz/run.sh $(BUILD_FUZZ)/tests/fuzz/$$t tests/fuzz/corpus/$${t#fuzz_} $(FUZZ_SECONDS) $$r $$d || exit 1; \
	done

# Regenerate the committed seed corpora (tests/fuzz/make_seeds.cpp); the
# configuration seeds (corpus/config) are hand-written TOML and stay.
fuzz-seeds: deps-fuzz $(BUILD_FUZZ)/build.ninja
	ninja -C $(BUILD_FUZZ) tests/fuzz/fuzz-make-seeds
	rm -rf tests/fuzz/corpus/backplane tests/fuzz/corpus/msgq tests/fuzz/corpus/xmail tests/fuzz/corpus/args
	mkdir -p tests/fuzz/corpus/backplane tests/fuzz/corpus/msgq tests/fuzz/corpus/xmail tests/fuzz/corpus/args
	$(BUILD_FUZZ)/tests/fuzz/fuzz-make-seeds tests/fuzz/corpus

$(BUILD_BENCH)/build.ninja:
	meson setup $(BUILD_BENCH) --buildtype=release

bench: deps-bench $(BUILD_BENCH)/build.ninja
	meson compile -C $(BUILD_BENCH)
	/usr/bin/python3 bench/run.py --build $(BUILD_BENCH) $(if $(QUICK),--quick,)

clean:
	rm -rf $(BUILD) $(BUILD_BENCH) $(BUILD_FUZZ) $(BUILD_ASAN) $(BUILD_TSAN) build-m68k build-aarch64
