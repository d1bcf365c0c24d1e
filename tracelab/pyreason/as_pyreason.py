"""PyReason scripts as they are (`python -m tracelab.pyreason SCRIPT.py`, `tracelab run-pyreason`): for
the run of one script, `import pyreason`, `from pyreason import ...` and the `pyreason.scripts...`
modules PyReason's examples import resolve to tracelab's modules. A finder on sys.meta_path of this
process does it; nothing is installed under the name `pyreason`, and a name tracelab has no module for
is a ModuleNotFoundError naming it."""
from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import os
import runpy
import sys
import types
from collections.abc import Sequence

from tracelab.errors import UserError

# PyReason's module -> tracelab's module that holds what PyReason's examples import from it
MODULES = {
    "pyreason": "tracelab.pyreason",
    "pyreason.pyreason": "tracelab.pyreason",
    "pyreason.scripts.rules.rule": "tracelab.pyreason.objects",
    "pyreason.scripts.facts.fact": "tracelab.pyreason.objects",
    "pyreason.scripts.query.query": "tracelab.pyreason.objects",
    "pyreason.scripts.threshold.threshold": "tracelab.pyreason.objects",
    "pyreason.scripts.numba_wrapper.numba_types.interval_type": "tracelab.pyreason.numba_interval",
    "pyreason.scripts.interval.interval": "tracelab.pyreason.numba_interval",
    "pyreason.scripts.learning.classification.classifier": "tracelab.pyreason.classifier",
    "pyreason.scripts.learning.classification.temporal_classifier": "tracelab.pyreason.temporal_classifier",
    "pyreason.scripts.learning.classification.hf_classifier": "tracelab.pyreason.hf_classifier",
    "pyreason.scripts.learning.utils.model_interface": "tracelab.pyreason.classifier",
    "pyreason.scripts.utils.filter_ruleset": "tracelab.pyreason.ruleset_filter",
}
# the pip name of a package PyReason's examples import under another name (any other: its own name)
PIP_NAMES = {"cv2": "opencv-python", "PIL": "pillow", "yaml": "pyyaml", "sklearn": "scikit-learn"}
# the packages on the way to those modules (`pyreason.scripts`, `pyreason.scripts.rules`, ...): empty
PACKAGES = {name.rsplit(".", k)[0] for name in MODULES for k in range(1, name.count(".") + 1)} - set(MODULES)


class _Alias(importlib.abc.Loader):
    """Loads a PyReason module name as the tracelab module that stands for it (or an empty package)."""

    def __init__(self, target: str | None) -> None:
        self.target = target

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> types.ModuleType:
        if self.target is None:
            return types.ModuleType(spec.name)
        return importlib.import_module(self.target)  # the import system keeps its name and spec

    def exec_module(self, module: types.ModuleType) -> None:
        pass


class PyReasonFinder(importlib.abc.MetaPathFinder):
    """Finds `pyreason` and its modules (MODULES) as tracelab's; other `pyreason.*` names are not found
    (ModuleNotFoundError), so that no installed PyReason answers for them either."""

    def find_spec(self, fullname: str, path: Sequence[str] | None = None,
                  target: types.ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        if fullname != "pyreason" and not fullname.startswith("pyreason."):
            return None
        if fullname in PACKAGES:
            return importlib.machinery.ModuleSpec(fullname, _Alias(None), is_package=True)
        if fullname in MODULES:
            return importlib.machinery.ModuleSpec(fullname, _Alias(MODULES[fullname]),
                                                  is_package=fullname == "pyreason")
        raise ModuleNotFoundError(f"tracelab.pyreason has no module standing for PyReason's {fullname} "
                                  "(docs/pyreason.md, 'Scripts as they are')", name=fullname)


def run_script(script: str, args: Sequence[str] = ()) -> None:
    """Run a PyReason script as `python SCRIPT ARGS` would, its PyReason imports resolved to tracelab's
    (the finder stays for the rest of this process: the script's imports may happen at any time)."""
    if not os.path.isfile(script):
        raise FileNotFoundError(2, "No such file", script)
    if not any(isinstance(f, PyReasonFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, PyReasonFinder())
    sys.argv = [script, *args]
    sys.path.insert(0, os.path.dirname(os.path.abspath(script)))  # as python puts a script's folder first
    try:
        runpy.run_path(script, run_name="__main__")
    except ModuleNotFoundError as e:
        missing = _not_installed(e)
        if missing is None:
            raise  # a module the script or a package it uses got wrong: the script's own error
        here = os.path.abspath(script)
        line = next((f.tb_lineno for f in _frames(e.__traceback__)
                     if os.path.abspath(f.tb_frame.f_code.co_filename) == here), None)
        where = script if line is None else f"{script}:{line}"
        raise UserError(f"{where}: the script imports {missing}, which is not installed "
                        f"(pip install {PIP_NAMES.get(missing, missing)})") from e


def _not_installed(e: ModuleNotFoundError) -> str | None:
    """The top-level package a ModuleNotFoundError says is missing, when it is not installed at all (a
    PyReason module tracelab lacks is not such a package: the finder's own message says what it is)."""
    top = (e.name or "").partition(".")[0]
    if not top or top == "pyreason" or top in sys.modules:
        return None
    return top if importlib.util.find_spec(top) is None else None


def _frames(tb: types.TracebackType | None) -> list[types.TracebackType]:
    out = []
    while tb is not None:
        out.append(tb)
        tb = tb.tb_next
    return out
