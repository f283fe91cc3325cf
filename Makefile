# The two commands of the README: `make demo` and `make test`. Each does everything on a
# fresh Debian 12 machine: install packages, configure (Release), build in parallel, run.
# Other targets: build, asan (ASan+UBSan test build in build-asan), format, clean.

BUILD_DIR ?= build
BUILD_TYPE ?= Release
JOBS ?= $(shell nproc)
CMAKE_FLAGS ?= -DFACEDYN_WERROR=ON  # the supported platform (Debian 12, GCC 12) builds warning-free
DEMO_OUT ?= demo-out

MAKEFLAGS += --no-print-directory

.PHONY: all deps configure build test demo asan format clean

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

format:
	@git ls-files '*.h' '*.cc' | xargs clang-format -i

clean:
	@rm -rf $(BUILD_DIR) build-asan $(DEMO_OUT)
