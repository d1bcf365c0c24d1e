"""argparse value types shared by the commands: a bad value is a usage error (exit 2) naming it."""
from __future__ import annotations

import argparse


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None


def non_negative_int(text: str) -> int:
    v = _int(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {v}")
    return v


def positive_int(text: str) -> int:
    v = _int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {v}")
    return v


# Engine(kernel=...) choices, spelled out here so that parsers need not import the engine (numba) to list
# them; tests/test_compiled_kernel.py checks them against tracelab.engine.core.KERNELS
ENGINE_KERNELS = ("auto", "counting", "lanes", "compiled")
