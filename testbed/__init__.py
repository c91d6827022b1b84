"""The harness: runs, sweeps, networks by hand, reports (docs/architecture.md)."""

from pathlib import Path

# The checkout this package runs from (it holds pyproject.toml, node/, tests/): where Slurm
# tasks start, and what tests put on a child's PYTHONPATH.
PROJECT_ROOT = str(Path(__file__).resolve().parents[1])
