# adaptune — two commands on a fresh machine: `make repro` and `make test`.
VENV ?= .venv
PY := $(VENV)/bin/python
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: constraints setup test fuzz lint deps bench repro verdict verdict-headroom real docs kitti clean

setup: $(STAMP)

# the Debian packages (.ci/install-system-deps: open3d's libusb, qemu-user for the emulated-CPU
# test, ROS 1 for `adaptune node`) when one is missing, then Debian's ROS modules for the venv,
# after its own (.ci/ros-python)
$(STAMP): pyproject.toml constraints.txt .ci/install-system-deps .ci/ros-python
	python3 -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -c constraints.txt -e '.[dev]'
	@bash .ci/install-system-deps
	@$(PY) -c "import open3d" >/dev/null
	@$(PY) .ci/ros-python
	touch $(STAMP)

# constraints.txt: the exact versions of every package the venv holds (pip freeze), which
# `make setup` installs: numpy, OpenBLAS, numba, open3d or DuckDB of another version give other
# numbers; after a dependency change in pyproject.toml: make constraints, then commit both
constraints: setup
	$(BIN)/pip install --quiet -e '.[dev]'
	{ sed -n '1,3p' constraints.txt; $(BIN)/pip freeze --exclude-editable; } > constraints.txt.new
	mv constraints.txt.new constraints.txt

# the suite in TEST_WORKERS processes (pytest-xdist), a test file per process so that a file's
# module fixtures (the DVC projects of tests/test_pipeline_dvc.py) are built once; 2 on 2 cores
# (3 were no faster than 2 in three idle runs on 2 cores, and used more CPU); the slow modules
# go out first (tests/conftest.py's order, --no-loadscope-reorder)
TEST_WORKERS ?= 2
# every command below runs through `adaptune exec`: the pinned CPU dispatch of the stages
# (pipeline/dispatch.py), so that in-process code gives the numbers the stages give
test: setup
	$(BIN)/adaptune exec -- $(BIN)/pytest -q -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder

# the fuzz suite of tests/fuzz at length: FUZZ_EXAMPLES examples a target, random seeds
# (make test runs it small and seeded); a failure prints the blob that replays it
FUZZ_EXAMPLES ?= 2000
fuzz: setup
	ADAPTUNE_FUZZ_EXAMPLES=$(FUZZ_EXAMPLES) nice -n 10 $(BIN)/adaptune exec -- $(BIN)/pytest -q tests/fuzz \
		--hypothesis-show-statistics --durations=0

lint: setup
	$(BIN)/ruff check pipeline stages studies schemas tests bench experiments examples
	$(BIN)/mypy pipeline stages studies
	$(PY) tests/helpers/dvc_deps.py --check

# dvc.yaml's code deps, generated from the import graph of each stage's command (checked by
# `make lint` and tests/test_dvc_deps.py)
deps: setup
	$(PY) tests/helpers/dvc_deps.py

bench: setup
	$(BIN)/adaptune exec -- $(PY) bench/run.py

# DVC hashes every output it caches on min(4, cores / 2) threads by default, one on 2 cores;
# DVC_HASH_JOBS threads instead (this clone's .dvc/config.local): the verdict's tuning suite,
# 41 GB, hashes in 31 s instead of 62 on 2 cores (docs/performance.md, "The verdict's suites")
DVC_HASH_JOBS ?= $(shell nproc)
DVC_CONFIG = $(BIN)/dvc config --local core.checksum_jobs $(DVC_HASH_JOBS)

# dvc runs the stages' `adaptune ...` commands: the venv's bin must be on PATH
repro: setup
	$(DVC_CONFIG)
	PATH="$(abspath $(BIN)):$$PATH" $(BIN)/dvc repro

