# facesvg: `make run` sets up and converts the bundled sample (then serves the web UI); `make test` runs the tests.
# `make test-fast` skips the tests marked slow or browser; `make lint` runs ruff (configured in pyproject.toml).
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
WARM := $(VENV)/.warm
KERNELS := $(shell grep -rl --include=*.py numba.njit converter)  # the sources of the compiled kernels
export PYOPENGL_PLATFORM := egl

.PHONY: setup run convert test test-fast lint golden bench clean

setup: $(WARM)
	@if command -v npm >/dev/null 2>&1 && ! [ tests/reference/node_modules/.package-lock.json -nt tests/reference/package-lock.json ]; then cd tests/reference && npm ci --no-audit --no-fund --silent; fi

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

# Compile the kernels once here, not in the first conversion (~20 s); afresh after any change to their sources,
# since numba's cache does not notice a change to a kernel's callee in another file (converter/warm.py).
$(WARM): $(STAMP) $(KERNELS)
	$(BIN)/facesvg warm --fresh --quiet
	touch $(WARM)

convert: setup
	mkdir -p out
	$(BIN)/facesvg convert samples/face.glb -o out/face.svg --progress

run: convert
	@if $(BIN)/python -c "import webapp" 2>/dev/null; then \
		echo "Serving the web UI on http://127.0.0.1:5000 (Ctrl-C to stop)"; \
		$(BIN)/facesvg serve --host 127.0.0.1 --port 5000; \
	else echo "Wrote out/face.svg"; fi

test: setup
	$(BIN)/python -m pytest -q -n 2 --dist loadfile

test-fast: setup
	$(BIN)/python -m pytest -q -n 2 --dist loadfile -m "not slow and not browser"

lint: setup
	$(BIN)/ruff check .

golden: setup
	$(BIN)/python -m pytest -q --update-golden tests

bench: setup
	$(BIN)/python bench/run.py

clean:
	rm -rf out bench/out .pytest_cache
