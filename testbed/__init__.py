"""The harness: runs, sweeps, networks by hand, reports (docs/architecture.md)."""

# The checkout this package runs from (it holds pyproject.toml, node/, tests/): where Slurm
# tasks start, and what tests put on a child's PYTHONPATH.
from common.paths import PROJECT_ROOT

__all__ = ["PROJECT_ROOT"]
