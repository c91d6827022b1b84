"""The shape of a run's code: execute.py's and steploop.py's classes set their attributes in
`__init__` only (what changes during a run lives in the clock, the records and the files),
and the run's modules stay small (no function over 80 lines, no module over 600)."""

import ast
from pathlib import Path

import pytest

RUN = Path(__file__).resolve().parents[2] / "testbed" / "run"
RUN_MODULES = sorted(p.name for p in RUN.glob("*.py"))


def _targets(node: ast.AST):
    """Every expression a statement under `node` assigns to."""
    for n in ast.walk(node):
        if isinstance(n, ast.Assign):
            for t in n.targets:
                yield from ast.walk(t) if isinstance(t, ast.Tuple | ast.List) else [t]
        elif isinstance(n, ast.AugAssign | ast.AnnAssign | ast.NamedExpr):
            yield n.target
        elif isinstance(n, ast.withitem) and n.optional_vars is not None:
            yield from ast.walk(n.optional_vars)
        elif isinstance(n, ast.For | ast.AsyncFor):
            yield from ast.walk(n.target)


def attributes_set_outside_init(source: str) -> list[str]:
    """`Class.method: self.attr` for every `self.attr = ...` (also +=, with ... as, for)
    in a method other than `__init__`."""
    bad = []
    for cls in ast.walk(ast.parse(source)):
        if not isinstance(cls, ast.ClassDef):
            continue
        for fn in cls.body:
            if not isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef) or fn.name == "__init__":
                continue
            for t in _targets(fn):
                if (isinstance(t, ast.Attribute) and isinstance(t.value, ast.Name)
                        and t.value.id == "self"):  # fmt: skip
                    bad.append(f"{cls.name}.{fn.name}: self.{t.attr}")
    return bad


def test_the_check_sees_what_it_must():
    src = (
        "class A:\n"
        "    def __init__(self):\n        self.a = 1\n"
        "    def f(self):\n        self.b = 2\n        self.a += 1\n        self.c[0] = 3\n"
        "    def g(self):\n        with open('x') as self.d:\n            pass\n"
        "        self.e, x = 1, 2\n        self.f.g = 4\n"
    )
    assert attributes_set_outside_init(src) == [
        "A.f: self.b", "A.f: self.a", "A.g: self.e", "A.g: self.d",
    ]  # fmt: skip


@pytest.mark.parametrize("module", ["execute.py", "steploop.py"])
def test_run_classes_set_attributes_only_in_init(module):
    assert attributes_set_outside_init((RUN / module).read_text()) == []


@pytest.mark.parametrize("module", RUN_MODULES)
def test_run_modules_are_small(module):
    source = (RUN / module).read_text()
    assert len(source.splitlines()) <= 600
    long = [
        (fn.name, fn.end_lineno - fn.lineno + 1)
        for fn in ast.walk(ast.parse(source))
        if isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef)
        and fn.end_lineno - fn.lineno + 1 > 80
    ]
    assert long == []


def test_runresults_does_not_know_the_run():
    tree = ast.parse((RUN / "results.py").read_text())
    imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module} | {
        a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names
    }
    assert "testbed.run.execute" not in imported
