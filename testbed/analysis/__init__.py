"""Offline analysis of finished runs and sweeps: figures, the report and its verdicts, the
routing metrics read from packet captures, and the causality check of a run's receipts.
Nothing here runs a testbed or needs root. See docs/architecture.md."""
