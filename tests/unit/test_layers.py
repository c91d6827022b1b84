"""Which package may use which (docs/architecture.md, "The packages"): the robot program
(node/) does not use the harness (testbed/); the kernel layer (topology/) and the routing
daemon (aodv/) use neither; the shared helpers (common/) use none of the project. Below
package level: testbed/files, the testbed's own files, imports only common/ and named
constants; testbed/analysis nothing of testbed/run; and no module imports itself through
others. Checked on
the source of every module with ast, so an import inside a function counts as much as one at
the top, and so does a module named in a string for another process to run (`python -m
testbed...`, a fork server's module, import_module).
"""

import ast
import os
import re
import sys
from pathlib import Path

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

FORBIDDEN = {
    "node": {"testbed"},
    "topology": {"testbed", "node"},
    "aodv": {"testbed", "node"},
    "common": {"testbed", "node", "topology", "aodv"},
}
# A string that names a module of a package: "testbed.world.rays", "node.__main__".
MODULE_STRING = re.compile(r"(testbed|node|topology|aodv|common)(\.\w+)+")
PACKAGE_NAMES = {"testbed", "node", "topology", "aodv", "common"}


def modules(package: str) -> list[str]:
    out = []
    for root, dirs, files in os.walk(os.path.join(REPO, package)):
        dirs[:] = [d for d in dirs if d != "__pycache__"]
        out += [os.path.join(root, f) for f in files if f.endswith(".py")]
    return sorted(out)


def _docstrings(tree: ast.AST) -> set[int]:
    """ids of the docstring nodes: prose may name any module."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                out.add(id(body[0].value))
    return out


def used_packages(path: str, package: str) -> set[tuple[str, int, str]]:
    """(top-level package, line, what) for everything `path` imports or names as a module."""
    tree = ast.parse(open(path).read(), path)
    docs = _docstrings(tree)
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {(a.name.split(".")[0], node.lineno, a.name) for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: within the package itself
                found.add((package, node.lineno, "." * node.level + (node.module or "")))
            else:
                found.add((node.module.split(".")[0], node.lineno, node.module))
        elif isinstance(node, (ast.List, ast.Tuple)):  # argv: [..., "-m", "testbed.cli"]
            elts = node.elts
            for flag, arg in zip(elts, elts[1:], strict=False):
                if (
                    isinstance(flag, ast.Constant)
                    and flag.value == "-m"
                    and isinstance(arg, ast.Constant)
                    and isinstance(arg.value, str)
                    and arg.value.split(".")[0] in PACKAGE_NAMES
                ):
                    found.add((arg.value.split(".")[0], arg.lineno, f"-m {arg.value}"))
        elif (
            isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and id(node) not in docs
            and MODULE_STRING.fullmatch(node.value)
        ):
            found.add((node.value.split(".")[0], node.lineno, repr(node.value)))
    return found


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_package_uses_nothing_above_it(package):
    paths = modules(package)
    assert len(paths) >= 4, f"found only {paths} in {package}/"
    bad = [
        f"{os.path.relpath(p, REPO)}:{line}: {what}"
        for p in paths
        for top, line, what in sorted(used_packages(p, package))
        if top in FORBIDDEN[package]
    ]
    assert not bad, f"{package}/ must not use {sorted(FORBIDDEN[package])}:\n" + "\n".join(bad)


@pytest.mark.parametrize(
    "source, found",
    [
        ("import testbed.run.execute\n", "testbed"),
        ("def f():\n    from testbed.world import body\n", "testbed"),
        ("argv = [sys.executable, '-m', 'testbed.cli', 'net']\n", "testbed"),
        ("argv = ('python3', '-m', 'node')\n", "node"),
        ("importlib.import_module('testbed.world.rays')\n", "testbed"),
        ("warm = [['node.rays', 'warm', 1]]\n", "node"),
    ],
)
def test_the_check_sees_every_kind_of_use(tmp_path, source, found):
    p = tmp_path / "m.py"
    p.write_text(source)
    assert found in {top for top, _, _ in used_packages(str(p), "x")}


def test_prose_and_other_strings_are_not_uses(tmp_path):
    p = tmp_path / "m.py"
    p.write_text(
        '"""Started by testbed.run.execute; see node.rays."""\n'
        "def f():\n"
        '    """As testbed.world.bodylink does."""\n'
        'TABLE = "testbed"\n'
    )
    assert used_packages(str(p), "x") == set()


def test_no_code_cites_documents_users_do_not_have():
    """The design notes that are not shipped: code cites docs/ instead."""
    gone = ("DESIGN" + ".md", "STYLE" + ".md")
    cites = [
        f"{os.path.relpath(p, REPO)}: {name}"
        for package in ("common", "node", "topology", "aodv", "testbed", "tests")
        for p in modules(package)
        for name in gone
        if name in open(p).read()
    ]
    assert not cites, cites


# The layouts of netlink's own structures, as struct formats in the host's byte order,
# counts written out and L as I (both 4 bytes in standard sizes).
NETLINK_LAYOUTS = {
    "IHHII": "nlmsghdr",
    "BBBBBBBBI": "rtmsg",
    "BxHiII": "ifinfomsg",
    "BBH": "nfgenmsg",
    "HH": "rtattr",
}
STRUCT_CALLS = {"Struct", "pack", "pack_into", "unpack", "unpack_from", "calcsize", "iter_unpack"}
NETLINK_MODULE = os.path.join("topology", "kernel", "netlinkmsg.py")


def netlink_layout(fmt: str) -> str | None:
    """The netlink structure a struct format begins with, or None. Formats in network or
    big-endian order (packets, files) are never netlink's."""
    if fmt[:1] in "!>":
        return None
    fmt = fmt.lstrip("@=<").replace(" ", "")
    expanded = "".join(
        code * int(count or 1) for count, code in re.findall(r"(\d*)([a-zA-Z?])", fmt)
    )
    expanded = expanded.replace("L", "I").replace("l", "i")
    for layout, name in NETLINK_LAYOUTS.items():
        if expanded.startswith(layout):
            return name
    return None


