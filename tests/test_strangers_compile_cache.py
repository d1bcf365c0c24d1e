"""The compile cache against files it did not write (engine/compile_cache.py, issue 24 §1): an edited or
malformed kernel.py, a planted numba cache file or bytecode file, another user's folders, and the program
handed to a background compile. Each payload would create a marker file; the tests prove it was not
created and that the run still gives the counting kernel's results.

One real compile of a small program (numba: tens of seconds of CPU) is shared by the module: each test
works on a copy of that cache in its own folder ($TRACELAB_CACHE_DIR). Only the malformed-kernel test
compiles again, through the CLI, because that is what it checks.
"""
from __future__ import annotations

import hashlib
import importlib.util
import marshal
import os
import pickle
import shutil
import stat
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from tracelab.engine import Engine, parse_program
from tracelab.engine import compile_cache as cc
from tracelab.engine import compile_background
from tracelab.engine.backend_compiled import cache_entry

SMALL = """
r1: b(X) <-0 a(X), e(X,Y)
r2: c(Y):[0.2,0.9] <-1 b(X), e(X,Y)
a(n1)
e(n1,n2)
e(n2,n1)
"""
STEPS = 3
STRANGER_UID = 12345


def _run(kernel: str) -> tuple[str, list[dict]]:
    """The kernel that ran and the interpretation after each step."""
    eng = Engine(parse_program(SMALL), kernel=kernel)
    seen = []
    for _ in range(STEPS):
        eng.step()
        seen.append(eng.interpretation(0))
    return eng.kernel, seen


@pytest.fixture(scope="module")
def compiled_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A cache folder ($TRACELAB_CACHE_DIR) holding SMALL's compiled kernel (compiled once per module)."""
    root = tmp_path_factory.mktemp("compiled-once")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(cc.CACHE_ENV, str(root))
        kernel, _ = _run("compiled")
    assert kernel == "compiled"
    return root


@pytest.fixture(scope="module")
def expected() -> list[dict]:
    return _run("counting")[1]


def _reason(folder: Path, kernel: str = "auto") -> subprocess.CompletedProcess:
    """`tracelab reason` of SMALL in a new process (the next run a user makes), with the test's cache."""
    rules = folder / "small.rules"
    rules.write_text(SMALL)
    return subprocess.run([sys.executable, "-m", "tracelab.cli", "reason", str(rules), "--steps", str(STEPS),
                           "--json", "--kernel", kernel], capture_output=True, text=True, timeout=900)


@pytest.fixture(scope="module")
def expected_output(tmp_path_factory: pytest.TempPathFactory) -> str:
    out = _reason(tmp_path_factory.mktemp("counting"), "counting")
    assert out.returncode == 0, out.stderr
    return out.stdout


