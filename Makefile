# hotgauge — the two commands of the README, and what they need.
#   make demo   install missing packages, build, run 12 hub-a parts through the virtual line
#   make test   install missing packages, build (release and sanitizer builds), run every test,
#               the fuzz harnesses' corpus replay among them (ctest fuzz_replay_*)
#   make fuzz   build the libFuzzer harnesses (clang, the volume build) and run each for
#               FUZZ_SECONDS; what they find goes into the corpus, what they ran into the ledger
#               (tests/fuzz/README.md)
SHELL := /bin/bash
BUILD ?= build
BUILD_ASAN ?= build-asan
BUILD_FUZZ ?= build-fuzz
BUILD_FUZZ_VOLUME ?= build-fuzz-volume
FUZZ_SECONDS ?= 600
FUZZ_PARALLEL ?= 1
FUZZ_BRIEF_SECONDS ?= 6
JOBS ?= $(shell nproc)

# Every dependency, once: Debian 12 packages only.
DEB_PACKAGES := build-essential cmake pkg-config clang-format \
  libeigen3-dev libpcl-dev libopencv-dev libopencv-contrib-dev libflann-dev \
  libaravis-dev aravis-tools libmodbus-dev mbpoll socat libsystemd-dev systemd \
  libyaml-cpp-dev libspdlog-dev libcli11-dev nlohmann-json3-dev libembree-dev libboost-dev \
  libgtest-dev libbenchmark-dev libceres-dev \
  python3-numpy python3-yaml python3-pymodbus python3-serial-asyncio \
  chromium python3-pil libcpp-httplib-dev \
  libmosquitto-dev mosquitto mosquitto-clients python3-paho-mqtt python3-prometheus-client \
  python3-jsonschema
# Only for make fuzz / fuzz-brief (libFuzzer needs clang).
FUZZ_PACKAGES := clang-14 libfuzzer-14-dev
# Only for make oracle-refs: the oracles whose answers are kept in data/oracle.
ORACLE_PACKAGES := python3-statsmodels

SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: deps deps-fuzz oracle-refs install-missing build build-asan build-fuzz build-fuzz-volume demo test fuzz fuzz-brief fuzz-ledger bench baseline format clean soak

deps:
	@$(MAKE) -s install-missing PACKAGES="$(DEB_PACKAGES)"

deps-fuzz: deps
	@$(MAKE) -s install-missing PACKAGES="$(FUZZ_PACKAGES)"

install-missing:
	@missing=$$(for p in $(PACKAGES); do \
	    dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q 'install ok installed' || echo $$p; \
	  done); \
	if [ -n "$$missing" ]; then \
	  echo "installing missing packages:" $$missing; \
	  $(SUDO) apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq --no-install-recommends $$missing; \
	else echo "all packages present"; fi

# Reference answers from oracles nobody here wrote, kept in data/oracle and read by the tests
# (statsmodels' DerSimonian-Laird τ² for measure::between_std; NumPy and statsmodels for the
# quality statistics: capability, control limits, type-1 and type-3 studies); make test does not
# need them.
oracle-refs:
	@$(MAKE) -s install-missing PACKAGES="$(ORACLE_PACKAGES)"
	/usr/bin/python3 tests/oracle/make_dl_reference.py
	/usr/bin/python3 tests/oracle/make_quality_reference.py

# -g1 (line tables: file:line in stack traces, profiles and core dumps, no variables) instead
# of RelWithDebInfo's -g: a quarter less compile time for make test. A full -g build for gdb:
#   cmake -S . -B build-gdb -DCMAKE_BUILD_TYPE=RelWithDebInfo
$(BUILD)/CMakeCache.txt:
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O2 -g1 -DNDEBUG"

build: deps $(BUILD)/CMakeCache.txt
	cmake --build $(BUILD) -j $(JOBS)