def netlink_structs(path: str) -> set[tuple[int, str]]:
    """(line, structure) of every struct call in `path` whose format is a netlink layout."""
    found = set()
    for node in ast.walk(ast.parse(open(path).read(), path)):
        if not (isinstance(node, ast.Call) and node.args):
            continue
        func = node.func
        name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", None)
        fmt = node.args[0]
        if name in STRUCT_CALLS and isinstance(fmt, ast.Constant) and isinstance(fmt.value, str):
            layout = netlink_layout(fmt.value)
            if layout:
                found.add((node.lineno, layout))
    return found


def test_netlink_structures_are_packed_in_one_module():
    """nlmsghdr, rtmsg, ifinfomsg, nfgenmsg and rtattr are laid out in topology/kernel/netlinkmsg.py
    only: the AODV daemon, the oracle, route queries and the medium use its functions."""
    where = {
        os.path.relpath(p, REPO): netlink_structs(p)
        for package in ("common", "node", "topology", "aodv", "testbed")
        for p in modules(package)
    }
    assert {name for _, name in where[NETLINK_MODULE]} == set(NETLINK_LAYOUTS.values())
    bad = [
        f"{path}:{line}: {name}"
        for path, found in sorted(where.items())
        if path != NETLINK_MODULE
        for line, name in sorted(found)
    ]
    assert not bad, f"netlink structures packed outside {NETLINK_MODULE}:\n" + "\n".join(bad)


@pytest.mark.parametrize(
    "source, found",
    [
        ('H = struct.Struct("=LHHLL")\n', "nlmsghdr"),
        ('struct.unpack_from("=IHHIIi", data, 0)\n', "nlmsghdr"),
        ('from struct import pack\npack("BBBBBBBBI", 2, 32, 0, 0, 254, 0, 0, 1, 0)\n', "rtmsg"),
        ('struct.pack("=8BI", 2, 32, 0, 0, 254, 0, 0, 1, 0)\n', "rtmsg"),
        ('_NLA = struct.Struct("=HH")\n', "rtattr"),
        ('struct.pack_into("<BxHiII", buf, 16, 7, 0, 1, 0, 0)\n', "ifinfomsg"),
    ],
)
def test_the_netlink_check_sees_every_spelling(tmp_path, source, found):
    p = tmp_path / "m.py"
    p.write_text(source)
    assert {name for _, name in netlink_structs(str(p))} == {found}


def test_packet_and_file_formats_are_not_netlink(tmp_path):
    p = tmp_path / "m.py"
    p.write_text('struct.unpack("!HHH", udp)\nstruct.pack(">II", w, h)\nstruct.pack("=I", 10)\n')
    assert netlink_structs(str(p)) == set()


def test_the_harness_is_in_named_parts():
    """testbed/ holds the command line (`testbed`, `python -m testbed`) at its top; everything
    else is in a subpackage that says what it holds (files/, run/, sweep/, net/, analysis/,
    ...)."""
    top = sorted(f for f in os.listdir(os.path.join(REPO, "testbed")) if f.endswith(".py"))
    assert top == ["__init__.py", "__main__.py", "cli.py", "console.py"]
    for part in ("files", "run", "sweep", "net"):
        names = os.listdir(os.path.join(REPO, "testbed", part))
        prefixed = [n for n in names if n.startswith(part) and n.endswith(".py")]
        assert not prefixed, f"testbed/{part}/ repeats its name in {prefixed}"


