"""Every file the testbed writes and reads again has one type (issue 41, item 1): sweep.json
(testbed.files.sweepstate), a robot's events.jsonl (node.events), result.json and its config
(testbed.files.resultfile, testbed.files.resultconfig), a Slurm sweep's jobs file
(testbed.files.slurmjobs), an AODV daemon's statistics (aodv.statsfile). Checked here on the
source of every module: no module but the type's own opens sweep.json, the jobs file or a
daemon's statistics or parses event lines by hand, and the old files' defaults of a run's
config are the type's; and result.json's config is made from the run's option table (its
keys, its fields' names and kinds)."""

import ast
import dataclasses
import re
from pathlib import Path

import pytest

from testbed.files.resultconfig import CONFIG_KEYS, ResultConfig
from testbed.files.runconfig import BY_NAME
from tests.unit.test_result_file import _call_name, _scope, tainted_names

REPO = Path(__file__).resolve().parents[2]
PACKAGES = ("testbed", "topology", "node", "aodv", "common")
SWEEP_OWNER = "testbed/files/sweepstate.py"
EVENTS_OWNER = "node/events.py"
JOBS_OWNER = "testbed/files/slurmjobs.py"
STATS_OWNER = "aodv/statsfile.py"
SWEEP_SPELLED = re.compile(r"(?:^|/)sweep\.json$")
JOBS_SPELLED = re.compile(r"(?:^|/)jobs\.json$")
# An AODV daemon's statistics file as a path spells it: the daemon's own (rK.aodv.json in the
# testbed's state directory) and a run's copy (aodv/rK.json); and the names that give them.
STATS_SPELLED = re.compile(r"\.aodv\.json$|(?:^|/)aodv/r[^/]*\.json$")
STATS_MARKERS = {"aodv_stats_file", "run_stats_path", "run_stats_files", "RUN_DIR",
                 "STATS_FILES", "stats_files"}  # fmt: skip
# Calls that read a file's or a string's JSON (or its text, for a JSON reader to parse).
RAW_READERS = {"load", "loads", "read_json", "load_json", "parse_json", "read_text", "read_bytes"}
EVENTS_MENTIONED = re.compile(r"events\.jsonl|EVENTS_SUFFIX")
# An event line's first bytes, as a reader matching lines by hand spells them.
EVENT_PREFIX = re.compile(r"""\{\s*\\?["']e\\?["']\s*:""")