# The sanitizer build: only what `ctest -L unit` runs (target hotgauge_unit_tests), with line
# tables (-g1) for the sanitizers' stacks; full -g made it 30 % slower to build.
$(BUILD_ASAN)/CMakeCache.txt:
	cmake -S . -B $(BUILD_ASAN) -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS_DEBUG=-g1 \
	  -DHOTGAUGE_SANITIZE=ON -DHOTGAUGE_BENCH=OFF

build-asan: deps $(BUILD_ASAN)/CMakeCache.txt
	cmake --build $(BUILD_ASAN) -j $(JOBS) --target hotgauge_unit_tests

# libFuzzer harnesses (tests/fuzz/): clang, every library instrumented; only the harnesses and
# what they link are built.
$(BUILD_FUZZ)/CMakeCache.txt:
	CC=clang-14 CXX=clang++-14 cmake -S . -B $(BUILD_FUZZ) -DHOTGAUGE_FUZZ=ON \
	  -DHOTGAUGE_TESTS=OFF -DHOTGAUGE_BENCH=OFF

build-fuzz: deps-fuzz $(BUILD_FUZZ)/CMakeCache.txt
	cmake --build $(BUILD_FUZZ) -j $(JOBS) --target hotgauge_fuzzers

# The volume build: coverage instrumentation only, -O2, for executions per second. What it finds
# is replayed in the sanitizer build above (tests/fuzz/README.md).
$(BUILD_FUZZ_VOLUME)/CMakeCache.txt:
	CC=clang-14 CXX=clang++-14 cmake -S . -B $(BUILD_FUZZ_VOLUME) -DHOTGAUGE_FUZZ=ON \
	  -DHOTGAUGE_FUZZ_SANITIZE=OFF -DHOTGAUGE_TESTS=OFF -DHOTGAUGE_BENCH=OFF

build-fuzz-volume: deps-fuzz $(BUILD_FUZZ_VOLUME)/CMakeCache.txt
	cmake --build $(BUILD_FUZZ_VOLUME) -j $(JOBS) --target hotgauge_fuzzers

# Each harness for FUZZ_SECONDS (FUZZ_PARALLEL at once) in the volume build; new coverage merged
# into tests/fuzz/corpus, a line per harness appended to tests/fuzz/ledger.tsv: commit both.
# Findings in $(BUILD_FUZZ_VOLUME)/fuzz-findings.
fuzz: build-fuzz-volume
	FUZZ_PARALLEL=$(FUZZ_PARALLEL) tests/fuzz/run.sh $(BUILD_FUZZ_VOLUME) $(FUZZ_SECONDS)
	/usr/bin/python3 tests/fuzz/ledger.py || true

# What the ledger adds up to for this commit's readers (goal 10^7 executions each).
fuzz-ledger:
	/usr/bin/python3 tests/fuzz/ledger.py

# Each libFuzzer harness for FUZZ_BRIEF_SECONDS under ASan/UBSan, corpus and ledger left alone.
# make test replays the corpora instead (ctest fuzz_replay_*: each file and 20 000 damaged
# variants per harness, under ASan/UBSan), without a clang build.
fuzz-brief: build-fuzz
	FUZZ_NO_LEDGER=1 tests/fuzz/run.sh $(BUILD_FUZZ) $(FUZZ_BRIEF_SECONDS)

# The main job on the built-in simulated cell: the virtual production line. The virtual cell
# (GigE Vision camera, accelerometer stream, axis with its part conveyor, pyrometer on a socat
# pair), hotgauged and a scripted pymodbus PLC run 12 as-forged hub-a parts (drafts, fillets, die
# shift), two of them bad, through all four faces under press vibration, with a master check
# after part 6; the paper's Table 2 is printed beside the measured values and their errors, and
# the PLC must read NOK on exactly the bad parts' features out of tolerance.
DEMO_OUT ?= out/line
demo: build
	/usr/bin/python3 tests/virtual_line.py --bin-dir $(BUILD) --parts 12 --commission 1 --master-at 6 \
	  --forged --bad-parts 2 --out $(DEMO_OUT)