# The coverage model's verdict (issue 29; docs/results/verdict-protocol.md): the second pipeline,
# verdict/dvc.yaml with verdict/params.yaml. `make verdict` trains the coverage model (the fixed
# set on every environment class with the HDL-32E and the HDL-64E, one portfolio model per
# sensor on the tuning suite) and scores both test suites (in distribution, out of
# distribution: the VLP-16); `make verdict-headroom` adds the oracles and the closed gap on the
# in-distribution suite. A dev suite: `dvc exp run verdict/dvc.yaml:verdict_id -S
# verdict/params.yaml:verdict.suite=dev`.
verdict: setup
	$(DVC_CONFIG)
	PATH="$(abspath $(BIN)):$$PATH" $(BIN)/dvc repro verdict/dvc.yaml:verdict_id \
		verdict/dvc.yaml:verdict_ood

verdict-headroom: setup
	$(DVC_CONFIG)
	PATH="$(abspath $(BIN)):$$PATH" $(BIN)/dvc repro verdict/dvc.yaml:headroom

# The real-data study (docs/results/real.md): the third pipeline, real/dvc.yaml with
# real/params.yaml (frozen before any test fold ran), on the four recorded runs of
# ../shared/data/real: every unit's studies, the folds' fixed, adaptive and in-sample best, the
# report. It resumes through the DVC cache (studies and folds persist). `make real` runs it
# all; a part with REAL_STAGES, e.g. NDT's folds: make real REAL_STAGES=real/dvc.yaml:folds@ndt
REAL_STAGES ?= real/dvc.yaml:report
real: setup
	$(DVC_CONFIG)
	PATH="$(abspath $(BIN)):$$PATH" $(BIN)/dvc repro $(REAL_STAGES)

# the docs pages that quote metrics/*.json (docs/results/toy.md, the README's result), rendered
# from the committed metrics, dvc.lock and docs/results/runs.yaml; a test checks they are current
docs: setup
	$(BIN)/adaptune study docs

# The paper's KITTI protocol (Table II): train 00-05, test 06-10, L = 100 m, the devkit metric.
#   make kitti KITTI_ROOT=/data/kitti/dataset         real KITTI (a KITTI odometry root), or
#   make kitti KITTI_SIMULATED=<folder of NN.txt>     simulated KITTI along the real trajectories
#   [KITTI_ALGORITHMS="gicp kiss_icp ndt"] [KITTI_OPTS="--start 0 --end 999 --iterations 64"]
# One `dvc exp run evaluate generalize` per algorithm (the stages they need, not the toy's
# simulate; adaptune study kitti-preset prints the --set-params, among them generalize.worlds=0:
# KITTI needs no generalization suite, and that stage then writes outputs that say so, not
# the toy's), then the table of all of them: $(KITTI_OUT)/table.md and
# table.json (from each algorithm's metrics and record).
KITTI_ALGORITHMS ?= gicp
KITTI_OUT ?= results/kitti
KITTI_SOURCE = $(if $(KITTI_ROOT),--root "$(KITTI_ROOT)",--simulated "$(KITTI_SIMULATED)")
kitti: setup
	@test -n "$(KITTI_ROOT)$(KITTI_SIMULATED)" || \
	  { echo "make kitti: set KITTI_ROOT=<KITTI odometry root> or KITTI_SIMULATED=<folder>" >&2; exit 1; }
	mkdir -p $(KITTI_OUT)/metrics $(KITTI_OUT)/records
	for a in $(KITTI_ALGORITHMS); do \
	  $(BIN)/adaptune study kitti-preset $(KITTI_SOURCE) --algorithm $$a $(KITTI_OPTS) \
	    > $(KITTI_OUT)/$$a.args && \
	  PATH="$(abspath $(BIN)):$$PATH" xargs -a $(KITTI_OUT)/$$a.args -d '\n' $(BIN)/dvc exp run evaluate generalize && \
	  cp metrics/evaluation.json $(KITTI_OUT)/metrics/$$a.json && \
	  cp records/evaluation.json $(KITTI_OUT)/records/$$a.json || exit 1; \
	done
	$(BIN)/adaptune study kitti-table $(foreach a,$(KITTI_ALGORITHMS),$(KITTI_OUT)/metrics/$(a).json) \
	  --out $(KITTI_OUT)

clean:
	rm -rf $(VENV) .pytest_cache