def test_the_project_root_is_the_checkout():
    """Moving a module deeper once broke a root computed from its own path: one definition."""
    from testbed import PROJECT_ROOT
    from testbed.sweep.slurm import batch_script

    assert os.path.samefile(PROJECT_ROOT, REPO)
    assert os.path.isfile(os.path.join(PROJECT_ROOT, "pyproject.toml"))
    assert f"cd {PROJECT_ROOT} ||" in batch_script(Path("/out"), Path("/out/tasks"))
    roots = [
        p
        for package in ("common", "node", "topology", "aodv", "testbed")
        for p in modules(package)
        if re.search(r"dirname\(os\.path\.dirname\(|\.parents\[|\.parent\.parent\b", open(p).read())
    ]
    assert roots == [os.path.join(REPO, "common", "paths.py")], f"take common.paths: {roots}"


MODULE_LINES = 600  # the house's limit for a module
CLASS_LINES = 400  # and for a class: past it, it holds more than one job


def test_no_module_over_600_lines_and_no_class_over_400():
    """The house's size rules (docs/architecture.md): a module that grows past them is split
    by job, as pcapmetrics.py, the AODV core and daemon, Network, Sweep and Robot were."""
    too_long = []
    for package in ("common", "node", "topology", "aodv", "testbed"):
        for path in modules(package):
            source = open(path).read()
            rel = os.path.relpath(path, REPO)
            if source.count("\n") > MODULE_LINES:
                too_long.append(f"{rel}: {source.count(chr(10))} lines")
            for node in ast.walk(ast.parse(source)):
                if isinstance(node, ast.ClassDef):
                    n = (node.end_lineno or node.lineno) - node.lineno + 1
                    if n > CLASS_LINES:
                        too_long.append(f"{rel}: class {node.name} {n} lines")
    assert not too_long, "split by job: " + "; ".join(too_long)


# ---------------------------------------------------------------- below package level

PROJECT = ("common", "node", "topology", "aodv", "testbed")
# What testbed/files, the ground floor of testbed/ (docs/architecture.md), takes from the
# project beyond common/ and itself: named constants, and the robot's own declarations of
# the parameters a run option sets and of the rule joining --maps and --middleware
# (node.argsdecl: bounds, maps_refusal; a module that loads no planner, step core or numpy),
# and a position's check. Nothing that runs.
FILES_MAY_IMPORT = {
    "node.argsdecl": {"MAX_LASER_CELLS", "MAX_RANGE_M", "bounds", "maps_refusal"},
    "node.events": {"EVENTS_SUFFIX"},
    "node.timing": {"STEP_S"},
    "topology.names": {"MAX_ROBOTS"},
    "topology.spec": {
        "AODV_DAEMONS", "AODV_PROFILES", "CELL_M", "LOS_MODELS", "MAX_COORD_M", "MEDIA",
        "RANGE_MODELS", "ROUTINGS", "VETH", "WIFI_LOSSES", "WIFI_STANDARDS", "check_position",
    },
}  # fmt: skip
# Modules of the standard library and beyond that run things, serve or draw: never in files/.
FILES_NEVER = {"subprocess", "http", "socketserver", "cv2", "numpy", "matplotlib", "ctypes"}
# Circles known and allowed: none. A circle that must stay a while is named here (a frozenset
# of its modules), and the test fails when it goes without leaving the list.
KNOWN_CIRCLES: set[frozenset[str]] = set()


def module_name(path: str) -> str:
    rel = os.path.relpath(path, REPO)[: -len(".py")].replace(os.sep, ".")
    return rel.removesuffix(".__init__")


def imports(path: str) -> list[tuple[int, str, str | None]]:
    """(line, module, name imported from it or None) for every import in `path`, those inside
    functions and under TYPE_CHECKING included; relative imports made absolute."""
    name = module_name(path)
    package = name if path.endswith("__init__.py") else name.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(open(path).read(), path)):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name, None) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                module = ".".join(base + ([module] if module else []))
            out += [(node.lineno, module, a.name) for a in node.names]
    return out


