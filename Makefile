# One task runner; CI calls `make test` verbatim (see .ci/run).
# Everything Python lives in ./.venv, created here; nothing is installed by hand.

PYTHON  ?= python3
VENV    := .venv
PY      := $(VENV)/bin/python
PIP     := $(PY) -m pip
WHEELS  := target/wheels
CARGO   ?= cargo
CC      ?= cc
PREFIX  ?= /usr/local
CBINDGEN := .tools/bin/cbindgen
LIBDIR  := target/release
CFLAGS_C := -std=c11 -O2 -Wall -Wextra -Werror -Iinclude
LDLIBS_C := -L$(LIBDIR) -likid -Wl,-rpath,$(abspath $(LIBDIR)) -lpthread -lm
VERSION := $(shell sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -1)

.PHONY: all venv wheel wheel-portable sdist demo data models models-track report check test test-rust test-python test-python-slow test-c faults lint fmt-check clippy ruff mypy stubtest bench bench-peers fuzz mutants clean capi c header check-header install compare-opensim compare-ekf compare-rates realdata exam live mutants-status

all: wheel

# The venv with the build tool; the wheel's own extras (test, eval) are installed from its
# metadata and the training pipeline's dependencies from training/pyproject.toml, so those two
# files are the lists of Python dependencies.
$(VENV)/.created:
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --quiet --upgrade pip
	$(PIP) install --quiet "maturin>=1.9.4,<2"
	touch $@

venv: $(VENV)/.created

# Build the abi3 wheel in release mode and install it (with extras) into the venv: tests
# run against the same wheel a user would pip install. Rebuilt only when a tracked source
# of it changed (the stamp is newer than every one of them); training/ is not one.
WHEEL_STAMP := $(VENV)/.wheel-installed
WHEEL_BUILT := $(VENV)/.wheel-built
WHEEL_SOURCES := $(shell git ls-files crates python Cargo.toml Cargo.lock pyproject.toml README.md 2>/dev/null)
$(WHEEL_BUILT): $(VENV)/.created $(WHEEL_SOURCES)
	rm -f $(WHEELS)/ikid-*.whl
	$(VENV)/bin/maturin build --release --quiet -o $(WHEELS)
	$(PIP) install --quiet --force-reinstall --no-deps $(WHEELS)/ikid-*.whl
	touch $@
$(WHEEL_STAMP): $(WHEEL_BUILT)
	$(PIP) install --quiet "$$(ls $(WHEELS)/ikid-*.whl)[test,eval]"
	touch $@

# What `make demo` needs and no more: the wheel with its runtime dependencies, and matplotlib
# for the demo's plot (not torch, not the peers: a first run stays light).
DEMO_STAMP := $(VENV)/.demo-installed
$(DEMO_STAMP): $(WHEEL_BUILT)
	$(PIP) install --quiet "$$(ls $(WHEELS)/ikid-*.whl)" matplotlib
	touch $@

# The training pipeline (training/, its own distribution ikid-training: torch, ONNX, matplotlib)
# installed editable after the runtime it depends on, so tests and `make models` run the sources
# as they are; reinstalled only when its metadata changes.
TRAINING_STAMP := $(VENV)/.training-installed
$(TRAINING_STAMP): training/pyproject.toml | $(WHEEL_STAMP)
	$(PIP) install --quiet -e ./training
	touch $@

wheel: $(WHEEL_STAMP) $(TRAINING_STAMP)

# The portable wheel (what is published): manylinux2014, i.e. glibc >= 2.17 (CentOS 7, RHEL 8,
# Ubuntu 18.04+, Debian 9+), linked by zig against that old glibc, checked by auditwheel (its tag
# and no library outside the manylinux policy), then installed in a fresh venv and run. In its
# own target folder so development rebuilds (`make wheel`, native, faster) are not undone; part
# of `make test`. The sdist (target/sdist) builds wherever cargo is: tests/test_packaging.py.
ZIGLANG_VERSION    := 0.17.0
AUDITWHEEL_VERSION := 6.8.2
PORTABLE_WHEELS    := target/wheels-portable
PORTABLE_TOOLS     := $(VENV)/.portable-tools
PORTABLE_TAG       := manylinux2014_x86_64.manylinux_2_17_x86_64
$(PORTABLE_TOOLS): $(VENV)/.created
	$(PIP) install --quiet "ziglang==$(ZIGLANG_VERSION)" "auditwheel==$(AUDITWHEEL_VERSION)"
	touch $@

