"""Each constant declared once (issue 41, item 2): the cell size, the veth medium, the time
scale's default and bounds, the middleware registry and a few named constants have one
definition, imported everywhere else. Found in the packages' source with ast, so pasting the
literal again somewhere fails here with the file and line."""

import ast
import os
from pathlib import Path

from testbed import PROJECT_ROOT

PACKAGES = ("common", "node", "topology", "aodv", "testbed")
ROOT = Path(PROJECT_ROOT)
CELL_HOME = "topology/spec.py"  # CELL_M, VETH
REGISTRY_HOME = "node/messaging/__init__.py"
# Module-level names that one module defines (others import them).
DEFINED_ONCE = ("CELL_M", "VETH", "MEDIA", "DAEMON_AGREEMENT", "LAG_FILE", "LAG_NAME",
                "EXIT_USAGE", "EXIT_FAILURE", "PROJECT_ROOT", "REPO", "MIDDLEWARES",
                "PROTOCOL_ORDER")  # fmt: skip
# Words that make a 0.05 a cell size where it stands (its statement, or a parameter's name).
CELL_WORDS = ("cell", "map", "png", "pixel")


def sources() -> dict[str, ast.Module]:
    out = {}
    for package in PACKAGES:
        for root, dirs, files in os.walk(ROOT / package):
            dirs[:] = [d for d in dirs if d != "__pycache__"]
            for f in files:
                if f.endswith(".py"):
                    path = Path(root, f)
                    rel = str(path.relative_to(ROOT))
                    out[rel] = ast.parse(path.read_text(), rel)
    return out


SOURCES = sources()


def _where(rel: str, node: ast.AST) -> str:
    return f"{rel}:{node.lineno}"


def _is_cell(node: ast.AST) -> bool:
    return isinstance(node, ast.Constant) and type(node.value) is float and node.value == 0.05


def test_the_cell_size_is_declared_once():
    found = []
    for rel, tree in SOURCES.items():
        lines = None
        parent: dict[int, ast.AST] = {}
        for node in ast.walk(tree):
            for child in ast.iter_child_nodes(node):
                parent[id(child)] = node
            if isinstance(node, ast.arguments):  # a parameter named for a cell, e.g. cell=0.05
                args = node.posonlyargs + node.args
                pairs = list(
                    zip(args[len(args) - len(node.defaults) :], node.defaults, strict=True)
                )
                pairs += list(zip(node.kwonlyargs, node.kw_defaults, strict=True))
                for a, d in pairs:
                    if _is_cell(d) and any(w in a.arg.lower() for w in CELL_WORDS):
                        found.append(_where(rel, d))
        for node in ast.walk(tree):
            if not _is_cell(node):
                continue
            stmt = node
            while not isinstance(stmt, ast.stmt):
                stmt = parent[id(stmt)]
            if lines is None:
                lines = (ROOT / rel).read_text().splitlines()
            # The statement's own lines (a compound statement's first line only).
            last = stmt.end_lineno if not hasattr(stmt, "body") else stmt.lineno
            segment = "\n".join(lines[stmt.lineno - 1 : last]).split("#")[0].lower()
            if any(w in segment for w in CELL_WORDS):
                found.append(_where(rel, node))
    home = f"{CELL_HOME}:{_line(CELL_HOME, 'CELL_M = 0.05')}"
    found = sorted(set(found) - {home})
    assert not found, f"a cell size of 0.05 written again: use topology.spec.CELL_M ({found})"


def _line(rel: str, text: str) -> int:
    lines = (ROOT / rel).read_text().splitlines()
    return next((i for i, line in enumerate(lines, 1) if line.startswith(text)), 0)


def test_the_veth_medium_is_named_once():
    found = []
    for rel, tree in SOURCES.items():
        kinds = set()  # `kind="veth"`: the kernel's link type, not the medium
        for node in ast.walk(tree):
            if isinstance(node, ast.keyword) and node.arg == "kind":
                kinds.add(id(node.value))
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and node.value == "veth" and id(node) not in kinds:
                found.append(_where(rel, node))
    home = f"{CELL_HOME}:{_line(CELL_HOME, 'VETH, NS3_WIFI = ')}"
    assert found == [home], f'"veth" written again: use topology.spec.VETH ({found})'


def test_every_robot_option_takes_its_default_and_bounds_from_the_robot():
    """The run options that a robot parameter sets (node.launch: run=True), time_scale among
    them, are declared `option(kind, help, **robot(name), ...)` or `robot(name)["default"]`:
    no default or bound of their own."""
    from node.launch import run_params

    tree = SOURCES["testbed/files/runconfig.py"]
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "RunConfig")
    fields = {s.target.id: s.value for s in cls.body
              if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name)}  # fmt: skip
    assert "time_scale" in run_params()
    for name in run_params():
        value = fields[name]
        calls = [n for n in ast.walk(value) if isinstance(n, ast.Call)]
        robot = [c for c in calls if isinstance(c.func, ast.Name) and c.func.id == "robot"]
        assert robot and all(ast.literal_eval(c.args[0]) == name for c in robot), name
        if isinstance(value, ast.Call) and getattr(value.func, "id", "") == "option":
            assert len(value.args) == 2, f"RunConfig.{name}: a default of its own"
            own = {k.arg for k in value.keywords} & {"above", "minimum", "choices", "default"}
            assert not own, f"RunConfig.{name}: {own} of its own, not node.launch's"


def test_the_middlewares_are_listed_in_one_table():
    from node.messaging import MIDDLEWARES

    names = set(MIDDLEWARES)
    found = []
    for rel, tree in SOURCES.items():
        if rel == REGISTRY_HOME:
            continue
        for node in ast.walk(tree):
            if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
                items = node.elts
            elif isinstance(node, ast.Dict):
                items = [k for k in node.keys if k is not None]
            else:
                continue
            listed = {i.value for i in items if isinstance(i, ast.Constant)} & names
            if len(listed) >= 2:
                found.append(f"{_where(rel, node)} {sorted(listed)}")
    assert not found, f"middlewares listed outside node.messaging's REGISTRY: {found}"


def test_named_constants_are_defined_in_one_module():
    defined: dict[str, list[str]] = {}
    for rel, tree in SOURCES.items():
        for stmt in tree.body:
            targets = []
            if isinstance(stmt, ast.Assign):
                for t in stmt.targets:
                    targets += [t, *getattr(t, "elts", [])]
            elif isinstance(stmt, ast.AnnAssign):
                targets = [stmt.target]
            for t in targets:
                if isinstance(t, ast.Name) and t.id in DEFINED_ONCE:
                    defined.setdefault(t.id, []).append(_where(rel, stmt))
    again = {name: where for name, where in defined.items() if len(where) > 1}
    assert not again, f"defined in more than one module (import it instead): {again}"
    assert "REPO" not in defined and "PROTOCOL_ORDER" not in defined and "LAG_NAME" not in defined
    lag = [rel for rel, tree in SOURCES.items() for n in ast.walk(tree)
           if isinstance(n, ast.Constant) and n.value == "relay-lag.bin"]  # fmt: skip
    assert lag == ["topology/names.py"]
