# Two commands for users: `make demo` and `make test`. Both do the whole set-up when needed.
VENV   := .venv
VPY    := $(VENV)/bin/python
STAMP  := $(VENV)/.setup-stamp
OUT    ?= out

.PHONY: setup demo test test-fast bench clean pyvista

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

clean:
	rm -rf $(OUT) .pytest_cache
