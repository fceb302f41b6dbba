# The README's two commands: `make demo` and `make test`. Both install missing Debian packages first.
BUILD      ?= build
ASAN_BUILD ?= build-asan
FUZZ_BUILD ?= build-fuzz
TSAN_BUILD ?= build-tsan
FUZZ_SECONDS ?= 300
JOBS       ?= $(shell nproc)
DEMO_DIR   ?= demo-out
# Unity build (CMakeLists.txt, FMV3D_UNITY): each target's sources compiled in batches, -16% compiler CPU on the
# whole Release build; a whole `reconstruct` gives byte-identical outputs either way (bench/RESULTS.md, Build).
# `make UNITY=OFF` keeps one object per file (faster incremental rebuilds). With unity on, the heavy third-party
# headers are also precompiled once for every target (cmake/Pch.cmake; `make PCH=OFF` turns that off; the
# sanitizer builds do not use it: a few percent of their compile time, not measured with them).
UNITY      ?= ON
PCH        ?= ON

.PHONY: all deps build demo test test-product test-release test-asan test-asan-readers test-tsan fuzz bench clean

all: build

deps:
	@scripts/install-deps.sh

$(BUILD)/build.ninja: | deps
	cmake -S . -B $(BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Release -DFMV3D_UNITY=$(UNITY) -DFMV3D_PCH=$(PCH)

build: deps $(BUILD)/build.ninja
	cmake --build $(BUILD) -j $(JOBS)

demo: build
	$(BUILD)/fmv3d demo -o $(DEMO_DIR)

# The README's test command (and CI's): each test runs once. The end-to-end flights and the browser tests run on
# the Release product; every unit test and fuzz regression replay runs under ASan + UBSan (test-asan), so the
# Release build skips the unit-test binaries. `make test-release` runs every test on the Release build.
# The sanitizer build runs at the lowest CPU priority beside the product's build and tests: it takes only the
# cycles they leave idle (link steps, the last browser test running alone), so they keep their pace; about 2% of
# `make test` (bench/RESULTS.md, Tests and CI). Its log: $(ASAN_BUILD)/build.log.
test: deps $(BUILD)/build.ninja $(ASAN_BUILD)/build.ninja
	@echo "test: building $(ASAN_BUILD) in the background (nice 19), log in $(ASAN_BUILD)/build.log"
	@nice -n 19 cmake --build $(ASAN_BUILD) -j $(JOBS) > $(ASAN_BUILD)/build.log 2>&1 & asan=$$!; \
	  $(MAKE) --no-print-directory test-product; status=$$?; \
	  wait $$asan || { tail -n 40 $(ASAN_BUILD)/build.log; echo "test: the sanitizer build failed" >&2; exit 1; }; \
	  exit $$status
	$(MAKE) --no-print-directory test-asan

test-product: deps $(BUILD)/build.ninja web
	cmake --build $(BUILD) -j $(JOBS) --target fmv3d test_e2e
	ctest --test-dir $(BUILD) --output-on-failure -j $(JOBS) -L 'e2e|browser'

test-release: build
	ctest --test-dir $(BUILD) --output-on-failure -j $(JOBS)

# Unit tests under AddressSanitizer + UndefinedBehaviorSanitizer (the long end-to-end flights and the browser tests are
# skipped, and test_e2e is not built). -O1, line tables only (-g1) and the unity build keep the build and the run
# within CI's time; stack traces still name file and line. Built with clang, not the product's GCC: it instruments
# the tree for less than half of GCC's CPU (GCC's UBSan alone costs ×2.7), and its UBSan also checks float-to-int
# overflow, which GCC's does not (bench/results/ci12.md, RESULTS.md "Tests and CI").
$(ASAN_BUILD)/build.ninja: | deps
	CC=clang CXX=clang++ cmake -S . -B $(ASAN_BUILD) -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DFMV3D_SANITIZE=ON \
	  -DFMV3D_UNITY=$(UNITY) -DFMV3D_PCH=OFF \
	  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG" -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG"

test-asan: deps $(ASAN_BUILD)/build.ninja
	cmake --build $(ASAN_BUILD) -j $(JOBS)
	ASAN_OPTIONS=detect_leaks=0:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
	  ctest --test-dir $(ASAN_BUILD) --output-on-failure -j $(JOBS) -LE 'e2e|browser'

# CI's sanitizer step: the unit tests and fuzz regression replays of the readers of untrusted bytes (core, io,
# telemetry: KLV, SRT, EXIF/XMP, GPMF, PLY, OBJ, COLMAP models, tie points) under ASan + UBSan. They link those
# modules only, so this builds a few libraries, not the whole product (`make test-asan` runs every unit test).
test-asan-readers: deps $(ASAN_BUILD)/build.ninja
	cmake --build $(ASAN_BUILD) -j $(JOBS) --target reader_tests
	ASAN_OPTIONS=detect_leaks=0:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
	  ctest --test-dir $(ASAN_BUILD) --output-on-failure -j $(JOBS) -L readers

# The console's front end (web/): npm ci only when node_modules is missing or older than the lock file.
.PHONY: web
build: web
web: web/node_modules/.package-lock.json
	cd web && npm run build --silent -- --outDir $(abspath $(BUILD))/web --logLevel warn

web/node_modules/.package-lock.json: web/package-lock.json
	cd web && npm ci --no-audit --no-fund --loglevel=error
	@touch $@

# The tests of the multithreaded stages (PatchMatch and fusion, matching, bundle adjustment) under ThreadSanitizer,
# on a runtime that lets it see the thread pools' synchronisation (scripts/tsan-runtime.sh: oneTBB built with
# -fsanitize=thread; LLVM's libomp + Archer for the OpenMP of SuiteSparse and Open3D). Every report is listed,
# then the run fails; tests/tsan.supp holds the suppressions of third-party code, each with its reason.
TSAN_RUNTIME ?= $(TSAN_BUILD)/runtime
$(TSAN_BUILD)/build.ninja: | deps
	cmake -S . -B $(TSAN_BUILD) -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG" \
	  -DFMV3D_TSAN=ON -DFMV3D_UNITY=$(UNITY) -DFMV3D_PCH=OFF

test-tsan: deps $(TSAN_BUILD)/build.ninja
	@FMV3D_WITH_TSAN=1 scripts/install-deps.sh
	cmake --build $(TSAN_BUILD) -j $(JOBS) --target test_mvs test_features test_sfm
	scripts/tsan-runtime.sh $(TSAN_RUNTIME) > $(TSAN_BUILD)/runtime.env
	set -a; . $(TSAN_BUILD)/runtime.env; set +a; status=0; \
	for t in mvs features sfm; do \
	  TSAN_OPTIONS="halt_on_error=0 second_deadlock_stack=1 ignore_noninstrumented_modules=1 suppressions=$(CURDIR)/tests/tsan.supp" \
	    $(TSAN_BUILD)/tests/test_$$t || status=1; done; exit $$status

# Every tests/fuzz/*_fuzz.cc as a libFuzzer binary (clang, ASan + UBSan; the readers under test are compiled
# instrumented, the rest of the library is linked from $(BUILD)), each run FUZZ_SECONDS on a seed corpus
# made in $(FUZZ_BUILD) from ../shared/data and a small flight our own writers produce; prints executions and
# coverage per target. Crashing inputs go to tests/fuzz/regressions/<target>/ once fixed (replayed by `make test`).
$(FUZZ_BUILD)/build.ninja: | deps
	CC=clang CXX=clang++ cmake -S . -B $(FUZZ_BUILD) -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g" -DFMV3D_FUZZ=ON -DFMV3D_BUILD_TESTS=OFF -DFMV3D_BUILD_BENCH=OFF \
	  -DFMV3D_FUZZ_PREBUILT=$(abspath $(BUILD))

fuzz: build $(FUZZ_BUILD)/build.ninja
	cmake --build $(FUZZ_BUILD) -j $(JOBS) --target fuzz_targets
	tests/fuzz/run.sh $(FUZZ_BUILD) $(BUILD)/fmv3d $(FUZZ_SECONDS)

# Style drift against .clang-format (`scripts/check-format.sh --fix` rewrites); .ci/run runs it after `make test`.
.PHONY: check-format
check-format: deps
	@scripts/check-format.sh

# clang-tidy (.clang-tidy) on the sources changed since BASE (default: the merge base with main); see scripts/tidy.sh.
.PHONY: tidy
tidy: $(BUILD)/build.ninja
	@scripts/tidy.sh "$(BASE)" $(BUILD)

# CI's gate: clang-tidy on the sources changed since .ci/tidy-baseline.txt's commit, failing on findings beyond it
# (scripts/tidy_ci.sh; configures build-tidy for a one-object-per-file compile database, builds nothing).
# After a landing, `make tidy-baseline` moves the baseline to HEAD so that CI checks only the next landing's changes.
.PHONY: tidy-ci tidy-baseline
tidy-ci:
	@scripts/tidy_ci.sh
tidy-baseline:
	@scripts/tidy_ci.sh --update

# The benchmarks are not part of `build` (CI never runs them): this builds them.
bench: build
	cmake --build $(BUILD) -j $(JOBS) --target benchmarks
	@echo "benchmarks: $(BUILD)/bench/ (see bench/README.md)"

clean:
	rm -rf $(BUILD) $(ASAN_BUILD) $(FUZZ_BUILD) $(TSAN_BUILD)
