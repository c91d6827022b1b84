"""C++ literals of Python values, for the headers that carry numbers and names a compiled
program shares with its Python twin (node.argsgen -> build/gen/node_args.h, aodv.constgen ->
build/gen/aodv_consts.h, node.constgen -> build/gen/robot_consts.h): each such value is
written once, in Python, and reaches the compiled code through these; `write_header` is how
each generator writes its file."""

from __future__ import annotations

from pathlib import Path


def write_header(path: Path, text: str) -> None:
    """`text` into `path`, only if it differs from what is there (make then rebuilds what
    includes it only when a value changed), through a `.part` file renamed over it (a build
    killed half-way leaves no half header)."""
    if path.exists() and path.read_text() == text:
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    part = path.with_name(path.name + ".part")
    part.write_text(text)
    part.replace(path)


def c_string(text: str) -> str:
    """`text` as a C string literal (UTF-8; a byte not printable ASCII as an octal escape)."""
    out = []
    for byte in text.encode():
        ch = chr(byte)
        if ch in '\\"':
            out.append("\\" + ch)
        elif ch == "\n":
            out.append("\\n")
        elif 32 <= byte < 127:
            out.append(ch)
        else:
            out.append(f"\\{byte:03o}")
    return '"' + "".join(out) + '"'


def c_real(value: float | None) -> str:
    """A double as a C++ literal that reads back as the same double (0.0 for None)."""
    return repr(float(value if value is not None else 0.0))
