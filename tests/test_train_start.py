"""What a training pays before its first step (issue 40): torch's deterministic mode is set without
importing torch.compile's machinery (torch._inductor, torch._dynamo: ~2 s of CPU), and set as torch's own
switch would (the eager flag that the operations read). Figures: `tracelab bench first-run` (train)."""
from __future__ import annotations

import json
import subprocess
import sys

CHILD = """
import json, sys, torch
from tracelab.train.determinism import use_deterministic_algorithms
seen = []
for mode in (True, False, True):
    use_deterministic_algorithms(mode)
    seen.append(torch.are_deterministic_algorithms_enabled())
loaded = "torch._inductor" in sys.modules or "torch._dynamo" in sys.modules
import torch._inductor.config as inductor_config  # once something has loaded it, its flag follows too
use_deterministic_algorithms(False)
print(json.dumps({"seen": seen, "loaded": loaded, "inductor": inductor_config.deterministic,
                  "eager": torch.are_deterministic_algorithms_enabled()}))
"""


def test_the_deterministic_switch_loads_no_compiler() -> None:
    done = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, timeout=300, check=True)
    got = json.loads(done.stdout.splitlines()[-1])
    assert got["seen"] == [True, False, True]
    assert got["loaded"] is False
    assert got["inductor"] is False and got["eager"] is False
