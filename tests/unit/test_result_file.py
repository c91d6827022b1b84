"""result.json is one type (testbed/files/resultfile.py's `RunResult`): what runresults writes is
what every reader reads, and no module but resultfile.py reads the file by hand.

The structure rule, checked on every module of the project's packages:

1. the file's name is spelled in code only in resultfile.py (everyone else names it by
   `RESULT_NAME` or asks `has_result`/`result_path`), and
2. within a function, no value made from `RESULT_NAME` or `result_path(...)` (directly, or
   through a variable or a loop over it) reaches a raw reader: `open`, `json.load(s)`,
   `read_json`, `.read_text()`, `.read_bytes()`. It may reach `RunResult.from_json`/`read`.

Together they leave no way to a result.json's raw keys but through the type: a module
cannot open the file without naming it, and naming it goes through the one constant.
"""

import ast
import dataclasses
import json
import re
from pathlib import Path

import pytest

from testbed.files.resultfile import ResultConfig, ResultError, RobotResult, RunResult

REPO = Path(__file__).resolve().parents[2]
PACKAGES = ("testbed", "topology", "node", "aodv")
OWNER = REPO / "testbed" / "files" / "resultfile.py"
MARKERS = {"RESULT_NAME", "result_path"}
READERS = {"open", "load", "loads", "read_json", "read_text", "read_bytes"}
# The name as a path (or a path's last part), not a sentence that mentions the file.
SPELLED = re.compile(r"(?:^|/)result\.json$")


def _docstrings(tree: ast.AST) -> set[int]:
    ids = set()
    for n in ast.walk(tree):
        if isinstance(n, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = n.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                ids.add(id(body[0].value))
    return ids


def _spelled(n: ast.AST) -> bool:
    return (
        isinstance(n, ast.Constant) and isinstance(n.value, str) and bool(SPELLED.search(n.value))
    )


def _mentions(node: ast.AST, names: set[str]) -> bool:
    """Whether `node` uses one of `names` or spells result.json as a path."""
    for n in ast.walk(node):
        if isinstance(n, ast.Name) and n.id in names:
            return True
        if isinstance(n, ast.Attribute) and n.attr in names:
            return True
        if _spelled(n):
            return True
    return False


def _scope(fn: ast.AST):
    """The nodes of one scope: the function's (or module's) own, not its nested functions'."""
    todo = list(ast.iter_child_nodes(fn))
    while todo:
        n = todo.pop()
        yield n
        if not isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
            todo.extend(ast.iter_child_nodes(n))


def _call_name(call: ast.Call) -> str | None:
    f = call.func
    return f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else None


def tainted_names(fn: ast.AST, seeds, reaches) -> set[str]:
    """The names in `fn`'s own scope that are assigned (or looped over) from a value that
    `reaches(value, names)` says comes from one of `seeds` or a name already found, until
    no more are found."""
    tainted = set(seeds)
    changed = True
    while changed:
        changed = False
        for n in _scope(fn):
            targets, value = [], None
            if isinstance(n, ast.Assign):
                targets, value = n.targets, n.value
            elif isinstance(n, ast.AnnAssign | ast.AugAssign | ast.NamedExpr):
                targets, value = [n.target], n.value
            elif isinstance(n, ast.For | ast.comprehension):
                targets, value = [n.target], n.iter
            elif isinstance(n, ast.withitem) and n.optional_vars is not None:
                targets, value = [n.optional_vars], n.context_expr
            if value is None or not reaches(value, tainted):
                continue
            for t in targets:
                for name in ast.walk(t):
                    if isinstance(name, ast.Name) and name.id not in tainted:
                        tainted.add(name.id)
                        changed = True
    return tainted


def raw_reads(source: str) -> list[str]:
    """Where `source` reads result.json by hand: `line: what`."""
    tree = ast.parse(source)
    docs = _docstrings(tree)
    found = []
    for n in ast.walk(tree):
        if _spelled(n) and id(n) not in docs:
            found.append(f"{n.lineno}: spells the file's name")
    scopes = [
        n
        for n in ast.walk(tree)
        if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda)
    ]
    for fn in [tree, *scopes]:
        # names assigned (or looped over) from a path to result.json
        tainted = tainted_names(fn, MARKERS, _mentions)
        for n in _scope(fn):
            if isinstance(n, ast.Call) and _call_name(n) in READERS:
                parts = [*n.args, *(k.value for k in n.keywords)]
                if isinstance(n.func, ast.Attribute):
                    parts.append(n.func.value)  # path.read_text()
                if any(_mentions(p, tainted) for p in parts):
                    found.append(f"{n.lineno}: {_call_name(n)}() of result.json")
    return sorted(set(found))


def test_the_check_sees_what_it_must():
    # the readers this project had before the type, one per pattern
    bad = {
        'def f(out):\n    return read_json(run_dir(out) / "result.json") or {}\n': 1,
        "def f(out):\n    with open(os.path.join(out, 'result.json')) as f:\n"
        "        return json.load(f)\n": 1,
        'def f(out):\n    for res in out.glob("runs/*/result.json"):\n'
        '        x = (read_json(res) or {}).get("cpu_s")\n': 2,
        "def f(d):\n    p = d / RESULT_NAME\n    return json.loads(p.read_text())\n": 1,
        "def f(d):\n    q = result_path(d)\n    with open(q) as f:\n        pass\n": 1,
        "def f(d):\n    for p in d.glob(f'runs/*/{RESULT_NAME}'):\n        doc = read_json(p)\n": 1,
        "def f(d):\n    text = (d / RESULT_NAME).read_text()\n": 1,
    }
    for src, n in bad.items():
        assert len(raw_reads(src)) >= n, src
    good = [
        "def f(d):\n    r = RunResult.read(d / RESULT_NAME)\n    return r.status\n",
        "def f(d):\n    for p in d.glob(f'runs/*/{RESULT_NAME}'):\n"
        "        r = RunResult.from_json(p.parent)\n",
        '"""A module about result.json (docstrings may name it)."""\n',
        "def f(d):\n    return has_result(d) and read_json(d / 'sweep.json')\n",
    ]
    for src in good:
        assert raw_reads(src) == [], src


