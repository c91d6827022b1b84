# The two commands for users: `sudo make experiment` and `sudo make test`.
# Both install what they need first (make setup), idempotently.

SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

# Debian packages the testbed drives. python3-venv: to build .venv on a stock Debian.
APT_PACKAGES := iproute2 nftables tcpdump tshark babeld batmand nanomsg-utils iputils-ping \
	iperf3 procps python3-venv g++ libns3-dev
# `make vm-test` (netem under Debian's stock kernel) installs its own: tests/vm/run-netem-tests.

# The ns3-wifi radio medium (medium/ns3, docs/ns3-medium.md): one binary, rebuilt when its
# source changes. Debian's pkg-config file for ns-3 is broken: the libraries are named here.
NS3_MEDIUM := build/tb-ns3-wifi
NS3_LIBS := -lns3-wifi -lns3-fd-net-device -lns3-mobility -lns3-propagation -lns3-network \
	-lns3-core -lpthread

NEED_ROOT = @[ "$$(id -u)" = 0 ] || { echo "make $@ needs root (network namespaces): run 'sudo make $@'"; exit 2; }

.PHONY: setup apt venv test unit integration experiment experiment-short experiment-ablation \
	experiment-protocols \
	experiment-paper-literal bench lint format vm-test slurm-test browser-test clean

setup: apt venv $(NS3_MEDIUM)

$(NS3_MEDIUM): medium/ns3/wifi-medium.cc | apt
	@[ -e /usr/include/ns3/wifi-module.h ] || { echo "the ns3-wifi medium needs Debian's libns3-dev: run 'sudo make setup'"; exit 2; }
	@mkdir -p $(@D)
	g++ -std=c++17 -O2 -Wall -o $@ $< $(NS3_LIBS)

apt:
	@missing=$$(for p in $(APT_PACKAGES); do \
		dpkg-query -W -f='$${Status}\n' $$p 2>/dev/null | grep -q 'ok installed' || echo $$p; done); \
	if [ -n "$$missing" ]; then \
		[ "$$(id -u)" = 0 ] || { echo "missing Debian packages ($$missing): run 'sudo make setup'"; exit 2; }; \
		echo "installing Debian packages: $$missing"; \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing >/dev/null; \
	fi

venv: $(STAMP)

$(STAMP): pyproject.toml constraints.txt
	@[ -x $(PY) ] || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --disable-pip-version-check -c constraints.txt -e '.[dev]'
	@touch $(STAMP)

test: setup
	$(NEED_ROOT)
	@$(VENV)/bin/testbed clean   # leftovers of an earlier run that was killed, and only those
	$(PY) -m pytest -q tests/unit tests/integration

unit: venv
	$(PY) -m pytest -q tests/unit

integration: setup
	$(NEED_ROOT)
	$(PY) -m pytest -q tests/integration

experiment: setup
	$(NEED_ROOT)
	$(VENV)/bin/testbed sweep testbed/experiments/paper.toml --out results/paper --resume
	$(VENV)/bin/testbed report results/paper

experiment-short: setup
	$(NEED_ROOT)
	$(VENV)/bin/testbed sweep testbed/experiments/short.toml --out results/short --resume
	$(VENV)/bin/testbed report results/short

# Issue 11: coordination x start placement (600 runs, about two hours here).
experiment-protocols: setup
	$(NEED_ROOT)
	$(VENV)/bin/testbed sweep testbed/experiments/protocols.toml --out results/protocols --resume
	$(VENV)/bin/testbed report results/protocols

experiment-ablation: setup
	$(NEED_ROOT)
	$(VENV)/bin/testbed sweep testbed/experiments/ablation.toml --out results/ablation --resume
	$(VENV)/bin/testbed report results/ablation

# The paper's grid under the paper's coordination read literally (240 runs, about an hour).
experiment-paper-literal: setup
	$(NEED_ROOT)
	$(VENV)/bin/testbed sweep testbed/experiments/paper-literal.toml --out results/paper-literal --resume
	$(VENV)/bin/testbed report results/paper-literal

bench: setup
	$(NEED_ROOT)
	$(PY) -m testbed.bench

# $(call test_packages,PACKAGES,AFTER): install those of the Debian PACKAGES a test target
# needs that are missing (no recommends), then run the shell command AFTER (may be empty).
define test_packages
	@missing=$$(for p in $(1); do \
		dpkg-query -W -f='$${Status}\n' $$p 2>/dev/null | grep -q 'ok installed' || echo $$p; done); \
	if [ -n "$$missing" ]; then \
		apt-get update -qq && \
		DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends $$missing && \
		{ true; $(2) }; \
	fi
endef

# A one-node Slurm cluster on this machine, all its state in a temporary directory, for the
# --slurm sweep tests (tests/slurm). Debian's packages enable their services on install;
# they are disabled again here: the tests start their own daemons and stop them by pid.
SLURM_PACKAGES := slurm-wlm munge

slurm-test: setup
	$(NEED_ROOT)
	$(call test_packages,$(SLURM_PACKAGES),if command -v systemctl >/dev/null; then \
		systemctl disable --now slurmctld slurmd munge >/dev/null 2>&1 || true; fi;)
	$(PY) -m pytest -q tests/slurm

# The live view in a real headless Chromium (tests/browser); Debian's chromium and
# chromium-driver are installed for this test only.
BROWSER_PACKAGES := chromium chromium-driver

browser-test: setup
	$(NEED_ROOT)
	$(call test_packages,$(BROWSER_PACKAGES),)
	$(PY) -m pytest -q tests/browser

lint: venv
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/ruff check .

format: venv
	$(VENV)/bin/ruff format .
	$(VENV)/bin/ruff check --fix .

vm-test: setup
	$(NEED_ROOT)
	bash tests/vm/run-netem-tests

clean:
	$(NEED_ROOT)
	$(VENV)/bin/testbed clean
