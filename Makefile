# Two commands for users: `make demo` and `make test`. Both do the whole set-up when needed.
VENV   := .venv
VPY    := $(VENV)/bin/python
STAMP  := $(VENV)/.setup-stamp
OUT    ?= out

.PHONY: setup demo test test-fast bench clean pyvista mutate

setup: $(STAMP)

$(STAMP): pyproject.toml scripts/setup.sh
	bash scripts/setup.sh
	touch $@

demo: $(STAMP)
	$(VPY) -m fem_blocks.cli demo default --out $(OUT)/demo

test: $(STAMP)
	$(VPY) -m pytest -q -p no:cacheprovider tests

# optional: pyvista/VTK renderer for the 3D PNGs (about 700 MB in the venv; numpy kept at the Debian version)
pyvista: $(STAMP)
	$(VPY) -m pip install -q -c constraints.txt pyvista

bench: $(STAMP)
	$(VPY) bench/run_all.py

# deliberate-bug run (docs/testing.md): one-line mutations, each with a fresh numba cache; slow, not in CI
mutate: $(STAMP)
	$(VPY) scripts/mutate.py

clean:
	rm -rf $(OUT) .pytest_cache
