# gyrogen: make targets. `make run` and `make test` set everything up first
# (compilers through apt-get when root, Python packages into .venv).

PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
SCENE_DIR := generated/gyrostat

.PHONY: setup system-deps run test test-fast lint generate check-generated bench bench-taylor bench-auto bench-clusters bench-call bench-grid bench-events bench-sweep-metrics bench-var bench-methods bench-lanes bench-ensemble report check fuzz clean distclean examples strict fmu-agreement bench-lib sweep-bench sweep-map verify-axes test-wide docs docs-bench

## setup: the system packages the suite uses (SYSTEM_PACKAGES, through apt-get when root) and the Python environment in .venv
setup: system-deps $(STAMP)

# Every system package a test or a command uses: compilers, clang's sanitizer runtime (a separate
# package on Debian), valgrind, CMake, pkg-config and binutils (objdump); make itself runs this.
SYSTEM_PACKAGES := gcc g++ gfortran clang libclang-rt-dev valgrind cmake pkg-config binutils

system-deps:
	@missing=""; \
	if command -v dpkg-query >/dev/null 2>&1; then \
	  for pkg in $(SYSTEM_PACKAGES); do \
	    dpkg-query -W -f='$${Status}' $$pkg 2>/dev/null | grep -q 'ok installed' || missing="$$missing $$pkg"; \
	  done; \
	else \
	  for tool in gcc g++ gfortran clang valgrind cmake pkg-config objdump; do command -v $$tool >/dev/null 2>&1 || missing="$$missing $$tool"; done; \
	fi; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "setup: installing$$missing (apt-get update, then apt-get install)"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -q$$missing || exit 1; \
	  else \
	    echo "missing system packages:$$missing; install them with: sudo apt-get update && sudo apt-get install -y$$missing" >&2; \
	    exit 1; \
	  fi; \
	fi

PIP := $(BIN)/python -m pip

$(STAMP): pyproject.toml
	@echo "setup: creating the Python environment in $(VENV)"
	$(PYTHON) -m venv $(VENV)
	@echo "setup: installing gyrogen and its test dependencies into $(VENV) (a few minutes on a new machine)"
	$(PIP) install --progress-bar on -e '.[test]'
	@touch $@

## run: the main job on the default scene: generate, build, verify, summary
run: setup
	$(BIN)/gyrogen run --out $(SCENE_DIR)

## test: lint, then the whole test suite (compiled tests included)
test: setup lint
	$(BIN)/python -m pytest

## test-fast: lint, then the suite without the tests marked slow (the default scene still derived,
## generated, compiled as C and Fortran and checked against the reference); its build cache is kept
## in .cache/test-fast (entries named by the hash of what built them), so a run compiles only what
## changed, at -O3: built once, the faster code pays off in every run (the whole suite, whose cache
## is new each run, builds at -O0; test-wide at -O2)
test-fast: setup lint
	GYROGEN_OPT_LEVEL=$${GYROGEN_OPT_LEVEL:-3} GYROGEN_TEST_CACHE=$(CURDIR)/.cache/test-fast \
	  $(BIN)/python -m pytest -m "not slow"

lint: setup
	$(BIN)/ruff check generator tests benchmarks tools docs/hooks
	$(BIN)/ruff format --check generator tests benchmarks tools docs/hooks
	$(BIN)/mypy

## docs: the documentation site into site/ (MkDocs, warnings as errors; the docs extra is in test's)
docs: setup
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --clean

## docs-bench: measure the rhs on this machine (a quick run) into docs/benchmarks/, read by the
## benchmarks page when the site is built
docs-bench: setup
	$(BIN)/python tools/docs_bench.py run --out docs/benchmarks

## generate: rewrite generated/ (every built-in scene) from the templates and the generator
generate: setup
	$(BIN)/gyrogen generate --all --lib --out generated
	$(RENDERED_BY) > generated/RENDERED_BY.tmp && mv generated/RENDERED_BY.tmp generated/RENDERED_BY

