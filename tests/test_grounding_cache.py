"""The grounding cache (engine/grounding_cache.py): a declared world built from a cache entry is the world
grounded cold (the same atoms, groundings and trace rows of seeded steps), and an entry that is not what a
close makes (cut short, another dtype, an id out of range, a giant declared shape, an atom that is not its
clause) is refused in one warning and grounded again, never used; a cache folder that cannot be used
leaves the build as it was."""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np
import pytest

import tracelab
from tracelab.engine import compile_cache, grounding_cache
from tracelab.engine.array_file import MAGIC, read_arrays, write_arrays
from tracelab.engine.grounding_cache import ARRAYS, FILE_CAP, cache_folder
from tracelab.engine.notices import showing_notices
from tracelab.envs.declared.spec import WorldSpec, load_spec
from tracelab.envs.declared.world import DeclaredWorld

WAR = Path(tracelab.__file__).resolve().parents[1] / "rules" / "gridworld" / "war.toml"


@pytest.fixture(scope="module")
def spec() -> WorldSpec:
    return load_spec(WAR)


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv(compile_cache.CACHE_ENV, str(tmp_path / "cache"))
    return cache_folder()


def played(spec: WorldSpec) -> str:
    """A digest of a world's build and of five seeded steps: its vocabulary, groundings and trace rows."""
    world = DeclaredWorld(spec, trace=True)
    rng = np.random.default_rng(7)
    world.reset(rng)
    for step in range(5):
        world.step(step % len(spec.action_names), rng)
    eng = world.engine
    h = hashlib.sha256(json.dumps([eng.vocab.nodes, eng.vocab.labels]).encode())
    for a in (eng.vocab.atom_label, eng.vocab.atom_arg0, eng.vocab.atom_arg1, eng.grounder.g_rule,
              eng.grounder.table().body_atoms, eng.grounder.table().var_values,
              eng.grounder.settable_mask(eng.vocab.n_atoms)):
        h.update(np.ascontiguousarray(a).tobytes())
    for name, column in sorted(eng.take_trace().items()):
        h.update(name.encode() + np.ascontiguousarray(column).tobytes())
    return h.hexdigest()


def entries(folder: Path) -> dict[str, int]:
    """Each entry's file name and inode (a hit reads an entry; a miss writes a new file)."""
    return {p.name: p.stat().st_ino for p in sorted(folder.iterdir())}


def test_a_world_from_the_cache_is_the_world_grounded_cold(spec: WorldSpec, cache: Path, tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    first = played(spec)  # grounds, and writes the entries
    written = entries(cache)
    assert written and all(name.endswith(".grounding") for name in written)
    assert played(spec) == first
    assert entries(cache) == written  # read, not written again
    # a cache folder that cannot be made (its root is a file): grounded cold, the same world, no failure
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("")
    monkeypatch.setenv(compile_cache.CACHE_ENV, str(blocker))
    assert played(spec) == first


def _largest(folder: Path) -> Path:
    return max(folder.iterdir(), key=lambda p: p.stat().st_size)


def _rewritten(path: Path, **changed: np.ndarray) -> None:
    fields, arrays = read_arrays(path, FILE_CAP, ARRAYS)
    write_arrays(path, fields, {**arrays, **changed})


def _out_of_range(path: Path) -> None:
    fields, arrays = read_arrays(path, FILE_CAP, ARRAYS)
    body = arrays["body"].copy()
    body[0, 0] = 1 << 30
    _rewritten(path, body=body)


def _another_dtype(path: Path) -> None:
    _, arrays = read_arrays(path, FILE_CAP, ARRAYS)
    _rewritten(path, rule=arrays["rule"].astype(np.int64))


def _not_its_clause(path: Path) -> None:
    """Every id in range, but a grounding's first body atom swapped for another grounding's."""
    _, arrays = read_arrays(path, FILE_CAP, ARRAYS)
    body = arrays["body"].copy()
    body[0, 0], body[-1, 0] = body[-1, 0], body[0, 0]
    _rewritten(path, body=body)


def _giant_shape(path: Path) -> None:
    data = path.read_bytes()
    size = int.from_bytes(data[len(MAGIC):len(MAGIC) + 8], "little")
    header = json.loads(data[len(MAGIC) + 8:len(MAGIC) + 8 + size])
    header["arrays"]["vals"]["shape"] = [1 << 40, 1 << 20]
    new = json.dumps(header).encode()
    path.write_bytes(MAGIC + len(new).to_bytes(8, "little") + new + data[len(MAGIC) + 8 + size:])


def _truncated(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[:len(data) // 2])


def _bigger_than_the_cap(path: Path) -> None:
    with open(path, "r+b") as f:
        f.truncate(FILE_CAP + 1)  # sparse: refused by its size, never read


@pytest.mark.parametrize("corrupt", [_truncated, _another_dtype, _out_of_range, _not_its_clause, _giant_shape,
                                     _bigger_than_the_cap])
def test_a_corrupt_entry_is_refused_and_grounded_again(corrupt, spec: WorldSpec, cache: Path) -> None:
    first = played(spec)
    entry = _largest(cache)
    corrupt(entry)
    said: list[tuple[bool, str]] = []
    with showing_notices(lambda warning, text: said.append((warning, text))):
        assert played(spec) == first
    assert [w for w, text in said if "grounding cache" in text and str(entry) in text] == [True]
    read_arrays(entry, FILE_CAP, ARRAYS)  # written again, whole
    kept = entries(cache)
    assert played(spec) == first
    assert entries(cache) == kept


def test_a_link_in_place_of_an_entry_is_not_read(spec: WorldSpec, cache: Path, tmp_path: Path) -> None:
    first = played(spec)
    entry = _largest(cache)
    elsewhere = tmp_path / "elsewhere"
    os.replace(entry, elsewhere)
    entry.symlink_to(elsewhere)
    assert played(spec) == first
    assert not entry.is_symlink()  # refused, removed and written again


def test_the_folder_keeps_the_recently_used_entries_within_its_bounds(spec: WorldSpec, cache: Path) -> None:
    played(spec)  # writes war.toml's entries
    ours = set(entries(cache))
    cache.joinpath("notes.txt").write_text("not the cache's")  # another file: never looked at
    for i in range(6):  # older strangers' entries, oldest first
        old = cache / f"{i:032x}{grounding_cache.SUFFIX}"
        old.write_bytes(b"x" * 1000)
        os.utime(old, ns=(10**18 + i, 10**18 + i))
    for mine in ours:  # the hit below touches our entries: make them the oldest before it
        os.utime(cache / mine, ns=(10**17, 10**17))
    played(spec)  # a hit: our entries are used now
    newest = cache / f"{'f' * 32}{grounding_cache.SUFFIX}"
    newest.write_bytes(b"y" * 1000)
    grounding_cache.prune(cache, keep=newest, max_entries=len(ours) + 3)
    left = set(entries(cache))
    assert ours <= left and newest.name in left and "notes.txt" in left
    assert left - ours - {newest.name, "notes.txt"} == {f"{i:032x}{grounding_cache.SUFFIX}" for i in (4, 5)}
    grounding_cache.prune(cache, keep=newest, max_bytes=1500)  # bytes: all but the entry just written
    assert set(entries(cache)) == {newest.name, "notes.txt"}