wheel-portable: $(PORTABLE_TOOLS)
	rm -rf $(PORTABLE_WHEELS) target/portable-venv
	PATH="$(abspath $(VENV)/bin):$$PATH" CARGO_TARGET_DIR=target/portable \
		$(VENV)/bin/maturin build --release --quiet --zig --compatibility manylinux2014 -o $(PORTABLE_WHEELS)
	ls $(PORTABLE_WHEELS)/ikid-*-cp310-abi3-$(PORTABLE_TAG).whl
	$(VENV)/bin/auditwheel show $(PORTABLE_WHEELS)/ikid-*.whl | tee target/auditwheel-show.txt
	tr -s '\n ' '  ' < target/auditwheel-show.txt | grep -q 'is consistent with the following platform tag: "manylinux_2_17_x86_64"'
	! grep -qi "external shared libraries\|not consistent\|cannot repair" target/auditwheel-show.txt
	$(PYTHON) -m venv target/portable-venv
	target/portable-venv/bin/python -m pip install --quiet $(PORTABLE_WHEELS)/ikid-*.whl
	cd target && portable-venv/bin/python -c "import ikid, numpy as np; m = ikid.load('wrist-ik'); \
		f = ikid.forward_markers(np.zeros((80, 3)), 0.3); print('portable wheel runs:', ikid.__file__, m.predict(f).shape)"

sdist: $(VENV)/.created
	rm -rf target/sdist
	$(VENV)/bin/maturin sdist --out target/sdist

demo: $(DEMO_STAMP)
	$(PY) -m ikid demo

# Simulated datasets (gitignored): the thesis-sized set (3 shoulder poses x 42 movements)
# and 18 random multi-DoF trials of 60 s (3 poses x 3 subject sizes x 2), in parallel.
data: wheel
	$(VENV)/bin/ikid dataset -o data

# Retrain the shipped models from scratch (<= 15 min on 2 cores; training/ikid_training) into
# python/ikid/models/; rebuild the wheel afterwards to ship them.
models: wheel
	$(PY) -m ikid_training.models

# Retrain wrist-track, the Kalman tracker's refiner (~9 min on 2 cores), into python/ikid/models/
# (`python -m ikid_training.refine --rate 100` trains one at another rate; why none is shipped:
# ikid_training/refine.py).
models-track: wheel
	$(PY) -m ikid_training.refine

# The evaluation report (docs/report.md + PNG plots) of the shipped models, beside the
# classical reference and the thesis' numbers.
report: wheel
	$(PY) -m ikid_training.report

# Two tiers. `make check` (a few minutes once built): lint first (rustfmt, clippy, ruff, mypy,
# the C header), then the Rust tests, the fast Python tests and the stub check. `make test`
# (what CI runs): check, then the slow tier: shipped-model accuracy, training end to end,
# torch/OpenSim/biorbd peers, the C programs under valgrind (a failure, not a skip, in CI when
# valgrind is missing), the embedding programs and the sdist built from outside the repository,
# 60 s of fuzzing, the fault suite and the portable wheel (built, audited, installed, run).
check: lint test-rust test-python stubtest mutants-status
	@echo "make check: all passed"

test: check test-python-slow fuzz faults wheel-portable
	@echo "make test: all suites passed"

lint: fmt-check clippy ruff mypy check-header

fmt-check:
	$(CARGO) fmt --all --check
	cd fuzz && $(CARGO) fmt --check

clippy:
	$(CARGO) clippy --workspace --all-targets -- -D warnings

