"""C++ literals of Python values, for the headers that carry numbers and names a compiled
program shares with its Python twin (node.argsgen -> build/gen/node_args.h, aodv.constgen ->
build/gen/aodv_consts.h): each such value is written once, in Python, and reaches the
compiled code through these."""

from __future__ import annotations


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
