# aogm: `make demo` and `make test` are all the set-up a fresh clone needs (Python 3.11).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
# STAMP: aogm and what it imports, all that demo, bench and figure need; DEV: and the dev extra
# (pytest, ruff, import-linter, hypothesis, Dask) that test and lint need
STAMP  := $(VENV)/.installed-stamp
DEV    := $(VENV)/.dev-stamp
PIP    := $(BIN)/python -m pip install --quiet --disable-pip-version-check
OUT    := out
SEED   := 1
WORLDS := $(wildcard worlds/*.yaml)

.PHONY: demo test kernels bench lint install clean figure

# Python compiles each module it imports to bytecode once, into __pycache__ (the install skips it:
# --no-compile). An environment with PYTHONDONTWRITEBYTECODE set (this machine's) would make every
# process compile numpy, scipy, numba and aogm again: 3-4 s to start aogm instead of 1.6 s, and the
# test suite's CPU time 280 s instead of 199 s (it starts a process per command it runs)
unexport PYTHONDONTWRITEBYTECODE

# a fresh clone's make demo installs no dev extra; make test installs both in one pip run
$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(PIP) --no-compile -e .
	touch $(STAMP)

$(DEV): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(PIP) --no-compile -e '.[dev]'
	touch $(STAMP) $(DEV)

install: $(DEV)

demo: $(STAMP)
	@mkdir -p $(OUT)/maps
	@for w in $(WORLDS); do \
	  n=$$(basename $$w .yaml); \
	  $(BIN)/aogm simulate $$w -o $(OUT)/$$n.h5 --seed $(SEED) --png $(OUT)/$$n-truth.png --quiet || exit 1; \
	  echo "simulated $$w -> $(OUT)/$$n.h5 (truth picture $(OUT)/$$n-truth.png)"; \
	done
	$(BIN)/aogm compare $(addprefix $(OUT)/,$(notdir $(WORLDS:.yaml=.h5))) --modes standard,em,adaptive \
	  --maps-dir $(OUT)/maps --json $(OUT)/report.json --figure $(OUT)/report.png --quiet
	@echo "table above; figure $(OUT)/report.png, JSON $(OUT)/report.json, maps in $(OUT)/maps/"

# one pytest worker per core (pytest-xdist), an idle worker taking tests from the busy one's queue
# (--dist worksteal: the warm suite in 92 s instead of 97-109 s on two cores): the suite is
# CPU-bound numba and numpy. First, two processes compile two halves of the kernels into numba's
# cache (tests/warm_kernels.py), which both workers would otherwise compile each
kernels: $(DEV)
	d=$$(mktemp -d); $(BIN)/python tests/warm_kernels.py em $$d & p=$$!; \
	  $(BIN)/python tests/warm_kernels.py rest $$d && wait $$p; s=$$?; rm -rf $$d; exit $$s

test: kernels
	$(BIN)/python -m pytest -n auto --dist worksteal

# Property-based fuzzing (hypothesis, fixed seed) of world files and of damaged logs, maps and
# detectors: FUZZ_EXAMPLES per file kind (make test runs 15); prints per kind the examples,
# crashes, hangs, other exits, partial outputs and the time taken.
FUZZ_EXAMPLES ?= 2000
.PHONY: fuzz
fuzz: $(DEV)
	AOGM_FUZZ_EXAMPLES=$(FUZZ_EXAMPLES) $(BIN)/python -m pytest -q -s -p no:cacheprovider tests/test_fuzz.py

# Throughput against a ceiling measured in the same run: the simulator, the standard mapper, EM and
# adaptive mapping (docs/benchmarks.md, "Throughput against a ceiling")
bench: $(STAMP)
	$(BIN)/python bench/bench_simulate.py
	$(BIN)/python bench/bench_standard.py
	$(BIN)/python bench/bench_em.py
	$(BIN)/python bench/bench_adaptive.py
	$(BIN)/python bench/bench_summary.py

# Benchmarks at building scale (not part of test or bench; docs/benchmarks.md, "Benchmarks at scale"): each
# mode on the two seed worlds (best of BENCH_RUNS, one process), then the generated office floor at
# SCALE_SIZES scans in every mode of SCALE_MODES (/1: on one thread), each map in its own process under SCALE_MEMORY of
# address space (a run that does not fit is a failed row). Worlds, logs, maps and JSON: out/bench-scale/.
SCALE_SIZES  ?= 2000,10000,50000,200000
SCALE_MODES  ?= standard,em,em/1,adaptive,adaptive/1,adaptive:all,adaptive:none
SCALE_MEMORY ?= 12G
SCALE_ARGS   ?=
BENCH_RUNS   ?= 5
SEED_ARGS    ?=
.PHONY: bench-scale
bench-scale: $(STAMP)
	@mkdir -p $(OUT)/bench-scale
	$(BIN)/python bench/bench_seed_adaptive.py --runs $(BENCH_RUNS) $(SEED_ARGS) --json $(OUT)/bench-scale/seed_worlds.json
	$(BIN)/python bench/bench_scale.py --sizes $(SCALE_SIZES) --modes $(SCALE_MODES) --max-memory $(SCALE_MEMORY) \
	  --workdir $(OUT)/bench-scale --json $(OUT)/bench-scale/scale.json $(SCALE_ARGS)

# ruff, and the layers of pyproject.toml's [tool.importlinter] (an import against the flow fails)
lint: $(DEV)
	@status=0; $(BIN)/ruff check . || status=1; $(BIN)/lint-imports --no-cache || status=1; exit $$status

# The packaged detector: simulate every bundled world, clean and realistic (*_real: an errors:
# section), except the two test worlds of the paper's figures and their realistic variants
# (*_real) and the Pioneer worlds (another sensor: 8 sonars), hold
# out two (a specular corridor and a furnished room) for validation, train (seeded). The file's
# training_logs attribute records each log's world, realistic flag, seed and scans.
# DETECTOR_OUT=FILE writes the detector there instead of into the package.
DETECTOR_TEST_WORLDS := corridor_door corridor_specular
DETECTOR_WORLDS     := $(filter-out $(foreach n,$(DETECTOR_TEST_WORLDS),worlds/$(n).yaml worlds/$(n)_real.yaml) worlds/%_pioneer.yaml,$(WORLDS))
DETECTOR_VALIDATION := l_corridor furnished_room
DETECTOR_OUT        ?= aogm_cli/data/detector.h5
.PHONY: detector
detector: $(STAMP)
	@mkdir -p $(OUT)/detector
	@for w in $(DETECTOR_WORLDS); do \
	  $(BIN)/aogm simulate $$w -o $(OUT)/detector/$$(basename $$w .yaml).h5 --seed $(SEED) --quiet || exit 1; \
	done
	$(BIN)/aogm train $(patsubst worlds/%.yaml,$(OUT)/detector/%.h5,$(DETECTOR_WORLDS)) \
	  $(foreach n,$(DETECTOR_VALIDATION),--validation-logs $(OUT)/detector/$(n).h5) \
	  -o $(DETECTOR_OUT) --seed $(SEED) --sensor-models --quiet

# The README's picture: corridor_door at seed 1, its truth and the three modes (docs/modes.png)
figure: $(STAMP)
	@mkdir -p $(OUT)
	$(BIN)/aogm simulate worlds/corridor_door.yaml -o $(OUT)/figure_door.h5 --seed 1 --quiet
	$(BIN)/aogm compare $(OUT)/figure_door.h5 --modes standard,em,adaptive --figure docs/modes.png --quiet

clean:
	rm -rf $(OUT) .pytest_cache .hypothesis