def module_graph() -> dict[str, set[str]]:
    """Every project module and the project modules it imports (`from p import m` counts as
    importing the module p.m where there is one)."""
    paths = {module_name(p): p for package in PROJECT for p in modules(package)}
    graph: dict[str, set[str]] = {}
    for name, path in paths.items():
        edges = set()
        for _, module, imported in imports(path):
            for target in (f"{module}.{imported}", module):
                parts = target.split(".")
                found = next((".".join(parts[:i]) for i in range(len(parts), 0, -1)
                              if ".".join(parts[:i]) in paths), None)  # fmt: skip
                if found:
                    break
            if found and found != name:
                edges.add(found)
        graph[name] = edges
    return graph


def circles(graph: dict[str, set[str]]) -> list[frozenset[str]]:
    """The strongly connected parts of more than one module (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            w = next(children, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph.get(w, ())))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                part = set()
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    part.add(w)
                    if w == v:
                        break
                if len(part) > 1:
                    out.append(frozenset(part))
    return out


def test_no_import_circles():
    """No module imports itself through others: not at the top, not inside a function and not
    under TYPE_CHECKING (each of those only hid a circle: resultfile -> resultcheck ->
    resultconfig -> config -> isolation -> resultfile; figures -> middlewares -> verdicts ->
    figures; execute <-> steploop)."""
    found = set(circles(module_graph()))
    new = [sorted(c) for c in found - KNOWN_CIRCLES]
    assert not new, f"import circles: {new}"
    gone = [sorted(c) for c in KNOWN_CIRCLES - found]
    assert not gone, f"no longer circles, take them off KNOWN_CIRCLES: {gone}"


@pytest.mark.parametrize(
    "graph, found",
    [
        ({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}, [{"a", "b", "c"}]),
        ({"a": {"b"}, "b": set(), "c": {"b"}}, []),
        ({"a": {"b"}, "b": {"a"}, "c": {"d"}, "d": {"c"}}, [{"a", "b"}, {"c", "d"}]),
    ],
)
def test_the_circle_check_finds_circles(graph, found):
    assert sorted(map(sorted, circles(graph))) == sorted(map(sorted, found))


def test_the_graph_counts_imports_in_functions_and_type_checking(tmp_path, monkeypatch):
    pkg = tmp_path / "testbed" / "x"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("def f():\n    from testbed.x import b\n")
    (pkg / "b.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                              "    from .a import f\n")  # fmt: skip
    monkeypatch.setattr(sys.modules[__name__], "REPO", str(tmp_path))
    monkeypatch.setattr(sys.modules[__name__], "PROJECT", ("testbed",))
    assert circles(module_graph()) == [frozenset({"testbed.x.a", "testbed.x.b"})]


def files_may_import(module: str, name: str | None) -> bool:
    """Whether a module of testbed/files may import `name` from `module` (None: `import
    module`)."""
    top = module.split(".")[0]
    if top in FILES_NEVER:
        return False
    if top not in PROJECT or top == "common":
        return True
    if module == "testbed.files" or module.startswith("testbed.files."):
        return True
    return name in FILES_MAY_IMPORT.get(module, ())


@pytest.mark.parametrize(
    "module, name, ok",
    [
        ("common.boundedfile", "read", True),
        ("testbed.files.resultvalues", "one_line", True),
        ("topology.spec", "CELL_M", True),
        ("topology.spec", "NetworkSpec", False),
        ("testbed.run", "robotchoice", False),
        ("testbed.world.worldmap", "START_PLACEMENTS", False),
        ("subprocess", None, False),
        ("cv2", None, False),
        ("json", None, True),
    ],
)
def test_the_files_check_knows_the_floor(module, name, ok):
    assert files_may_import(module, name) is ok


def test_files_import_only_common_and_named_constants():
    """testbed/files, the testbed's own files and option table, is the ground floor of
    testbed/: it imports common/, itself and the names FILES_MAY_IMPORT lists, and nothing
    that serves, draws or starts processes."""
    paths = modules(os.path.join("testbed", "files"))
    assert len(paths) >= 10, paths
    bad = [
        f"{os.path.relpath(path, REPO)}:{line}: {module}" + (f".{name}" if name else "")
        for path in paths
        for line, module, name in imports(path)
        if not files_may_import(module, name)
    ]
    assert not bad, "testbed/files imports beyond its floor:\n" + "\n".join(bad)


def test_analysis_reads_runs_through_files_only():
    """testbed/analysis reads what runs wrote through testbed/files' types: nothing of
    testbed/run (which runs a testbed)."""
    bad = [
        f"{os.path.relpath(p, REPO)}:{line}: {module}"
        for p in modules(os.path.join("testbed", "analysis"))
        for line, module, name in imports(p)
        if module == "testbed.run"
        or module.startswith("testbed.run.")
        or (module == "testbed" and name == "run")
    ]
    assert not bad, "testbed/analysis uses testbed/run:\n" + "\n".join(bad)