# The plant-data outage at full length (30 parts; make test runs 8), then the fault soak (issue
# 18, tests/soak.py): the virtual line for SOAK_PARTS parts with faults on
# a seeded schedule (accelerometer loss and outage, camera packet loss and restarts, PLC
# disconnects, a full results disk, SIGHUP with a bad and a good config, kill -9 of hotgauged
# with a supervisor that restarts it like systemd), then the report: parts in, results out, lost,
# duplicated, reused sequence numbers, false NOK, faults by code, RSS over time, cycle time.
# About 11.5 s a part; a line uses a third of a core, so SOAK_LINES independent lines share the
# parts out (seeds SOAK_SEED, SOAK_SEED+1, ...; one folder each under SOAK_OUT): 2000 parts on
# five lines take about 80 min (docs/operations.md "The fault soak").
SOAK_PARTS ?= 2000
SOAK_SEED ?= 1
SOAK_LINES ?= 5
SOAK_OUT ?= out/soak
soak: build
	/usr/bin/python3 tests/plant_data_test.py $(BUILD) --outage-parts 30
	/usr/bin/python3 tests/soak.py --bin-dir $(BUILD) --parts $(SOAK_PARTS) --seed $(SOAK_SEED) \
	  --lines $(SOAK_LINES) --out $(SOAK_OUT)

# Every test of both builds (tests/run_all.sh): the real-time tests of the virtual line while the
# sanitizer build compiles at nice 19, then the other tests on all cores, then the sanitizer
# build's unit tests.
test: build $(BUILD_ASAN)/CMakeCache.txt
	tests/run_all.sh $(BUILD) $(BUILD_ASAN) $(JOBS)

# The remeasure bench sets the stages of BENCH_BASELINE (a commit, default the previous one) beside
# ours: that commit checked out and built in build-baseline, again whenever it names another
# commit (docs/benchmarks.md "Re-measuring the archive"). BENCH_BASELINE= leaves it out.
BENCH_BASELINE ?= HEAD~1
BASELINE_BUILD := build-baseline
baseline:
	@commit=$$(git rev-parse --verify "$(BENCH_BASELINE)^{commit}") || exit 1; \
	if [ "$$(cat $(BASELINE_BUILD)/COMMIT 2>/dev/null)" != "$$commit" ]; then \
	  rm -rf $(BASELINE_BUILD) && git worktree prune && \
	  git worktree add --detach -f $(BASELINE_BUILD)/tree $$commit && \
	  cmake -S $(BASELINE_BUILD)/tree -B $(BASELINE_BUILD) -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	    "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O2 -g1 -DNDEBUG" && \
	  echo $$commit > $(BASELINE_BUILD)/COMMIT; \
	fi; \
	cmake --build $(BASELINE_BUILD) -j $(JOBS) --target hotgauge

bench: build $(if $(BENCH_BASELINE),baseline)
	cmake --build $(BUILD) -j $(JOBS) --target hotgauge_bench_match
	$(BUILD)/tests/bench/hotgauge_bench
	$(BUILD)/tests/bench/hotgauge_bench_match
	$(BUILD)/tests/bench/hotgauge_bench_acquire
	$(BUILD)/tests/bench/hotgauge_bench_plc
	/usr/bin/python3 tests/bench/daemon_latency.py $(BUILD) --parts 5
	/usr/bin/python3 tests/bench/accel_loss.py $(BUILD) --recordings 4 --loss-seeds 2
	/usr/bin/python3 tests/bench/lot_report.py $(BUILD)
	/usr/bin/python3 tests/bench/forged_sorting.py $(BUILD) --parts 60 --first-seed 1000 --bad-every 3
	/usr/bin/python3 tests/bench/remeasure_bench.py $(BUILD) --parts 200 --distinct 10 --old-parts 20 \
	  $(if $(BENCH_BASELINE),--baseline-bin-dir $(BASELINE_BUILD))

format:
	clang-format -i $$(git ls-files '*.cpp' '*.hpp')

clean:
	rm -rf $(BUILD) $(BUILD_ASAN) $(BUILD_FUZZ) $(BUILD_FUZZ_VOLUME) $(BASELINE_BUILD)