PY_SOURCES := python training tests benches studies examples tools
ruff: wheel
	$(VENV)/bin/ruff check $(PY_SOURCES)
	$(VENV)/bin/ruff format --check $(PY_SOURCES)

mypy: wheel
	$(VENV)/bin/mypy python/ikid training/ikid_training

# The doc tests run here too (the crate docs' examples); the shipped models compiled in
# (feature embedded-models) are checked against the files.
test-rust:
	$(CARGO) test --workspace --exclude ikid-py --profile quick
	$(CARGO) test -p ikid --profile quick --features embedded-models --lib shipped

# Python tests against the installed wheel; those marked `slow` (tests/conftest.py) run in
# `make test` only. The C ABI tests need the C programs (`make c`).
test-python: wheel c
	cd tests && ../$(PY) -m pytest -q -p no:cacheprovider -m "not slow" .

test-python-slow: wheel c
	cd tests && ../$(PY) -m pytest -q -p no:cacheprovider -m slow .

# The fault suite (tests/faults, issue #22; part of `make test`): ~1000 probes, each one bad
# input (mutated C3D/TRC/CSV/MOT/STO/TOML/JSON/safetensors files, bad option values, a full
# disk, a read-only folder, garbage frames, corrupted weights, NULLs into libikid) with its
# assertions: no traceback or crash, a named error or a flagged output, no partial write.
# Not collected by pytest (no test_*.py there). Prints one line per failing probe; the last
# line reads `faults: probes=<n> passed=<n> silent=<n> partial_writes=<n> tracebacks=<n>`.
faults: wheel capi
	cd tests && ../$(PY) -m faults

stubtest: wheel
	$(PY) -m mypy.stubtest ikid._native

test-c: c wheel
	cd tests && ../$(PY) -m pytest -q -p no:cacheprovider test_capi.py

# --- C ABI (libikid) ---------------------------------------------------------------------
# cbindgen >= 0.29 reads edition-2024 attributes (Debian's 0.24 cannot): built once into .tools.
$(CBINDGEN):
	$(CARGO) install cbindgen --version 0.29.4 --locked --root .tools

# libikid.so carries the SONAME libikid.so.$(SOMAJOR) (crates/ikid-capi/build.rs): a host records
# that name, so the link sits beside the library here too (the C tests run from target/release).
SOMAJOR := $(firstword $(subst ., ,$(VERSION)))
capi:
	$(CARGO) build --release -p ikid-capi
	ln -sf libikid.so $(LIBDIR)/libikid.so.$(SOMAJOR)

# Regenerate include/ikid.h after changing the ABI; check-header fails on any difference.
header: $(CBINDGEN)
	$(CBINDGEN) --config crates/ikid-capi/cbindgen.toml --crate ikid-capi --output include/ikid.h

check-header: $(CBINDGEN)
	$(CBINDGEN) --config crates/ikid-capi/cbindgen.toml --crate ikid-capi --output include/ikid.h --verify

# The C test, example and ABI benchmark, built with plain cc against the committed header.
c: capi
	mkdir -p target/c
	$(CC) $(CFLAGS_C) tests/c/test_capi.c -o target/c/test_capi $(LDLIBS_C)
	$(CC) $(CFLAGS_C) tests/c/test_tracker.c -o target/c/test_tracker $(LDLIBS_C)
	$(CC) $(CFLAGS_C) tests/c/every_call.c -o target/c/every_call $(LDLIBS_C)
	$(CC) $(CFLAGS_C) examples/c/stream_csv.c -o target/c/stream_csv $(LDLIBS_C)
	$(CC) $(CFLAGS_C) examples/c/track_csv.c -o target/c/track_csv $(LDLIBS_C)
	$(CC) $(CFLAGS_C) benches/c/abi_overhead.c -o target/c/abi_overhead $(LDLIBS_C)