## check-generated: fail if generated/ differs from a fresh rendering (rendered only, not compiled:
## `make generate` checks what it writes; the built-in scenes in two processes, a half each)
check-generated: setup
	@tmp=$$(mktemp -d) && trap 'rm -rf "$$tmp"' EXIT && \
	half() { $(BIN)/python -c "from gyrogen.scene import builtin_names as b; n = b(); \
	  print(*(n[:len(n) // 2], n[len(n) // 2:])[$$1])"; } && \
	{ $(BIN)/gyrogen generate $$(half 0) --lib --no-check --out "$$tmp" </dev/null >/dev/null 2>&1 & } && \
	$(BIN)/gyrogen generate $$(half 1) --lib --no-check --out "$$tmp" >/dev/null 2>&1 && wait $$! && \
	$(RENDERED_BY) > "$$tmp/RENDERED_BY" && \
	diff -r "$$tmp" generated && echo "generated/ is up to date"

# what generated/ is rendered from (runtime/scene_build.py's rendered_by): the suite reads it
RENDERED_BY = $(BIN)/python -c 'from gyrogen.runtime.scene_build import rendered_by; \
  from gyrogen.scene import builtin_names, load; print(rendered_by(map(load, builtin_names())))'

## bench: RHS timings (cffi, batched C and Fortran, numpy, PyDy cython)
bench: setup
	$(PIP) install -q -e '.[bench]'
	$(BIN)/gyrogen bench-rhs --out bench-out
	$(BIN)/python benchmarks/bench_clusters.py

## bench-clusters: the cluster scenes' rhs, hoisted against an M-solve per call (ops, ns per state), ops vs N
bench-clusters: setup
	$(BIN)/python benchmarks/bench_clusters.py

## bench-taylor: the Taylor method on one trajectory against heyoka's, gyrostat and dual_spin, side by side
bench-taylor: setup
	$(BIN)/python benchmarks/bench_taylor.py gyrostat 9
	$(BIN)/python benchmarks/bench_taylor.py dual_spin 9

## bench-auto: the Taylor method against dop853 on every built-in scene that offers it (simulate's auto choice)
bench-auto: setup
	$(BIN)/python benchmarks/bench_auto.py 7

## bench-call: us per call of Compiled.integrate and integrate_batch against the raw cffi call
bench-call: setup
	$(BIN)/python benchmarks/bench_call.py

## bench-grid: an output grid (_grid, 1001 times) against the end point alone and 1000 restarted calls,
## then taylor's and dop853's against heyoka's propagate_grid at equal error
bench-grid: setup
	$(BIN)/python benchmarks/bench_grid.py --heyoka

## bench-events: three non-terminal events (nutation, wheel rate, q2 thresholds) against the plain run, per method
bench-events: setup
	$(BIN)/python benchmarks/bench_events.py

## bench-sweep-metrics: a chunk's sampled metrics and located events (time_to) against its final
## state alone, one parameter set and one per trajectory; BASELINE=REV runs gyrogen as of REV beside
## this tree
bench-sweep-metrics: setup
	$(BIN)/python benchmarks/sweep_metrics.py $(if $(BASELINE),--baseline $(BASELINE))

## bench-var: the state transition matrix's cost over the plain trajectory, per method (error of Phi with x or not)
bench-var: setup
	$(BIN)/python benchmarks/bench_var.py

## bench-methods: us per call and ns per step of every compiled method (raw cffi call, best of several)
## on the default scene and stiff_wheel; BASELINE=REV times gyrogen as of REV beside this tree,
## interleaved, with each method's ratio new/old per step (slower by more than 3 % flagged);
## SAME_FLAGS=1 builds REV's sources with this tree's flags (the generated code's share alone)
BASELINE ?=
SAME_FLAGS ?=
bench-methods: setup
	$(BIN)/python benchmarks/methods.py $(if $(BASELINE),--baseline $(BASELINE)) \
	  $(if $(SAME_FLAGS),--same-flags)

## bench-lanes: each laned method's _batch on one core against a C loop of its single calls
## (default scene and stiff_wheel; loop / lanes above 1: the lanes win)
bench-lanes: setup
	$(BIN)/python benchmarks/bench_lanes.py

