"""The compiled AODV daemon's shared numbers and command line, written from the Python
daemon: `python -m aodv.constgen HEADER`; and the protocol core's parameter table:
`python -m aodv.constgen --params HEADER` (build/gen/aodv_params.h: aodv.params.Params'
fields with their defaults and the profiles, which native/aodv/params.h builds on).

`make` runs it before it compiles build/tb-aodv (native/aodv/daemon/): HEADER
(build/gen/aodv_consts.h) holds what the two daemons must agree on, each read here from the
one Python place that defines it, so that a change there reaches the compiled daemon at its
next build instead of drifting:

- the kernel side: RTPROT_AODV, the TUN device's and the nftables table's names, the UDP
  port, IP_RECVTTL, the pending-request bound of rtnetlink (the route-use poll's nftables
  ruleset, aodv.kernel.UseMonitor's text, tb-aodv sends as the netlink messages nft makes of
  it; tests/integration/test_aodv_cpp_daemon.py holds the two tables equal);
- the loop and its files: STATS_PERIOD, HOSTS_REMEMBERED, the timer-lateness histogram's
  bounds and how many late firings are kept (aodv.stats), the counter file's block
  (aodv.persist), the deadline priority (common.sched);
- the command line: every option of aodv.__main__'s parser in order (flags, default,
  choices, whether it is required or a switch) and every field of aodv.params.Params that
  `--set` takes, with its type and the profiles' names; the digits and blanks Python's int()
  and float() take beyond ASCII.

tests/unit/test_aodv_cpp_cli.py holds the binary's answers to the same command lines equal
to the Python daemon's. The file is rewritten only when its text changes, so that make
rebuilds tb-aodv only then.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import unicodedata
from pathlib import Path

from aodv import __main__ as cli
from aodv import daemon, kernel, persist, stats
from aodv.control import IP_RECVTTL
from aodv.packet import AODV_PORT
from aodv.params import MAX_TTL, PROFILES, Params
from common.cliterals import c_real, c_string, write_header
from common.sched import DEADLINE_PRIORITY


def parser() -> argparse.ArgumentParser:
    """aodv.__main__'s parser, as parse_args builds it (caught before it parses)."""
    caught: list[argparse.ArgumentParser] = []

    def catch(self, args=None, namespace=None):
        caught.append(self)
        return argparse.Namespace()

    original = cli._Parser.parse_args
    cli._Parser.parse_args = catch  # type: ignore[method-assign]
    try:
        cli.parse_args([])
    finally:
        cli._Parser.parse_args = original  # type: ignore[method-assign]
    return caught[0]


def option_rows(p: argparse.ArgumentParser) -> list[str]:
    """One Option a line: flag, dest, kind, default, choices, required."""
    rows = []
    for a in p._actions:
        if isinstance(a, argparse._HelpAction):
            kind = "Help"
        elif isinstance(a, argparse._StoreTrueAction):
            kind = "Switch"
        elif isinstance(a, argparse._AppendAction):
            kind = "Append"
        else:
            kind = "Value"
        flag = max(a.option_strings, key=len)
        default = a.default if isinstance(a.default, str) and kind != "Help" else None
        if kind == "Value" and a.default is not None and default is None:
            default = repr(a.default)  # a number: its repr, as the C++ side parses it
        choices = list(a.choices or ())
        rows.append(
            f"    {{{c_string(flag)}, {c_string(a.dest)}, OptKind::{kind}, "
            f"{c_string(default) if default is not None else 'nullptr'}, "
            f"{{{', '.join(c_string(c) for c in choices) or 'nullptr'}}}, {len(choices)}, "
            f"{'true' if a.required else 'false'}}},"
        )
    return rows


def param_rows() -> list[str]:
    """One Param a line: the field's name and type (Bool, Int, Real, OptReal)."""
    rows = []
    for f in dataclasses.fields(Params):
        kind = str(f.type)
        if f.name == "time_scale":
            continue  # not for --set (aodv.__main__.build_params)
        if "bool" in kind:
            k = "Bool"
        elif "float" in kind:
            k = "OptReal" if "None" in kind else "Real"
        else:
            k = "Int"
        rows.append(f"    {{{c_string(f.name)}, ParamKind::{k}}},")
    return rows


def unicode_rows() -> list[str]:
    """What Python's int() and float() read as digits and blanks beyond ASCII: the first code
    point of every run of ten decimal digits (category Nd), and every str.isspace() one."""
    digits = [chr(c) for c in range(0x110000) if unicodedata.category(chr(c)) == "Nd"]
    zeros = [ord(d) for d in digits if unicodedata.digit(d) == 0]
    spaces = [c for c in range(0x110000) if chr(c).isspace()]
    return [
        f"constexpr unsigned DIGIT_ZEROS[] = {{{', '.join(hex(c) for c in zeros)}}};",
        f"constexpr unsigned SPACES[] = {{{', '.join(hex(c) for c in spaces)}}};",
    ]