def _docstrings(tree: ast.AST) -> set[int]:
    ids = set()
    for n in ast.walk(tree):
        if isinstance(n, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = n.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                ids.add(id(body[0].value))
    return ids


def _strings(tree: ast.AST) -> list[tuple[int, str]]:
    docs = _docstrings(tree)
    out = []
    for n in ast.walk(tree):
        if isinstance(n, ast.Constant) and id(n) not in docs:
            if isinstance(n.value, str):
                out.append((n.lineno, n.value))
            elif isinstance(n.value, bytes):
                out.append((n.lineno, n.value.decode("latin-1")))
    return out


def _calls(tree: ast.AST) -> list[tuple[int, str]]:
    out = []
    for n in ast.walk(tree):
        if isinstance(n, ast.Call):
            f = n.func
            name = (
                f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""
            )
            out.append((n.lineno, name))
    return out


def sweep_reads(source: str) -> list[str]:
    """Where `source` reaches sweep.json but through its type: its name spelled as a path,
    the type module's name constant, or its check of a raw document."""
    tree = ast.parse(source)
    found = [f"{ln}: spells sweep.json" for ln, s in _strings(tree) if SWEEP_SPELLED.search(s)]
    for n in ast.walk(tree):
        if isinstance(n, ast.alias) and n.name == "STATE_NAME":
            found.append(f"{n.lineno}: imports STATE_NAME")
        elif isinstance(n, ast.Attribute) and n.attr == "STATE_NAME":
            found.append(f"{n.lineno}: uses STATE_NAME")
        elif (isinstance(n, ast.Attribute) and n.attr == "check"
              and isinstance(n.value, ast.Name) and n.value.id == "sweepstate"):  # fmt: skip
            found.append(f"{n.lineno}: checks a raw sweep.json")
    return found


def event_parses(source: str) -> list[str]:
    """Where `source` parses event-log lines by hand: an event line's first bytes spelled,
    or json.load(s) in a module that names an event log."""
    tree = ast.parse(source)
    found = [f"{ln}: matches an event line's bytes" for ln, s in _strings(tree)
             if EVENT_PREFIX.search(s)]  # fmt: skip
    if EVENTS_MENTIONED.search(source):
        found += [f"{ln}: {name}() in a module that reads an event log"
                  for ln, name in _calls(tree) if name == "loads"]  # fmt: skip
    return found


def _names(tree: ast.AST, name: str) -> list[int]:
    """The lines where `name` is imported, named or taken as an attribute."""
    out = []
    for n in ast.walk(tree):
        if (isinstance(n, ast.alias) and n.name == name
                or isinstance(n, ast.Attribute) and n.attr == name
                or isinstance(n, ast.Name) and n.id == name):  # fmt: skip
            out.append(n.lineno)
    return out


def jobs_reads(source: str) -> list[str]:
    """Where `source` reaches the Slurm jobs file but through its type: its name spelled as a
    path, the type module's name constant, its check of a raw document, or its path handed
    to a raw JSON reader in the same module."""
    tree = ast.parse(source)
    found = [f"{ln}: spells jobs.json" for ln, s in _strings(tree) if JOBS_SPELLED.search(s)]
    found += [f"{ln}: uses JOBS_NAME" for ln in _names(tree, "JOBS_NAME")]
    found += [f"{ln}: checks a raw jobs file" for ln in _names(tree, "from_json")
              if "SlurmJobs" in source]  # fmt: skip
    if _names(tree, "jobs_path"):
        found += [f"{ln}: {name}() beside jobs_path" for ln, name in _calls(tree)
                  if name in RAW_READERS]  # fmt: skip
    return found


def _stats_place(n: ast.AST) -> bool:
    """Whether `n` names where a statistics file is: spelled, or "aodv" as a part of a path
    (`d / "aodv"`, `os.path.join(d, "aodv", ...)`)."""
    aodv = [n.left, n.right] if isinstance(n, ast.BinOp) and isinstance(n.op, ast.Div) else (
        n.args if isinstance(n, ast.Call) and _call_name(n) == "join" else [])  # fmt: skip
    if any(isinstance(a, ast.Constant) and a.value == "aodv" for a in aodv):
        return True
    return (
        isinstance(n, ast.Constant)
        and isinstance(n.value, str)
        and bool(STATS_SPELLED.search(n.value))
    )


def _reaches(node: ast.AST, tainted: set[str]) -> bool:
    for n in ast.walk(node):
        name = n.id if isinstance(n, ast.Name) else n.attr if isinstance(n, ast.Attribute) else ""
        if name in tainted or _stats_place(n):
            return True
    return False


def stats_reads(source: str) -> list[str]:
    """Where `source` reads an AODV daemon's statistics file but through its type: within a
    function, a value made from the file's place (spelled, "aodv" joined to a directory, or
    a name that gives it) reaching a raw reader (directly, through a variable or a loop over
    it); or the type's check of a raw document."""
    tree = ast.parse(source)
    found = [f"{ln}: checks a raw statistics document" for ln in _names(tree, "from_json")
             if "DaemonStats" in source]  # fmt: skip
    scopes = [n for n in ast.walk(tree)
              if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda)]  # fmt: skip
    for fn in [tree, *scopes]:
        # names assigned (or looped over) from a statistics file's place
        tainted = tainted_names(fn, STATS_MARKERS, _reaches)
        for n in _scope(fn):
            if isinstance(n, ast.Call) and _call_name(n) in RAW_READERS | {"open"}:
                parts = [*n.args, *(k.value for k in n.keywords)]
                if isinstance(n.func, ast.Attribute):
                    parts.append(n.func.value)  # path.read_text()
                if any(_reaches(p, tainted) for p in parts):
                    found.append(f"{n.lineno}: {_call_name(n)}() of a statistics file")
    return sorted(set(found))