@pytest.fixture
def entry(compiled_cache: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A copy of the compiled cache for this test (the cache in use); returns the kernel's entry folder."""
    shutil.copytree(compiled_cache, tmp_path / "cache")
    monkeypatch.setenv(cc.CACHE_ENV, str(tmp_path / "cache"))
    (found,) = (tmp_path / "cache" / "compiled").iterdir()
    return found


def _pickle_payload(marker: Path) -> bytes:
    class Payload:
        def __reduce__(self) -> tuple:
            return os.system, (f"touch {marker}",)
    return pickle.dumps(Payload())


def _add_payload(kernel_py: Path, marker: Path) -> None:
    """Edit the cached module: a line that creates `marker` when the module runs (after its
    `from __future__` import, so that the file still compiles)."""
    head, future, rest = kernel_py.read_text().partition("from __future__ import annotations\n")
    assert future
    kernel_py.write_text(f"{head}{future}open({str(marker)!r}, 'w').write('ran')\n{rest}")


def _notices(err: str) -> list[str]:
    assert "Traceback" not in err
    return [line for line in err.splitlines() if line.startswith("tracelab: notice:")]


def _digests(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def test_the_shared_entry_loads_from_the_cache(entry: Path, expected: list[dict]) -> None:
    """The copy is a working cache: auto takes it, and numba loads the machine code (compiles nothing)."""
    eng = Engine(parse_program(SMALL))
    assert eng.kernel == "compiled"
    for want in expected:
        eng.step()
        assert eng.interpretation(0) == want
    step = eng._state.step_kernel
    assert step.stats.cache_hits and not step.stats.cache_misses


def _edit_kernel(entry: Path, marker: Path) -> None:
    _add_payload(entry / "kernel.py", marker)


def _plant_index(entry: Path, marker: Path) -> None:
    (index,) = (entry / "__pycache__").glob("kernel.step_worlds-*.nbi")
    index.write_bytes(_pickle_payload(marker))


def _plant_data(entry: Path, marker: Path) -> None:
    (data,) = (entry / "__pycache__").glob("kernel.step_worlds-*.1.nbc")
    data.write_bytes(_pickle_payload(marker))


def _plant_bytecode(entry: Path, marker: Path) -> None:
    """A bytecode cache of kernel.py that Python's import would take instead of the source (it matches
    the source's time stamp and size)."""
    kernel_py = entry / "kernel.py"
    st = kernel_py.stat()
    code = compile(f"open({str(marker)!r}, 'w').write('ran')", str(kernel_py), "exec")
    header = importlib.util.MAGIC_NUMBER + struct.pack("<III", 0, int(st.st_mtime) & 0xFFFFFFFF, st.st_size)
    (entry / "__pycache__" / f"kernel.{sys.implementation.cache_tag}.pyc").write_bytes(header + marshal.dumps(code))


@pytest.mark.parametrize(("plant", "named"), [(_edit_kernel, "kernel.py differs from the source generated"),
                                              (_plant_index, ".nbi does not match the digest"),
                                              (_plant_data, ".nbc does not match the digest"),
                                              (_plant_bytecode, ".pyc is not a file this kernel's compile wrote")],
                         ids=["kernel.py", "index", "data", "bytecode"])
def test_an_edited_or_planted_cache_file_does_not_run(entry: Path, tmp_path: Path, expected_output: str,
                                                      plant, named: str) -> None:  # noqa: ANN001
    """The next `reason` of the program: the payload does not run, the output is right, one notice says
    which file failed, and the entry is removed so that the next compile rebuilds it."""
    marker = tmp_path / "payload-ran"
    plant(entry, marker)
    out = _reason(tmp_path)
    assert not marker.exists()
    assert out.returncode == 0 and out.stdout == expected_output, out.stderr
    (notice,) = _notices(out.stderr)
    assert "failed its check" in notice and named in notice and "removed it" in notice
    assert not (entry / "kernel.py").exists() and not (entry / "ready.json").exists()


def test_numba_files_of_an_entry_never_marked_ready_are_removed_before_use(entry: Path, tmp_path: Path) -> None:
    """Without ready.json nothing recorded numba's files (a compile that died, or files put there): they
    are gone once the kernel is loaded, before its first call could read them."""
    marker = tmp_path / "planted-payload-ran"
    (entry / "ready.json").unlink()
    _plant_index(entry, marker)
    eng = Engine(parse_program(SMALL), kernel="counting")
    cache_entry(eng).load()
    assert not list((entry / "__pycache__").iterdir()) and not marker.exists()


def test_a_malformed_kernel_py_is_rebuilt_not_a_traceback(entry: Path, tmp_path: Path, expected: list[dict],
                                                           expected_output: str) -> None:
    kernel_py = entry / "kernel.py"
    kernel_py.write_text(kernel_py.read_text()[:5000])  # cut mid-function: a SyntaxError if imported
    out = _reason(tmp_path, "compiled")
    assert out.returncode == 0 and out.stdout == expected_output, out.stderr
    (notice,) = _notices(out.stderr)
    assert "kernel.py differs" in notice and "compiled again now" in notice
    # rebuilt in place: the next run loads it as it is
    assert _run("auto") == ("compiled", expected)


def test_the_cache_folders_are_private(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(cc.CACHE_ENV, str(tmp_path / "new"))
    eng = Engine(parse_program(SMALL), kernel="counting")
    fresh = cache_entry(eng)
    fresh.load()  # writes the generated module (compiles nothing before the first step)
    for folder in (cc.cache_root(), fresh.dir):
        assert stat.S_IMODE(folder.stat().st_mode) == 0o700, folder
    assert stat.S_IMODE(fresh.module_path.stat().st_mode) == 0o600
    # a root made before (0755, as tracelab used to make it) is made private when next used
    monkeypatch.setenv(cc.CACHE_ENV, str(tmp_path / "old"))
    cc.cache_root().mkdir(parents=True)
    os.chmod(cc.cache_root(), 0o755)
    cache_entry(eng).load()
    assert stat.S_IMODE(cc.cache_root().stat().st_mode) == 0o700


def test_an_entry_owned_by_someone_else_is_ignored(entry: Path, tmp_path: Path, expected: list[dict],
                                                   expected_output: str, compiled_cache: Path) -> None:
    marker = tmp_path / "stranger-payload-ran"
    kernel_py = entry / "kernel.py"
    _add_payload(kernel_py, marker)
    for p in (entry, *entry.rglob("*")):
        os.chown(p, STRANGER_UID, STRANGER_UID)
    before = _digests(entry)
    out = _reason(tmp_path)
    assert not marker.exists()
    assert out.returncode == 0 and out.stdout == expected_output, out.stderr  # on the counting kernel
    (notice,) = _notices(out.stderr)
    assert f"{entry} is owned by uid {STRANGER_UID}" in notice and "ignored" in notice
    mine = entry.with_name(f"{entry.name}.uid{os.geteuid()}")
    assert str(mine) in notice
    # this user's kernel lives beside it: once built (here: copied from the shared compile), it is used
    shutil.copytree(compiled_cache / "compiled" / entry.name, mine)
    assert _run("compiled") == ("compiled", expected)
    assert not marker.exists()
    assert _digests(entry) == before  # the stranger's entry is left as it was


def test_a_cache_root_owned_by_someone_else_is_not_used(entry: Path, tmp_path: Path, expected_output: str) -> None:
    marker = tmp_path / "stranger-payload-ran"
    kernel_py = entry / "kernel.py"
    _add_payload(kernel_py, marker)
    os.chown(entry.parent, STRANGER_UID, STRANGER_UID)
    out = _reason(tmp_path, "compiled")
    assert not marker.exists()
    assert out.returncode == 0 and out.stdout == expected_output, out.stderr
    (notice,) = _notices(out.stderr)
    assert f"{entry.parent} is owned by uid {STRANGER_UID}" in notice and "counting kernel" in notice


def test_a_background_compile_gets_its_program_through_a_pipe(entry: Path) -> None:
    """No pickle file is written anywhere for the child (unpickling one that another process replaced
    would run its code): the program goes down the child's stdin. The entry is cached, so the child
    only loads it."""
    program = parse_program(SMALL)
    target = cache_entry(Engine(program, kernel="counting"))
    assert target.dir == entry
    before = set(os.listdir(entry))
    job, new = compile_background.start(program, target)
    try:
        assert new and job.proc.args[-2:] == ["tracelab.engine.compile_job", target.key]
        assert not [name for name in os.listdir(entry) if name not in before and not name.endswith(".log")]
        assert job.wait(timeout=300) == "ready", job.why
        assert job.result["cached"] is True
    finally:
        if job.proc.poll() is None:
            job.proc.kill()
        compile_background._JOBS.pop(target.dir, None)
