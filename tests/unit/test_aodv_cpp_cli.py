"""One command line, two AODV daemons: the same argument lists go to the Python daemon's
parser (aodv.__main__.parse_args, then build_params, which `python -m aodv` runs before it
does anything) and to build/tb-aodv, and both must take or refuse each alike. A list the
Python daemon takes makes tb-aodv go on to its root check: run as nobody, it then says it
needs root (status 2), which tells "taken" from "refused" without starting a daemon in the
host's namespace; a list either refuses is one line, "tb-aodv: error: ...", status 2. And the
numbers the two daemons share (build/gen/aodv_consts.h, which tb-aodv is compiled with) are
the Python daemon's, written by aodv.constgen from the Python modules that define them.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import os
import re
import subprocess
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aodv import __main__ as cli
from aodv import constgen, daemon, kernel, persist, stats
from aodv.packet import AODV_PORT
from aodv.params import PROFILES, Params
from common.paths import PROJECT_ROOT
from common.sched import DEADLINE_PRIORITY

TB_AODV = Path(PROJECT_ROOT) / "build" / "tb-aodv"
CONSTS = Path(PROJECT_ROOT) / "build" / "gen" / "aodv_consts.h"
UNBUILT = TB_AODV.with_name("tb-aodv.unbuilt")
NEEDS_ROOT = "tb-aodv: error: needs root (CAP_NET_ADMIN) in the robot's namespace"


def _unbuilt() -> str | None:
    if TB_AODV.is_file():
        return None
    return UNBUILT.read_text().strip() if UNBUILT.is_file() else "build/tb-aodv not built"


needs_binary = pytest.mark.skipif(_unbuilt() is not None, reason=str(_unbuilt()))


def python_takes(argv: list[str]) -> bool | str:
    """True if the Python daemon takes argv, "help" for -h, else False."""
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            args = cli.parse_args(argv)
            cli.build_params(args)
    except SystemExit as e:
        return "help" if e.code == 0 else False
    except ValueError:
        return False
    return True


def cpp_takes(argv: list[str]) -> bool | str:
    """True if tb-aodv takes argv (it then stops at its root check), "help" for -h, else
    False; a refusal must be one line and status 2."""
    prefix = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"]
    proc = subprocess.run(
        (prefix if os.geteuid() == 0 else []) + [str(TB_AODV), *argv],
        capture_output=True,
        timeout=10,
        cwd="/",
    )
    err = proc.stderr.decode(errors="replace")
    if proc.returncode == 0:
        assert proc.stdout.startswith(b"usage: tb-aodv"), proc.stdout
        return "help"
    assert proc.returncode == 2, (argv, proc.returncode, err)
    assert err.count("\n") == 1 and err.startswith("tb-aodv: error: "), (argv, err)
    return err.strip() == NEEDS_ROOT


BASE = ["--robot", "r1"]
PARAM_FIELDS = [f for f in dataclasses.fields(Params) if f.name != "time_scale"]
NUMBERS = ["nan", "NaN", "inf", "-inf", "Infinity", "-0", "0", "", " ", "1e999", "1_000",
           "1__0", "_1", " 5", "5 ", "+5", "0x10", "0x1p3", "1e3", "1.5", "1.", ".5", "-.5e-3",
           "\uff15", "\u0663", "\u00a07\u2003", "5\x1c", "0005", "-", "e5", "1e", "9" * 400,
           "-1", "16", "15", "255", "256", "2", "1", "\udcff"]  # fmt: skip

CASES: list[list[str]] = [
    [],
    ["--robot"],
    BASE,
    ["--robot="],
    ["--robot=r1"],
    ["--rob", "r1"],
    ["--rob=r1", "--i=eth0"],
    ["--robot", "-x"],
    ["--robot", "--x y"],
    ["--robot", "-1"],
    ["--robot", "r1", "extra"],
    ["--robot", "r1", "-x"],
    ["--robot", "r1", "-"],
    ["--robot", "r1", "--"],
    [*BASE, "--s", "x"],
    [*BASE, "--st", "x"],
    [*BASE, "--sta", "/tmp/x"],
    [*BASE, "--stats", "/tmp/x", "--state", "/tmp/y"],
    [*BASE, "--unknown"],
    [*BASE, "--no-local-repair"],
    [*BASE, "--no-local-repair=1"],
    [*BASE, "--no"],
    [*BASE, "-h"],
    [*BASE, "--help"],
    [*BASE, "--he"],
    [*BASE, "--help=x"],
    [*BASE, "--profile", "ns3"],
    [*BASE, "--profile", "rfc"],
    [*BASE, "--profile", "RFC"],
    [*BASE, "--profile", ""],
    [*BASE, "--log-level", "debug"],
    [*BASE, "--log-level", "warn"],
    [*BASE, "--log-level"],
    [*BASE, "--iface", "wlan0", "--iface", "eth0"],
    *(
        [*BASE, "--netns", n]
        for n in ["tb-x-r1", "", ".", "..", "a/b", "/run/netns/x", "...", "-x", "x y", "r\u00e9"]
    ),
    ["--netns=tb-x-r1", *BASE],
    [*BASE, "--netns"],
    [*BASE, "--netn", "x"],
    [*BASE, "--net", "10.0.0.0/16", "--netns", "x"],
    [*BASE, "--ne", "x"],
    *(
        [*BASE, "--net", n]
        for n in [
            "10.0.0.0/16",
            "10.0.0.1/16",
            "10.0.0.0",
            "10.0.0.0/8",
            "10.0.0.0/255.255.0.0",
            "10.0.0.0/0.0.255.255",
            "10.0.0.0/255.0.255.0",
            "10.0.0.0/33",
            "10.0.0.0/016",
            "010.0.0.0/16",
            "10.0.0/16",
            "10.0.0.0.0/16",
            "::1/128",
            "10.0.0.0/16/1",
            "0.0.0.0/0",
            "256.0.0.0/8",
            "10.0.0.0/",
            " 10.0.0.0/16",
            "10.0.0.0/-1",
            "10.0.0.0/+8",
        ]
    ),  # fmt: skip
    *([*BASE, "--time-scale", n] for n in NUMBERS),
    *([*BASE, f"--time-scale={n}"] for n in ["-1", "-inf", "1e-300", "0.0"]),
    *([*BASE, "--stats-period", n] for n in NUMBERS),
    *([*BASE, f"--stats-period={n}"] for n in ["-0.0", "-1e-300", "0", "1e308"]),
    [*BASE, "--set"],
    [*BASE, "--set", "x"],
    [*BASE, "--set", "time_scale=2"],
    [*BASE, "--set", "=1"],
    [*BASE, "--set", "local_repair=1"],
    [*BASE, "--set", "local_repair=false", "--set", "dest_only=true"],
    [*BASE, "--set", "ttl_start=3", "--set", "ttl_start=9"],
    [*BASE, "--set", "my_route_timeout_ms=100"],
    [*BASE, "--set", "my_route_timeout_ms=11200"],
    [*BASE, "--set", "my_route_timeout_ms=nan"],
    [*BASE, "--set", "hello_interval_ms=10000"],
    [*BASE, "--set", "allowed_hello_loss=99999999999999999999"],
    [*BASE, "--profile", "ns3", "--set", "ttl_start=1"],
    *(
        [*BASE, "--set", f"{f.name}={v}"]
        for f in PARAM_FIELDS
        for v in [
            "true",
            "false",
            "1",
            "0",
            "-1",
            "16",
            "15",
            "1.5",
            "1e3",
            "nan",
            "",
            "x",
            "99999999999999999999999",
        ]
    ),  # fmt: skip
    *(
        [*BASE, "--set", f"ttl_threshold={v}", "--set", f"net_diameter={v}"]
        for v in ["255", "256", "\u0662\u0665\u0665"]
    ),  # fmt: skip
]


@needs_binary
@pytest.mark.parametrize("argv", CASES, ids=lambda a: " ".join(a)[:60] or "(none)")
def test_same_command_lines_taken(argv):
    assert cpp_takes(argv) == python_takes(argv), argv


_ARG = st.one_of(
    st.sampled_from(["--robot", "r1", "--time-scale", "--net", "--set", "--profile", "ns3",
                     "--stats", "--stats-period", "--state", "--no-local-repair", "--log-level",
                     "info", "--iface", "--ro", "--t", "--n", "-1", "2", "10.0.0.0/16",
                     "--netns", "--netn", "..",
                     "ttl_start=3", "--", "-"]),
    st.text(alphabet="-=_.0123456789abcdefinrst/ ", max_size=12),
)  # fmt: skip


@needs_binary
@settings(max_examples=150, deadline=None)
@given(st.lists(_ARG, max_size=7))
def test_random_command_lines_taken_alike(argv):
    assert cpp_takes(argv) == python_takes(argv), argv


@needs_binary
def test_help_lists_every_option():
    out = subprocess.run([str(TB_AODV), "--help"], capture_output=True, text=True, check=True)
    for flag in ("--robot", "--iface", "--time-scale", "--profile", "--no-local-repair", "--set",
                 "--stats", "--stats-period", "--state", "--log-level", "--net",
                 "--netns"):  # fmt: skip
        assert flag in out.stdout


@needs_binary
def test_shared_numbers_are_the_python_daemons():
    """The header tb-aodv is built from is what aodv.constgen writes now, and names the
    Python values (so a change to one of them reaches tb-aodv at its next make)."""
    text = CONSTS.read_text()
    assert text == constgen.header(), "build/gen/aodv_consts.h is stale: run make build/tb-aodv"
    assert CONSTS.stat().st_mtime <= TB_AODV.stat().st_mtime, "tb-aodv older than its header"

    def value(name: str) -> str:
        m = re.search(rf"constexpr [^=]*\b{name}(\[\])? = (.*);", text)
        assert m, name
        return m.group(2)

    assert int(value("RTPROT_AODV")) == kernel.RTPROT_AODV == 101
    assert value("TUN_NAME") == f'"{kernel.TUN_NAME}"' == '"aodv0"'
    assert value("NFT_TABLE") == f'"{kernel.NFT_TABLE}"'
    assert int(value("AODV_PORT")) == AODV_PORT == 654
    assert float(value("STATS_PERIOD")) == stats.STATS_PERIOD
    assert int(value("HOSTS_REMEMBERED")) == daemon.HOSTS_REMEMBERED
    assert value("TIMER_BOUNDS_MS") == "{" + ", ".join(map(str, stats.TIMER_BOUNDS_MS)) + "}"
    assert int(value("WORST_KEPT")) == stats.WORST_KEPT
    assert int(value("COUNTER_BLOCK")) == persist.CounterStore.block
    assert (int(value("DEADLINE_RT_PRIORITY")), int(value("DEADLINE_NICE"))) == DEADLINE_PRIORITY
    assert int(value("PENDING_MAX")) == kernel.KernelRoutes.PENDING_MAX
    names = re.findall(r'\{"(\w+)", ParamKind::', text)
    assert names == [f.name for f in PARAM_FIELDS]


def test_the_cores_parameter_table_is_aodv_params():
    """The protocol's parameters reach the compiled core from aodv/params.py alone: the header
    it is built from is what aodv.constgen writes now, with every field's default and every
    profile's overrides as Python has them."""
    path = CONSTS.parent / "aodv_params.h"
    if not path.is_file():
        pytest.skip("build/gen/aodv_params.h not made (make setup makes it with the core)")
    text = path.read_text()
    assert text == constgen.params_header(), "aodv_params.h is stale: run make build/tb-aodv-core"
    fields = {f.name: f for f in dataclasses.fields(Params)}
    for f in fields.values():
        assert f"{f.name} = {constgen._c_value(f, f.default)};" in text, f.name
    assert "p.my_route_timeout_ms = 11200.0;" in text  # the ns3 profile, as a reader sees it
    for name, overrides in PROFILES.items():
        block = text.split(f'if (name == "{name}") {{')[1].split("return true;")[0]
        for k, v in overrides.items():
            assert f"p.{k} = {constgen._c_value(fields[k], v)};" in block, (name, k)