def _modules(owner: str):
    for pkg in PACKAGES:
        for path in sorted((REPO / pkg).rglob("*.py")):
            rel = str(path.relative_to(REPO))
            if rel != owner:
                yield pytest.param(path, id=rel)


def test_the_checks_see_what_they_must():
    assert sweep_reads("x = read_json(out / 'sweep.json')\n")
    assert sweep_reads("p = os.path.join(d, 'sweep.json')\n")
    assert sweep_reads("p = out / sweepstate.STATE_NAME\n")
    assert sweep_reads("from testbed.files.sweepstate import STATE_NAME\n")
    assert sweep_reads("doc = sweepstate.check(json.load(f))\n")
    assert not sweep_reads('"""Reads sweep.json."""\ns = sweepstate.read(out)\n')
    assert event_parses('if line.startswith(b\'{"e":"send"\'):\n    pass\n')
    assert event_parses("p = 'r1.events.jsonl'\nevs = [json.loads(x) for x in open(p)]\n")
    assert event_parses("p = f'r{k}{EVENTS_SUFFIX}'\ne = json.loads(line)\n")
    assert not event_parses("p = 'r1.events.jsonl'\nevs = events.read(p, only=('plan',))\n")
    assert not event_parses("d = json.loads(text)\n")  # not a module about event logs
    assert jobs_reads("jobs = read_json(out / 'slurm' / 'jobs.json')['jobs']\n")
    assert jobs_reads("p = os.path.join(out, 'slurm/jobs.json')\n")
    assert jobs_reads("from testbed.files.slurmjobs import JOBS_NAME\n")
    assert jobs_reads("d = json.loads(slurmjobs.jobs_path(out).read_text())\n")
    assert jobs_reads("j = SlurmJobs.from_json(json.load(f))\n")
    assert not jobs_reads('"""Reads slurm/jobs.json."""\njobs = slurmjobs.read(out).jobs\n')

    # the AODV statistics' readers this project had before the type, one per pattern
    bad = [
        "def f(out, k):\n    with open(os.path.join(out, 'aodv', f'r{k}.json')) as f:\n"
        "        return json.load(f)\n",
        "def f(run_dir):\n    d = Path(run_dir) / 'aodv'\n    for p in sorted(d.glob('r*.json')):\n"
        "        doc = boundedfile.load_json(p)\n",
        "def f(run_dir):\n    for p in sorted((Path(run_dir) / 'aodv').glob('r*.json')):\n"
        "        doc = read_json(p) or {}\n",
        "def f(self):\n    for f in self.stats_files:\n        doc = read_json(f) or {}\n",
        "def f(net, k):\n    p = Path(f'{net.state_dir}/r{k}.aodv.json')\n"
        "    return json.loads(p.read_text())\n",
        "def f(net, k):\n    return read_json(aodv_stats_file(k, net.state_dir))\n",
        "def f(p):\n    return DaemonStats.from_json(json.load(open(p)))\n",
    ]
    for src in bad:
        assert stats_reads(src), src
    good = [
        "def f(out, k):\n    return DaemonStats.read(run_stats_path(out, k))\n",
        "def f(d):\n    for p in run_stats_files(d) or []:\n        s = DaemonStats.read(p)\n"
        "    return read_json(os.path.join(d, 'medium.json'))\n",
        '"""Reads aodv/rK.json."""\ndef f(p):\n    return read_json(p)\n',
    ]
    for src in good:
        assert stats_reads(src) == [], src


@pytest.mark.parametrize("path", list(_modules(STATS_OWNER)))
def test_no_module_but_the_type_reads_an_aodv_statistics_file(path):
    assert stats_reads(path.read_text()) == []


@pytest.mark.parametrize("path", list(_modules(JOBS_OWNER)))
def test_no_module_but_the_type_reads_the_slurm_jobs_file(path):
    assert jobs_reads(path.read_text()) == []


@pytest.mark.parametrize("path", list(_modules(SWEEP_OWNER)))
def test_no_module_but_the_type_reads_sweep_json(path):
    assert sweep_reads(path.read_text()) == []


@pytest.mark.parametrize("path", list(_modules(EVENTS_OWNER)))
def test_no_module_but_the_type_parses_event_lines(path):
    assert event_parses(path.read_text()) == []