## bench-ensemble: lane-batched ensembles and the single trajectory against numbalsoda and diffrax
bench-ensemble: setup
	$(PIP) install -q -e '.[bench]'
	$(BIN)/gyrogen bench-ensemble

## report: work-precision reports (figure, tables, summary) for the default, dual_spin and the stiff scene against the compiled peers, and the ensembles
report: setup
	$(PIP) install -q -e '.[bench]'
	$(BIN)/gyrogen bench gyrostat --out report/gyrostat
	$(BIN)/gyrogen bench dual_spin --out report/dual_spin
	$(BIN)/gyrogen bench stiff_wheel --out report/stiff_wheel
	$(BIN)/gyrogen bench-ensemble --out report

## verify-axes: rw4_pyramid with every cluster property runtime (axes too) against the Newton-Euler
## reference at the issue's size, 10^4 states x 100 parameter sets, C and Fortran, to 1e-13; then the
## scenes whose gimbal axes are runtime (minutes each to derive): one CMG against the gimbal reference,
## and a sweep with a misalignment cone on cmg4_pyramid's first gimbal
verify-axes: setup
	GYROGEN_VERIFY_AXES=1 $(BIN)/python -m pytest -q -p no:cacheprovider -n 0 tests/test_cluster_axes.py -k issues_size
	GYROGEN_VERIFY_AXES=1 $(BIN)/python -m pytest -q -p no:cacheprovider -n 0 tests/test_gimbals.py \
	  tests/test_sweep_misalign.py -k "reference and axes or pyramid_gimbal_runs"

## test-wide: the cases the suite leaves out (tests/wide.py's mark): further scenes, builds and pages
## on paths the suite's cases take, the drawn-scene shards, the sanitizers, the examples' builds, the
## sensitivities' costly checks and the sweeps at scale
test-wide: setup
	GYROGEN_WIDE=1 GYROGEN_OPT_LEVEL=$${GYROGEN_OPT_LEVEL:-2} \
	  $(BIN)/python -m pytest -q -p no:cacheprovider -m wide

## fuzz: FUZZ_EVENTS draws of twelve events located by every adaptive method against scipy's on the reference,
## FUZZ_GIMBAL drawn (start, step) pairs against gimbal lock and FUZZ_SWEEPS drawn sweep files (and misalignments),
## FUZZ_TOLERANCE drawn motions on which every adaptive method keeps its tolerance in each state group,
## FUZZ_VAR drawn scenes whose state transition matrix and sensitivities meet the flow's differences,
## C and Fortran running every method alike on FUZZ_AGREE drawn scenes of each attitude (with and
## without -march=native), then the scene-space property test at scale: FUZZ_EXAMPLES drawn scenes (then FUZZ_CLUSTERS
## clusters, then FUZZ_CMGS clusters of control-moment gyros) with a fresh seed on every core; prints the counts, a reproducing TOML per failure in fuzz-failures/
FUZZ_EXAMPLES ?= 2000
FUZZ_CLUSTERS ?= 200
FUZZ_CMGS ?= 60
FUZZ_GIMBAL ?= 10000
FUZZ_SWEEPS ?= 5000
FUZZ_AGREE ?= 250
FUZZ_TOLERANCE ?= 300
FUZZ_EVENTS ?= 20
FUZZ_VAR ?= 12
fuzz: export GYROGEN_WIDE = 1
fuzz: export GYROGEN_OPT_LEVEL ?= 2
fuzz: setup
	GYROGEN_EVENT_DRAWS=$(FUZZ_EVENTS) GYROGEN_EVENT_SEED=$$(od -An -N4 -tu4 /dev/urandom) \
	  $(BIN)/python -m pytest -q -n auto tests/test_events_drawn.py
	GYROGEN_VAR_EXAMPLES=$(FUZZ_VAR) $(BIN)/python -m pytest -q -n auto tests/test_sensitivities.py \
	  -k drawn_scenes
	GYROGEN_TOLERANCE_EXAMPLES=$(FUZZ_TOLERANCE) $(BIN)/python -m pytest -q tests/test_global_error.py \
	  -k every_method
	GYROGEN_GIMBAL_DRAWS=$(FUZZ_GIMBAL) GYROGEN_GIMBAL_SEED=$$(od -An -N4 -tu4 /dev/urandom) \
	  $(BIN)/python -m pytest -q tests/test_ode_edges.py -k gimbal_lock_is_never_stepped_over
	GYROGEN_SWEEP_EXAMPLES=$(FUZZ_SWEEPS) $(BIN)/python -m pytest -q tests/test_sweep_space.py \
	  tests/test_sweep_misalign.py -k "space or drawn_misalignments"
	GYROGEN_AGREE_SCENES=$(FUZZ_AGREE) GYROGEN_AGREE_SEED=$$(od -An -N4 -tu4 /dev/urandom) \
	  $(BIN)/python -m pytest -q -n auto tests/test_scene_space.py -k every_method
	$(BIN)/python tools/fuzz_scenes.py --examples $(FUZZ_EXAMPLES) --out fuzz-failures
	$(BIN)/python tools/fuzz_scenes.py --clusters --examples $(FUZZ_CLUSTERS) --out fuzz-failures
	$(BIN)/python tools/fuzz_scenes.py --gimbals --examples $(FUZZ_CMGS) --out fuzz-failures

