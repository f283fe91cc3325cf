# The two commands of the README: `make demo` and `make test`. Each does everything on a
# fresh Debian 12 machine: install packages, configure (Release), build in parallel, run.
# Other targets: build, asan (ASan+UBSan test build in build-asan), asan-ci (the sanitizer step of
# .ci/run: core, rig, capture tests and the fuzz replays under ASan+UBSan in build-asan-ci), fuzz
# (libFuzzer run of every fuzz/ target, clang, build-fuzz), format, clean.

BUILD_DIR ?= build
BUILD_TYPE ?= Release
JOBS ?= $(shell nproc)
CMAKE_FLAGS ?= -DFACEDYN_WERROR=ON  # the supported platform (Debian 12, GCC 12) builds warning-free
DEMO_OUT ?= demo-out

MAKEFLAGS += --no-print-directory

.PHONY: all deps configure build test demo asan asan-ci fuzz format clean

all: build

deps:
	@bash scripts/install-deps.sh

configure: deps
	@cmake -S . -B $(BUILD_DIR) -DCMAKE_BUILD_TYPE=$(BUILD_TYPE) $(CMAKE_FLAGS) >/dev/null

build: configure
	@cmake --build $(BUILD_DIR) -j $(JOBS)

test: build
	@cd $(BUILD_DIR) && ctest --output-on-failure -j $(JOBS)

demo: build
	@$(BUILD_DIR)/app/facedyn demo --out $(DEMO_OUT)

asan:
	@$(MAKE) test BUILD_DIR=build-asan BUILD_TYPE=RelWithDebInfo CMAKE_FLAGS="-DFACEDYN_SANITIZE=ON"

# The sanitizer step of CI: only the test binaries of core, rig and capture that do not run the
# facedyn executable (tests/CMakeLists.txt, facedyn_add_sanitizer_ci_target) plus the fuzz
# corpus replays, so it builds a fraction of the project; `make asan` is the full run. -O1 -g1
# (line tables: sanitizer reports keep file:line) builds much faster than -O2 -g.
ASAN_CI_DIR ?= build-asan-ci
asan-ci: deps
	@cmake -S . -B $(ASAN_CI_DIR) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DFACEDYN_SANITIZE=ON \
	  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG" -DFACEDYN_WERROR=ON >/dev/null
	@cmake --build $(ASAN_CI_DIR) -j $(JOBS) --target asan_ci_tests
	@cd $(ASAN_CI_DIR) && ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 \
	  UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
	  ctest --output-on-failure -j $(JOBS) -L '^(core|rig|capture|fuzz)$$' \
	  -E "$$(cat asan_ci_tests_exclude.txt)"

# Fuzzing (README.md, "Fuzzing"): clang + libFuzzer, every target FUZZ_SECONDS in turn.
FUZZ_DIR ?= build-fuzz
FUZZ_SECONDS ?= 600
FUZZ_TARGETS ?=
fuzz: deps
	@CC=clang CXX=clang++ cmake -S . -B $(FUZZ_DIR) -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	  -DFACEDYN_FUZZ=ON -DFACEDYN_BUILD_TESTS=OFF -DFACEDYN_WERROR=OFF >/dev/null
	@cmake --build $(FUZZ_DIR) -j $(JOBS) --target fuzz_all
	@bash fuzz/run_fuzzers.sh $(FUZZ_DIR) $(FUZZ_SECONDS) $(FUZZ_TARGETS)

format:
	@git ls-files '*.h' '*.cc' | xargs clang-format -i

clean:
	@rm -rf $(BUILD_DIR) build-asan $(ASAN_CI_DIR) $(FUZZ_DIR) $(DEMO_OUT)
