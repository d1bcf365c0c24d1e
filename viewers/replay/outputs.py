"""Where the recordings go: an .rrd file (one recording per episode; several are merged into one file by
rerun's own `rerun rrd merge`), a gRPC server with the web viewer (--serve), or a spawned native viewer
(--spawn)."""
from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import rerun as rr
from tracelab.viewers.replay.recording import APPLICATION_ID, new_recording


def rerun_cli() -> str:
    """The `rerun` executable shipped with the installed rerun-sdk (the same version as the SDK)."""
    try:
        # deferred: imported under try: without the package, the `rerun` on PATH is used
        import rerun_cli
        exe = Path(rerun_cli.__file__).parent / "rerun"
        if exe.exists():
            return str(exe)
    except ImportError:
        pass
    found = shutil.which("rerun")
    if found is None:
        raise RuntimeError("rerun's command-line tool was not found (it ships with rerun-sdk)")
    return found


class SaveOutput:
    """Recordings saved into one .rrd file. Each episode is first written to its own file in a
    temporary directory; `write()` puts them together at `path` (temp name, then rename)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if self.path.is_dir():
            raise IsADirectoryError(f"{self.path} is a directory; give a .rrd file name")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmp = tempfile.TemporaryDirectory(prefix="tracelab-replay-")
        self.files: list[Path] = []
        self.blueprint_sent = False

    def recording(self, run_name: str, episode: int) -> rr.RecordingStream:
        rec = new_recording(run_name, episode)
        file = Path(self._tmp.name) / f"episode-{episode}-{len(self.files)}.rrd"
        rec.save(file)
        self.files.append(file)
        return rec

    def finished(self, rec: rr.RecordingStream) -> None:
        rec.flush()
        rec.disconnect()

    def write(self) -> None:
        """The recordings so far, as one file at `path`."""
        if not self.files:
            return
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        if len(self.files) == 1:
            shutil.copyfile(self.files[0], tmp)
        else:
            done = subprocess.run([rerun_cli(), "rrd", "merge", "-o", str(tmp), *map(str, self.files)],
                                  capture_output=True, text=True, check=False)
            if done.returncode != 0:
                tmp.unlink(missing_ok=True)
                raise RuntimeError(f"rerun rrd merge failed: {done.stderr.strip()[-500:]}")
        tmp.replace(self.path)

    def close(self) -> None:
        self.write()
        self._tmp.cleanup()

    def describe(self) -> str:
        return f"wrote {len(self.files)} recording(s) to {self.path}  (open it with: rerun {self.path})"


class GrpcOutput:
    """Recordings streamed over gRPC: to a server this process hosts, with the web viewer (serve), or to
    a native viewer spawned for them (spawn)."""

    def __init__(self, mode: str, port: int = 9876, web_port: int = 9090) -> None:
        self.mode = mode
        self.count = 0
        self.blueprint_sent = False
        if mode == "serve":
            self._hub = rr.RecordingStream(APPLICATION_ID, recording_id="tracelab-replay-server")
            self.url = self._hub.serve_grpc(grpc_port=port)
            rr.serve_web_viewer(web_port=web_port, open_browser=False, connect_to=self.url)
            self.web_url = f"http://localhost:{web_port}/?url={self.url}"
        elif mode == "spawn":
            rr.spawn(port=port, connect=False)
            self.url = f"rerun+http://127.0.0.1:{port}/proxy"
        else:
            raise ValueError(f"unknown output mode {mode!r}")

    def recording(self, run_name: str, episode: int) -> rr.RecordingStream:
        rec = new_recording(run_name, episode)
        rec.connect_grpc(self.url)
        self.count += 1
        return rec

    def finished(self, rec: rr.RecordingStream) -> None:
        rec.flush()

    def write(self) -> None:
        pass

    def close(self) -> None:
        pass

    def describe(self) -> str:
        where = self.web_url if self.mode == "serve" else self.url
        return f"sent {self.count} recording(s) to {where}"


Output = SaveOutput | GrpcOutput
