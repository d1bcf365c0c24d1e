"""Ray for the length of one command (experiment --ray, sweep): connect to a cluster by address, or start a
local Ray limited to this machine's cores; Ray's own logs and dashboard stay off the user's terminal.

Ray is the optional `ray` extra (pip install 'tracelab[ray]'). Ray keeps its session files (logs, sockets,
object spilling) in its temp dir, which the user chooses the usual Ray way (RAY_TMPDIR, or TMPDIR on
Linux); tracelab never overrides it (docs/scaling.md)."""
from __future__ import annotations

import logging
import os
import socket
from collections.abc import Iterator
from contextlib import contextmanager
from types import ModuleType

from tracelab.errors import UserError

INSTALL_HINT = "Ray is not installed: pip install 'tracelab[ray]' (or pip install 'ray[tune]')"
LOCAL = "local"  # Ray's own address for "start a new local Ray for this process"
CONNECT_TIMEOUT_S = 5.0  # Ray itself retries an address where nothing answers for minutes


def import_ray() -> ModuleType:
    """The ray module, or a UserError saying how to install it."""
    try:
        # deferred: Ray is an optional extra (tracelab[ray])
        import ray
    except ImportError:
        raise UserError(INSTALL_HINT) from None
    return ray


def machine_cores() -> int:
    """The cores this process may run on (its affinity, not the machine's total)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


@contextmanager
def ray_session(address: str = LOCAL) -> Iterator[ModuleType]:
    """`with ray_session(address) as ray:` Ray initialised for the block and shut down after it (a local
    Ray started here stops with it; a cluster keeps running). A cluster that cannot be reached is a
    UserError naming the address."""
    ray = check_address(address)
    quiet = {"log_to_driver": False, "logging_level": logging.ERROR}  # workers' output stays in Ray's logs
    try:
        if address == LOCAL:
            ray.init(address=LOCAL, num_cpus=machine_cores(), include_dashboard=False, **quiet)
        else:
            ray.init(address=address, **quiet)
    except (ConnectionError, ValueError, RuntimeError) as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        if address == LOCAL:
            raise UserError(f"could not start a local Ray ({first})") from None
        raise UserError(f"--ray {address}: could not join the Ray cluster there ({first}; a cluster with token "
                        f"authentication needs RAY_AUTH_MODE=token and its token, docs/scaling.md)") from None
    try:
        yield ray
    finally:
        ray.shutdown()


def check_address(address: str) -> ModuleType:
    """Before anything starts: Ray is installed, and a cluster's address answers. Returns the ray module."""
    ray = import_ray()
    if address not in (LOCAL, "auto"):
        check_reachable(address)
    return ray


def check_reachable(address: str) -> None:
    """HOST:PORT (or ray://HOST:PORT) answers a TCP connection within CONNECT_TIMEOUT_S, else a UserError
    naming it (ray.init would retry it for minutes, printing warnings)."""
    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not host or not port.isdigit():
        raise UserError(f"--ray {address}: expected HOST:PORT, ray://HOST:PORT, auto, or no address (a local Ray)")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as e:
        raise UserError(f"--ray {address}: no Ray cluster answers there ({e.strerror or e})") from None