def _modules():
    for pkg in PACKAGES:
        for path in sorted((REPO / pkg).rglob("*.py")):
            if path != OWNER:
                yield path


@pytest.mark.parametrize("path", list(_modules()), ids=lambda p: str(p.relative_to(REPO)))
def test_no_module_but_resultfile_reads_result_json_by_hand(path):
    assert raw_reads(path.read_text()) == []


# ---------------------------------------------------------------- the type

CONFIG = {
    "robots": 3, "comm_range": 20.0, "laser_range": 2.0, "seed": 7, "time_scale": 16.0,
    "routing": "aodv", "map": None, "loss_pct": 0.0, "delay_ms": 0.0, "capture": False,
    "max_steps": 4000, "coordination": "ours", "start": "corner",
    "extra": {"medium": "veth", "kill": ["2:150"], "isolate": []},
}  # fmt: skip


def test_what_is_written_reads_back_the_same():
    r2 = RobotResult(name="r2", finish_step=None, crashed=False, stopped_step=150,
                     exit_status=-9)  # fmt: skip
    r1 = RobotResult(name="r1", finish_step=1072, crashed=False, exit_status=0,
                     sent={"map": 3}, received={"map": 5}, path_length_m=12.5)  # fmt: skip
    result = RunResult(
        config=ResultConfig.from_dict(CONFIG), status="complete", steps=1082,
        mean_finish_step=1072.0, mean_finish_step_robots=1, survivors_finished=True,
        robots=(r1, r2), fidelity={"ok": True, "measures": {}, "network": {"ok": True}},
        world_missed_steps_ms_late=((5, 2.5),), network_timers={"time_scale": 16},
    )  # fmt: skip
    doc = json.loads(json.dumps(result.to_json()))
    assert list(doc)[:3] == ["format", "config", "status"] and list(doc)[-1] == "network_timers"
    assert doc["config"] == CONFIG
    back = RunResult.from_json(doc)
    assert back == result and back.to_json() == doc
    assert [r.name for r in back.counted_robots] == ["r1"] and back.exploration_steps == 1072


def test_per_robot_second_is_robot_time_at_the_scale_the_run_kept():
    """The one place a count over the captures becomes a rate per robot per second of robot
    (emulated) time, for the media, protocol and middleware tables."""
    base = RunResult(config=ResultConfig.from_dict(CONFIG), status="complete", steps=100)
    assert base.time_scale_ran == base.config.time_scale
    asked = dataclasses.replace(base, time_scale_requested=8.0)
    kept = dataclasses.replace(asked, time_scale_achieved=6.0)
    assert (asked.time_scale_ran, kept.time_scale_ran) == (8.0, 6.0)
    assert kept.per_robot_second(600.0, 5.0, 4) == pytest.approx(600 / (4 * 5 * 6))
    for total, wall, robots in ((None, 5.0, 4), (600.0, None, 4), (600.0, 0.0, 4), (1.0, 5.0, 0)):
        assert kept.per_robot_second(total, wall, robots) is None


def test_older_files_get_their_defaults_here(tmp_path):
    old = {"status": "step_cap", "steps": 300, "config": {"robots": 2, "comm_range": 5,
           "laser_range": 2.0, "extra": {"coordination": "paper"}},
           "robots": {"r1": {"finish_step": 100}, "r2": {"finish_step": None}}}  # fmt: skip
    (tmp_path / "result.json").write_text(json.dumps(old))
    r = RunResult.from_json(tmp_path)
    assert r.config.routing == "aodv" and r.config.coordination == "paper"
    assert r.config.start == "corner" and r.config.medium == "veth"
    assert r.mean_finish_step_robots is None and r.isolated == () and r.faithful is None
    assert all(x.counted for x in r.robots) and r.exploration_steps == 200
    assert RunResult.from_json(tmp_path / "result.json") == r


@pytest.mark.parametrize(
    ("doc", "says"),
    [
        ([], "not a JSON object"),
        ({"status": "complete"}, "no 'config'"),
        ({"status": "complete", "config": {"robots": 2}}, "no 'comm_range'"),
        ({"config": CONFIG}, "no 'status'"),
        ({"status": "complete", "config": CONFIG, "steps": "9"}, "'steps' is str"),
        ({"status": "complete", "config": CONFIG, "isolated": [{"robot": "r1"}]}, "from_step"),
        ({"status": "complete", "config": CONFIG, "fidelity": {"ok": "yes"}}, "'ok' is str"),
    ],
)
def test_a_malformed_result_is_one_line_naming_the_file(tmp_path, doc, says):
    (tmp_path / "result.json").write_text(json.dumps(doc))
    with pytest.raises(ResultError) as e:
        RunResult.from_json(tmp_path)
    assert str(tmp_path / "result.json") in str(e.value) and says in str(e.value)
    assert "\n" not in str(e.value)
    assert RunResult.read(tmp_path) is None
    assert RunResult.read(tmp_path / "missing") is None