# Installs libikid (shared and static), ikid.h and a pkg-config file under PREFIX, as a system
# library: libikid.so.$(VERSION) (the file), libikid.so.$(SOMAJOR) (its SONAME, what hosts load),
# libikid.so (the link -likid finds). ikid.pc's Libs carry an rpath to PREFIX/lib, so a host
# linked through pkg-config starts without LD_LIBRARY_PATH wherever PREFIX is.
install: capi
	install -d $(PREFIX)/lib/pkgconfig $(PREFIX)/include
	install -m 755 $(LIBDIR)/libikid.so $(PREFIX)/lib/libikid.so.$(VERSION)
	ln -sf libikid.so.$(VERSION) $(PREFIX)/lib/libikid.so.$(SOMAJOR)
	ln -sf libikid.so.$(SOMAJOR) $(PREFIX)/lib/libikid.so
	install -m 644 $(LIBDIR)/libikid.a $(PREFIX)/lib/
	install -m 644 include/ikid.h $(PREFIX)/include/
	sed -e 's|@PREFIX@|$(abspath $(PREFIX))|' -e 's|@VERSION@|$(VERSION)|' crates/ikid-capi/ikid.pc.in > $(PREFIX)/lib/pkgconfig/ikid.pc

# cargo-fuzz on the model loader for FUZZ_SECONDS (bounded; part of `make test`). Starts from
# the committed seeds (valid small models) and keeps its corpus in fuzz/corpus (ignored).
# cargo-fuzz needs the nightly toolchain (sanitizer flags); it is built once into .tools.
FUZZ_SECONDS ?= 60
CARGO_FUZZ := .tools/bin/cargo-fuzz
$(CARGO_FUZZ):
	$(CARGO) install cargo-fuzz --locked --root .tools

fuzz: $(CARGO_FUZZ)
	mkdir -p fuzz/corpus/model_file
	cd fuzz && PATH="$(abspath .tools/bin):$$PATH" cargo +nightly fuzz run model_file corpus/model_file seeds/model_file \
		-- -max_total_time=$(FUZZ_SECONDS) -max_len=8192 -timeout=5 -rss_limit_mb=2048 -print_final_stats=1 > corpus/last-run.log 2>&1 \
		|| (tail -40 corpus/last-run.log; exit 1)
	grep -E "^(Done|stat::number_of_executed_units|stat::peak_rss_mb)" fuzz/corpus/last-run.log
	@test ! -d fuzz/artifacts/model_file || test -z "$$(ls -A fuzz/artifacts/model_file)" || (echo "fuzz: crash inputs in fuzz/artifacts/model_file"; exit 1)

