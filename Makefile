# lmeform entry points. Each target does all set-up on a fresh Debian 12 machine:
# installs the packages (idempotent), configures, builds, then runs.
#   make demo   - the main demo
#   make test   - the whole test suite (unit, form FD checks, 2-rank MPI tests)
#   make bench  - the benchmarks in quick mode; JSON lands in build/bench/
#   make bench-full - the long benchmarks: the vesicle shape family down to eps = 0.005 with the
#                  second-order basis on grids 4 times finer than eps
#                  (build/bench/shapes_fine_second_f4.json, 40-90 minutes and 8.5-10.4 GB per shape on one core)
#   make compare - Stokes, the cantilever and fracture (SENT, SENS at l = 0.03): lmeform against
#                  FEniCSx; results in build/compare/

BUILD_DIR ?= build
BUILD_TYPE ?= Release
JOBS ?= $(shell nproc)
CMAKE_FLAGS ?=

.PHONY: all deps configure build test demo bench bench-full compare clean

all: build

deps:
	bash scripts/install-deps.sh

configure: deps
	cmake -S . -B $(BUILD_DIR) -DCMAKE_BUILD_TYPE=$(BUILD_TYPE) $(CMAKE_FLAGS)

build: configure
	cmake --build $(BUILD_DIR) -j $(JOBS)

test: build
	ctest --test-dir $(BUILD_DIR) --output-on-failure -j $(JOBS)

demo: build
	bash scripts/run-demo.sh $(BUILD_DIR)

bench: build
	bash scripts/run-benchmarks.sh $(BUILD_DIR)

bench-full: build
	$(BUILD_DIR)/tests/solvers/bench_shapes --fine --basis second --factor 4 --out $(BUILD_DIR)/bench

compare: build
	bash demos/stokes/compare.sh $(BUILD_DIR)
	bash demos/solids/compare.sh $(BUILD_DIR)
	bash demos/fracture/compare.sh $(BUILD_DIR) --quick

clean:
	rm -rf $(BUILD_DIR)