# ---------------------------------------------------------------- config.json's two descriptions


def test_result_configs_keys_are_run_options():
    """result.json's config repeats options of the run's table (testbed.files.runconfig): each of
    its keys is one, and its fields are those keys and the few it draws from `extra`."""
    assert [k for k in CONFIG_KEYS if k not in BY_NAME] == []
    fields = [f.name for f in dataclasses.fields(ResultConfig)]
    drawn = ("medium", "wifi_standard", "wifi_rate", "extra")
    assert sorted(fields) == sorted([*CONFIG_KEYS, *drawn])
    assert [k for k in drawn[:-1] if k not in BY_NAME] == []
    defaulted = ("middleware", "maps", "battery_failure")
    assert [k for k in defaulted if k not in BY_NAME] == []


def test_result_configs_keys_are_the_options_marked_in_result(monkeypatch):
    """The keys are the options marked in_result, in the order result.json has always had
    them; the table checks itself against them as it is made (check_options): an option
    marked in_result that is not a key, a key without a ResultConfig field, or a field whose
    annotation is not its option's kind, stops the table's import."""
    from testbed.files import resultconfig
    from testbed.files.runconfig import OPTIONS

    assert tuple(o.name for o in OPTIONS if o.in_result) == CONFIG_KEYS
    assert CONFIG_KEYS == ("robots", "comm_range", "laser_range", "seed", "time_scale",
                           "routing", "map", "loss_pct", "delay_ms", "capture", "max_steps",
                           "coordination", "start")  # fmt: skip
    resultconfig.check_options(OPTIONS)
    marked = [dataclasses.replace(o, in_result=o.in_result or o.name == "range_model")
              for o in OPTIONS]  # fmt: skip
    with pytest.raises(TypeError, match="in_result"):
        resultconfig.check_options(marked)
    monkeypatch.setattr(resultconfig, "CONFIG_KEYS", tuple(o.name for o in marked if o.in_result))
    with pytest.raises(TypeError, match="fields"):
        resultconfig.check_options(marked)
    monkeypatch.setattr(resultconfig, "CONFIG_KEYS", CONFIG_KEYS)
    kinds = [dataclasses.replace(o, kind=str) if o.name == "seed" else o for o in OPTIONS]
    with pytest.raises(TypeError, match="ResultConfig.seed"):
        resultconfig.check_options(kinds)


def test_result_config_defaults_match_the_options_defaults():
    """A run that left an option at its default and an old run without it read the same."""
    from testbed.files.runconfig import RunConfig

    new = RunConfig(robots=2, comm_range=20.0).to_dict()
    new.update(map_size=[400, 400])
    cfg = ResultConfig.from_config(new)
    old = ResultConfig.from_dict({"robots": 2, "comm_range": 20.0, "laser_range": 1.0})
    for prop in ("middleware", "maps", "battery_failure", "routing", "coordination", "start",
                 "medium", "loss_pct", "delay_ms"):  # fmt: skip
        assert getattr(old, prop) == getattr(cfg, prop), prop
    assert old.map_size == [400, 400] and old.map_cell == cfg.map_cell


def test_old_configs_defaults_are_the_types():
    old = ResultConfig.from_dict({"robots": 2, "comm_range": 20, "laser_range": 1.0})
    assert (old.middleware, old.maps, old.battery_failure) == ("nanomsg", "flood", "none")
    assert old.map_cell == 0.05 and old.map_size == [400, 400]
    given = ResultConfig.from_dict({"robots": 2, "comm_range": 20, "laser_range": 1.0,
                                    "extra": {"middleware": "zenoh", "maps": "pubsub",
                                              "battery_failure": "midrun", "map_cell": 0.1,
                                              "map_size": [10, 20]}})  # fmt: skip
    assert (given.middleware, given.maps, given.battery_failure) == ("zenoh", "pubsub", "midrun")
    assert given.map_cell == 0.1 and given.map_size == [10, 20]
    odd = ResultConfig.from_dict({"robots": 2, "comm_range": 20, "laser_range": 1.0,
                                  "extra": {"middleware": 3, "maps": None}})  # fmt: skip
    assert (odd.middleware, odd.maps) == ("nanomsg", "flood")