# Mutation testing of the core: the check to run on changes to crates/ikid (not part of
# `make test`). cargo-mutants mutates MUTANTS_FILES and runs `cargo test -p ikid` on each
# mutant in the `quick` profile (no LTO: ~15-20 s a mutant on this shared 2-core machine,
# build and tests). MUTANTS_SHARD=k/n takes every n-th mutant (round robin, so every file and
# kind is sampled): 0/6 is 550 mutants (a quarter unviable), ~3 h; run k = 0..5 for all of
# them. Mutants no test can tell from the original are listed, each with its reason, in
# .cargo/mutants.toml. Fails below MUTANTS_MIN_SCORE; the last line
# reads `mutants: viable=<n> caught=<n> missed=<n> score=<0.xx>`. MUTANTS_ARGS passes more
# options, e.g. `--shuffle`: mutants in random order, so a run stopped early is a fair sample
# of the shard (in source order it has seen only the first files).
CARGO_MUTANTS := .tools/bin/cargo-mutants
MUTANTS_FILES ?= features net/mlp gaps tracker/* calibration/* stream cluster
MUTANTS_SHARD ?= 0/6
MUTANTS_MIN_SCORE ?= 0.95
MUTANTS_ARGS ?=
$(CARGO_MUTANTS):
	$(CARGO) install cargo-mutants --version 27.1.0 --locked --root .tools

mutants: $(CARGO_MUTANTS)
	mkdir -p target
	PATH="$(abspath .tools/bin):$$PATH" $(CARGO) mutants -p ikid $(foreach f,$(MUTANTS_FILES),-f 'crates/ikid/src/$(f).rs') \
		--shard $(MUTANTS_SHARD) --sharding round-robin --profile quick $(MUTANTS_ARGS) -o target/mutants > target/mutants.log 2>&1 \
		|| test -f target/mutants/mutants.out/outcomes.json || (tail -30 target/mutants.log; exit 1)
	$(PYTHON) tools/mutants_summary.py target/mutants/mutants.out --min-score $(MUTANTS_MIN_SCORE) \
		--record "$(MUTANTS_FILES), shard $(MUTANTS_SHARD)"

# The last `make mutants` run's score, commit and date, and whether crates/ikid changed since:
# printed by `make check`, so the score is seen on every change to the core.
mutants-status:
	@$(PYTHON) tools/mutants_summary.py target/mutants/mutants.out --status

# Live sources (issue #30, docs/live.md): the live tests, then source -> ikid latency on the
# loopback at 1 kHz (LSL and a fake QTM server, 3 runs each, medians), a source restart, and
# one closing `live: ...` line. Not in make check's fast tier's time budget (~1 min).
live: $(WHEEL_STAMP)
	cd tests && ../$(PY) -m pytest -q -p no:cacheprovider test_live.py
	$(PY) benches/live.py

# Criterion benches, per-push latency distribution, the Python overhead and a 10^7-push soak
# (zero allocations, flat memory), written to docs/performance.md.
bench: wheel c
	$(CARGO) bench -p ikid --bench inference
	$(PY) benches/report.py

# ikid beside onnxruntime, torch (eager, TorchScript) and NumPy on the same networks, and ikid's
# Tracker (bare and with wrist-track) beside biorbd's EKF + inverse dynamics on the same held-out
# frames (angle and torque RMS, per-frame latency), one run (~5 min): a section of
# docs/performance.md and target/peers.json (`studies/peers.py --render` rewrites the section).
bench-peers: wheel c
	$(PY) studies/peers.py

clean:
	$(CARGO) clean
	rm -rf $(VENV)

# OpenSim's IK (on the .osim ikid writes) beside ikid's wrist-ik and reference_ik on the same
# held-out trials at 0/1/5 % noise: a section of docs/opensim.md and target/opensim_ik.json.
compare-opensim: wheel
	$(PY) studies/opensim_ik.py

# ikid beside biorbd's extended Kalman filter (+ its least-squares IK and inverse dynamics) on the
# same held-out frames, angles, torques and step latency: docs/ekf.md and target/ekf_peer.json
# (~10 min on 2 cores; the eval extra brings biorbd).
compare-ekf: wheel
	$(PY) studies/ekf_peer.py

# ikid at 100, 250 and 1000 Hz (the wrist-ik model for each rate, the Tracker) beside biorbd's EKF
# at the same rate on the same held-out frames: docs/rates.md and target/rates.json (~10 min on
# 2 cores; not part of `make test`).
compare-rates: wheel
	$(PY) studies/rates.py

# The exam (issue #28): ikid on wrist models it did not make — two published models simulated by
# OpenSim (Rajagopal 2016 / MoBL-ARMS, Gonzalez 1997), three marker layouts, clean / 1 % / 5 % noise
# / dropouts, calibrated by `ikid calibrate` from the exam's own trials — beside biorbd's EKF + ID
# and OpenSim IK + ID on the same frames: docs/exam.md and target/exam.json; the last line is
# exam: models=... rows_missing=... (~12 min on 2 cores; `$(PY) -m studies.exam --quick`: ~1 min).
exam: wheel
	$(PY) -m studies.exam

# Real recordings (../shared/realdata, or $$IKID_REALDATA) through the CLI: calibrate from the
# recording, ik, track, scored against the independent reference angles: docs/realdata.md and
# docs/realdata/*.png; the last line is realdata: pyomeca_ik=... diverged=N (~1 min).
realdata: wheel
	$(PY) tools/realdata.py
