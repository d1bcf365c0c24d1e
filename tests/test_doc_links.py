"""The documents the code and the docs point at are in the repository (issue 28 §4): every `docs/....md`
named in a source, rule or markdown file exists, and nothing sends a reader to files outside it."""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOC_PATH = re.compile(r"\bdocs/\w[\w./-]*?\.md\b")
OUTSIDE = re.compile(r"\bshared/[\w.-]+\.md\b")  # the project's brief, kept outside the repository
# named on purpose: a pattern (an experiment's report) and PyReason's own documentation (tests/test_pyreason.py)
NOT_OURS = {"docs/experiments/NAME.md", "docs/hello-world.md"}


def _tracked_texts() -> list[Path]:
    names = subprocess.run(["git", "ls-files", "*.py", "*.md", "*.rules", "*.toml"], cwd=ROOT,
                           capture_output=True, text=True, check=True).stdout.split()
    return [ROOT / n for n in names if (ROOT / n).is_file()]


def test_every_named_document_exists() -> None:
    missing, outside = [], []
    for path in _tracked_texts():
        text = path.read_text(errors="replace")
        rel = path.relative_to(ROOT)
        missing += [f"{rel}: {m}" for m in DOC_PATH.findall(text)
                    if m not in NOT_OURS and not (ROOT / m).exists()]
        outside += [f"{rel}: {m}" for m in OUTSIDE.findall(text)]
    assert missing == [] and outside == []