## fmu-agreement: the FMUs of the default, quaternion and stiff scenes in FMPy (Co-Simulation
## and Model Exchange) against `gyrogen simulate` over each scene's t_end (the suite runs 1 s)
fmu-agreement: setup
	$(BIN)/python benchmarks/fmu_agreement.py

## bench-lib: ns per rhs call of the CMake package under add_subdirectory: no build type
## (the package's -O2), Release, and None (no -O flag: the package's flags before it added -O2)
bench-lib: setup
	$(BIN)/python benchmarks/bench_cmake_default.py

## sweep-bench: the sweep's figures: 10^6 trajectories end to end against the bare batch
## compute, 1 -> 2 workers, the fixed and per-chunk costs, the scheduler's task rate, and the
## peak memory of 10^7; SWEEP_BASELINE=REV runs gyrogen as of REV beside this tree (before and
## after), SWEEP_LARGE=N also compares end to end at N trajectories
SWEEP_TRAJECTORIES ?= 1000000
SWEEP_MEMORY ?= 10000000
SWEEP_LARGE ?= 0
SWEEP_BASELINE ?=
sweep-bench: setup
	$(BIN)/python benchmarks/sweep_bench.py --trajectories $(SWEEP_TRAJECTORIES) --memory $(SWEEP_MEMORY) \
	  --large $(SWEEP_LARGE) $(if $(SWEEP_BASELINE),--baseline $(SWEEP_BASELINE))

## sweep-map: the stability map of NOTES.md, the Monte Carlo example and the misalignment Monte Carlo
## over rw4_hardware (10^5 trajectories, one build; its histograms.png is docs/rw4_misalignment.png), into report/
sweep-map: setup
	$(BIN)/gyrogen sweep stability_map --out report/stability_map
	$(BIN)/gyrogen sweep monte_carlo --out report/monte_carlo
	$(BIN)/gyrogen sweep rw4_misalignment --out report/rw4_misalignment

## check: numerical stability on every stiff and extreme case
check: setup
	$(BIN)/gyrogen check --all --plots report/check

clean:
	rm -rf build site examples/build bench-out report sim sweep fuzz-failures .hypothesis .pytest_cache .mypy_cache .ruff_cache *.egg-info
	find generator tests benchmarks tools docs/hooks -name __pycache__ -type d -prune -exec rm -rf {} +
	rm -rf "$${GYROGEN_CACHE:-$${XDG_CACHE_HOME:-$$HOME/.cache}/gyrogen}"

distclean: clean
	rm -rf $(VENV)

## examples: build and run the embedding examples (C, Fortran, C++) against generated/
examples: setup
	$(MAKE) -C examples run

## strict: the strictness matrix (gcc/clang c99/c11, g++, gfortran, sanitizers, valgrind)
strict: setup
	$(BIN)/pytest tests/test_strict.py
