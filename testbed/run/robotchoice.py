"""Which robot program a run starts: the C++ robot (build/tb-robot, native/robot) or the
Python robot (`python -m node`), and why (result.json's `robot` and `robot_reason`).

`--robot auto` (the default) takes the C++ robot wherever it was built and carries the run's
options: the default middleware (nanomsg) with flooded maps. Elsewhere the Python robot runs
and the reason says what was missing. `--robot cpp` insists (a run it cannot carry is refused
before it starts); `--robot python` asks for the reference. The display is always Python.
"""

from __future__ import annotations

from node.native import TB_ROBOT, unbuilt_reason

CHOICES = ("auto", "cpp", "python")
CPP_MIDDLEWARES = ("nanomsg",)
CPP_MAPS = ("flood",)


def cpp_refusal(middleware: str, maps: str, built: bool | None = None) -> str:
    """Why the C++ robot cannot run with these options ("" when it can)."""
    if built is None:
        built = TB_ROBOT.is_file()
    if not built:
        return unbuilt_reason() or (
            f"{TB_ROBOT.name} not built (make setup builds it where g++ and libnng-dev are)"
        )
    if middleware not in CPP_MIDDLEWARES:
        return f"it carries nanomsg, not --middleware {middleware}"
    if maps not in CPP_MAPS:
        return f"it floods maps, not --maps {maps}"
    return ""


def choose(robot: str, middleware: str, maps: str, built: bool | None = None) -> tuple[str, str]:
    """(the robot program, "cpp" or "python"; the reason) for a run's options. ValueError
    for `--robot cpp` where the C++ robot cannot run."""
    if robot == "python":
        return "python", "python: asked for"
    why = cpp_refusal(middleware, maps, built)
    if robot == "cpp":
        if why:
            raise ValueError(f"--robot cpp: the C++ robot cannot run this: {why}")
        return "cpp", "cpp: asked for"
    if robot != "auto":
        raise ValueError(f"--robot {robot!r}: one of {', '.join(CHOICES)}")
    if why:
        return "python", f"auto: the C++ robot cannot run this: {why}"
    return "cpp", "auto: built and carries nanomsg"
