"""torch's deterministic-algorithms switch without loading torch.compile's machinery.

`torch.use_deterministic_algorithms` (torch 2.13) imports `torch._inductor.config` to set torch.compile's
own flag, and with it torch._dynamo: ~2.2 s of CPU at every training's start (docs/benchmarks.md, issue
40), for a compiler tracelab never calls. The flag that the eager operations read is torch._C's; the
inductor's is set too when something in the process has loaded it (it then compiles with the same mode)."""
from __future__ import annotations

import sys

import torch


def use_deterministic_algorithms(mode: bool) -> None:
    """torch.use_deterministic_algorithms(mode), without importing torch._inductor when nothing has."""
    set_eager = getattr(torch._C, "_set_deterministic_algorithms", None)
    if "torch._inductor.config" in sys.modules or set_eager is None:
        torch.use_deterministic_algorithms(mode)
    else:
        set_eager(mode, warn_only=False)
