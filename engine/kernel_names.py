"""The kernels an Engine can run, by name (`Engine(kernel=...)`, every command's `--kernel`). A module of
its own, importing nothing, so that argument parsers and configs list the choices without importing
numba and the kernels (tracelab.engine imports its names lazily)."""

KERNELS = ("auto", "counting", "lanes", "compiled")
