# hotgauge — the two commands of the README, and what they need.
#   make demo   install missing packages, build, run 12 hub-a parts through the virtual line
#   make test   install missing packages, build (incl. sanitizer and fuzz builds), run every test
#               and each fuzz harness briefly
#   make fuzz   build the fuzz harnesses and run each for FUZZ_SECONDS (tests/fuzz/README.md)
SHELL := /bin/bash
BUILD ?= build
BUILD_ASAN ?= build-asan
BUILD_FUZZ ?= build-fuzz
FUZZ_SECONDS ?= 600
FUZZ_BRIEF_SECONDS ?= 6
JOBS ?= $(shell nproc)

# Every dependency, once: Debian 12 packages only.
DEB_PACKAGES := build-essential cmake pkg-config clang-format \
  libeigen3-dev libpcl-dev libopencv-dev libopencv-contrib-dev libflann-dev \
  libaravis-dev aravis-tools libmodbus-dev mbpoll socat libsystemd-dev systemd \
  libyaml-cpp-dev libspdlog-dev libcli11-dev nlohmann-json3-dev libembree-dev \
  libgtest-dev libgmock-dev libbenchmark-dev clang-14 libfuzzer-14-dev \
  python3-numpy python3-yaml python3-pymodbus python3-serial-asyncio

SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: deps build build-asan build-fuzz demo test fuzz fuzz-brief bench format clean soak

deps:
	@missing=$$(for p in $(DEB_PACKAGES); do \
	    dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q 'install ok installed' || echo $$p; \
	  done); \
	if [ -n "$$missing" ]; then \
	  echo "installing missing packages:" $$missing; \
	  $(SUDO) apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq --no-install-recommends $$missing; \
	else echo "all packages present"; fi

$(BUILD)/CMakeCache.txt:
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=RelWithDebInfo

build: deps $(BUILD)/CMakeCache.txt
	cmake --build $(BUILD) -j $(JOBS)

$(BUILD_ASAN)/CMakeCache.txt:
	cmake -S . -B $(BUILD_ASAN) -DCMAKE_BUILD_TYPE=Debug -DHOTGAUGE_SANITIZE=ON -DHOTGAUGE_BENCH=OFF

build-asan: deps $(BUILD_ASAN)/CMakeCache.txt
	cmake --build $(BUILD_ASAN) -j $(JOBS)

# libFuzzer harnesses (tests/fuzz/): clang, every library instrumented; only the harnesses and
# what they link are built.
$(BUILD_FUZZ)/CMakeCache.txt:
	CC=clang-14 CXX=clang++-14 cmake -S . -B $(BUILD_FUZZ) -DHOTGAUGE_FUZZ=ON \
	  -DHOTGAUGE_TESTS=OFF -DHOTGAUGE_BENCH=OFF

build-fuzz: deps $(BUILD_FUZZ)/CMakeCache.txt
	cmake --build $(BUILD_FUZZ) -j $(JOBS) --target hotgauge_fuzzers

# Each harness for FUZZ_SECONDS on a scratch copy of its seeds; findings in $(BUILD_FUZZ)/fuzz-findings.
fuzz: build-fuzz
	tests/fuzz/run.sh $(BUILD_FUZZ) $(FUZZ_SECONDS)

# make test's step: each harness for FUZZ_BRIEF_SECONDS, so that a regression is caught.
fuzz-brief: build-fuzz
	tests/fuzz/run.sh $(BUILD_FUZZ) $(FUZZ_BRIEF_SECONDS)

# The main job on the built-in simulated cell: the virtual production line. The virtual cell
# (GigE Vision camera, accelerometer stream, axis with its part conveyor, pyrometer on a socat
# pair), hotgauged and a scripted pymodbus PLC run 12 hub-a parts through all four faces under
# press vibration, with a master check after part 6; the paper's Table 2 is printed beside the
# measured values and their errors.
DEMO_OUT ?= out/line
demo: build
	/usr/bin/python3 tests/virtual_line.py --bin-dir $(BUILD) --parts 12 --commission 1 --master-at 6 --out $(DEMO_OUT)

# The fault soak (issue 18, tests/soak.py): the virtual line for SOAK_PARTS parts with faults on
# a seeded schedule (accelerometer loss and outage, camera packet loss and restarts, PLC
# disconnects, a full results disk, SIGHUP with a bad and a good config, kill -9 of hotgauged
# with a supervisor that restarts it like systemd), then the report: parts in, results out, lost,
# duplicated, false NOK, faults by code, RSS over time, cycle time. About 11 s a part.
SOAK_PARTS ?= 1000
SOAK_SEED ?= 1
SOAK_OUT ?= out/soak
soak: build
	/usr/bin/python3 tests/soak.py --bin-dir $(BUILD) --parts $(SOAK_PARTS) --seed $(SOAK_SEED) --out $(SOAK_OUT)

test: build build-asan build-fuzz
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS)
	cd $(BUILD_ASAN) && ctest --output-on-failure -j $(JOBS) -L unit
	tests/fuzz/run.sh $(BUILD_FUZZ) $(FUZZ_BRIEF_SECONDS)

bench: build
	cmake --build $(BUILD) -j $(JOBS) --target hotgauge_bench_match
	$(BUILD)/tests/bench/hotgauge_bench
	$(BUILD)/tests/bench/hotgauge_bench_match
	$(BUILD)/tests/bench/hotgauge_bench_acquire
	$(BUILD)/tests/bench/hotgauge_bench_plc
	/usr/bin/python3 tests/bench/daemon_latency.py $(BUILD) --parts 5

format:
	clang-format -i $$(git ls-files '*.cpp' '*.hpp')

clean:
	rm -rf $(BUILD) $(BUILD_ASAN) $(BUILD_FUZZ)
