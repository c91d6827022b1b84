"""The harness: runs, sweeps, networks by hand, reports (docs/architecture.md)."""

from pathlib import Path

# The checkout this package runs from (it holds pyproject.toml, node/, tests/): where Slurm
# tasks start, and what tests put on a child's PYTHONPATH.
from common.paths import PROJECT_ROOT

# This package's own folder: its data files (the sweep files, the maps they name) ship in it.
PACKAGE_DIR = Path(__file__).resolve().parent

__all__ = ["PACKAGE_DIR", "PROJECT_ROOT"]
