"""The bounded, regular-files-only, non-blocking reader under its older name: it lives in
common.boundedfile (the results directories' files need it too, and common/ is what every
package may use)."""

from common.boundedfile import Refused, describe, load_json, parse_json, read, regular

__all__ = ["Refused", "describe", "load_json", "parse_json", "read", "regular"]
