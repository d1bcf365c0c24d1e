"""Benchmarks behind `tracelab bench` (docs/benchmarks.md): engine compile and start-up, simulator speed
and memory, the envs, the trace store. Speed is measured here, never asserted by timed tests.

Kept import-light: `python -m tracelab.bench.probe` times process start-up through this package."""