def header() -> str:
    lines = [
        "// Written by `python -m aodv.constgen` from the Python daemon: do not edit.",
        "#pragma once",
        "",
        "namespace aodv::gen {",
        f"constexpr int RTPROT_AODV = {kernel.RTPROT_AODV};",
        f"constexpr const char* TUN_NAME = {c_string(kernel.TUN_NAME)};",
        f"constexpr const char* NFT_TABLE = {c_string(kernel.NFT_TABLE)};",
        f"constexpr int AODV_PORT = {AODV_PORT};",
        f"constexpr int RECVTTL_OPTION = {IP_RECVTTL};",
        f"constexpr int PENDING_MAX = {kernel.KernelRoutes.PENDING_MAX};",
        f"constexpr double STATS_PERIOD = {float(stats.STATS_PERIOD)!r};",
        f"constexpr int HOSTS_REMEMBERED = {daemon.HOSTS_REMEMBERED};",
        f"constexpr int TIMER_BOUNDS_MS[] = {{{', '.join(map(str, stats.TIMER_BOUNDS_MS))}}};",
        f"constexpr int WORST_KEPT = {stats.WORST_KEPT};",
        f"constexpr int COUNTER_BLOCK = {persist.CounterStore.block};",
        f"constexpr int DEADLINE_RT_PRIORITY = {DEADLINE_PRIORITY[0]};",
        f"constexpr int DEADLINE_NICE = {DEADLINE_PRIORITY[1]};",
        f"constexpr const char* PROFILES[] = {{{', '.join(c_string(p) for p in PROFILES)}}};",
        f"constexpr int N_PROFILES = {len(PROFILES)};",
        *unicode_rows(),
        "",
        "enum class OptKind { Help, Switch, Append, Value };",
        "struct Option {",
        "    const char* flag;",
        "    const char* dest;",
        "    OptKind kind;",
        "    const char* fallback;  // the default (nullptr: None)",
        "    const char* choices[8];",
        "    int n_choices;",
        "    bool required;",
        "};",
        "constexpr Option OPTIONS[] = {",
        *option_rows(parser()),
        "};",
        "",
        "enum class ParamKind { Bool, Int, Real, OptReal };",
        "struct ParamField {",
        "    const char* name;",
        "    ParamKind kind;",
        "};",
        "constexpr ParamField PARAMS[] = {",
        *param_rows(),
        "};",
        "}  // namespace aodv::gen",
        "",
    ]
    return "\n".join(lines)


def _c_value(f: dataclasses.Field, value) -> str:
    """A Params field's value as C++ (its type read from the dataclass field)."""
    kind = str(f.type)
    if value is None:
        return "std::nullopt"
    if "bool" in kind:
        return "true" if value else "false"
    if "float" in kind:
        return c_real(value)
    return str(int(value))


def _c_type(f: dataclasses.Field) -> str:
    kind = str(f.type)
    if "None" in kind:
        return "std::optional<double>"
    if "bool" in kind:
        return "bool"
    return "double" if "float" in kind else "long long"


def params_header() -> str:
    """The protocol's parameter table for the compiled core (native/aodv/params.h): every input
    of aodv.params.Params with its default, and each profile's overrides, from the one
    Python place that defines them."""
    fields = {f.name: f for f in dataclasses.fields(Params)}
    lines = [
        "// Written by `python -m aodv.constgen --params` from aodv/params.py: do not edit.",
        "#pragma once",
        "",
        "#include <optional>",
        "#include <string>",
        "",
        "namespace aodv::gen {",
        f"constexpr int MAX_TTL = {MAX_TTL};",
        "",
        "// RFC 3561 section 10's inputs and the bounds beyond it (aodv.params.Params' fields).",
        "struct ParamInputs {",
        *(f"    {_c_type(f)} {f.name} = {_c_value(f, f.default)};" for f in fields.values()),
        "};",
        "",
        "// aodv.params.PROFILES: a profile's overrides of the defaults; false for another name.",
        "inline bool apply_profile(const std::string& name, ParamInputs& p) {",
    ]
    for name, overrides in PROFILES.items():
        lines.append(f"    if (name == {c_string(name)}) {{")
        lines += [f"        p.{k} = {_c_value(fields[k], v)};" for k, v in overrides.items()]
        lines += ["        return true;", "    }"]
    lines += ["    return false;", "}", "}  // namespace aodv::gen", ""]
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    if len(argv) == 2 and argv[0] == "--params":
        make = params_header
    elif len(argv) == 1 and not argv[0].startswith("-"):
        make = header
    else:
        print("usage: python -m aodv.constgen [--params] HEADER", file=sys.stderr)
        return 2
    path = Path(argv[-1])
    text = make()
    write_header(path, text)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
