# One task runner; CI calls `make test` verbatim (see .ci/run).
# Everything Python lives in ./.venv, created here; nothing is installed by hand.

PYTHON  ?= python3
VENV    := .venv
PY      := $(VENV)/bin/python
PIP     := $(PY) -m pip
WHEELS  := target/wheels
CARGO   ?= cargo

.PHONY: all venv wheel demo test test-rust test-python lint bench clean

all: wheel

# The venv with the build tool; the wheel's own extras (train, test) are installed from its
# metadata, so pyproject.toml is the one list of Python dependencies.
$(VENV)/.created:
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --quiet --upgrade pip
	$(PIP) install --quiet "maturin>=1.9.4,<2"
	touch $@

venv: $(VENV)/.created

# Build the abi3 wheel in release mode and install it (with extras) into the venv: tests
# run against the same wheel a user would pip install.
wheel: $(VENV)/.created
	rm -f $(WHEELS)/ikid-*.whl
	$(VENV)/bin/maturin build --release --quiet -o $(WHEELS)
	$(PIP) install --quiet --force-reinstall --no-deps $(WHEELS)/ikid-*.whl
	$(PIP) install --quiet "$$(ls $(WHEELS)/ikid-*.whl)[train,test]"

demo: wheel
	$(PY) -m training.demo

test: test-rust wheel test-python lint
	@echo "make test: all suites passed"

test-rust:
	$(CARGO) test --workspace --exclude ikid-py

test-python: wheel
	cd tests && ../$(PY) -m pytest -q -p no:cacheprovider .
	$(PY) -m mypy.stubtest ikid._native

lint:
	$(CARGO) clippy --workspace --all-targets -- -D warnings

# Criterion benches, per-push latency distribution and the Python overhead, written to
# docs/performance.md.
bench: wheel
	$(CARGO) bench -p ikid --bench inference
	$(PY) benches/report.py

clean:
	$(CARGO) clean
	rm -rf $(VENV)
