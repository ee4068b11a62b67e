# SPDX-License-Identifier: GPL-3.0-or-later
"""The same per-file tasks on a Dask distributed cluster (``--dask ADDRESS``), or on a
``LocalCluster`` of N worker processes (``--dask local:N``).

Each task runs ``batch.worker.run_chunk`` on a Dask worker: the single-file command in that
machine's Blender (for one file, or for ``--files-per-worker`` files in one Blender), on
inputs and outputs every worker sees (shared storage). Dask workers are plain Python
processes without this extension, so the worker module is uploaded to them.

Dask is optional: it is imported only here, and its absence is a one-line error.
"""

from __future__ import annotations

import contextlib
import importlib.util
import logging
import os
import shutil
import socket
import sys
import tempfile
import time
import types
import urllib.parse
import uuid
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from . import worker
from .pool import by_size, cancelled

Result = dict[str, Any]
POLL = 0.1
TASK_MODULE = "eegt_batch_worker"
# Seconds to open a connection to a scheduler's port (nothing listening: refused at once; a
# host that does not answer: this long), then to complete Dask's handshake with it.
CONNECT_TIMEOUT = 3.0
HANDSHAKE_TIMEOUT = 10.0
# Address schemes whose scheduler listens on a TCP port that can be tried first.
TCP_SCHEMES = ("tcp", "tls", "ws", "wss")


class DaskError(Exception):
    """Dask missing, a bad address or no connection: one line, exit code 2."""


def install_hint() -> str:
    """How to install Dask for the Python this Blender runs: pip into Blender's user
    ``scripts/modules`` folder, which Blender puts on sys.path (it ignores PYTHONPATH)."""
    return ("install them for Blender's Python: blender -b --python-expr \"import bpy, "
            "subprocess, sys; subprocess.check_call([sys.executable, '-m', 'pip', 'install', "
            "'--target', bpy.utils.user_resource('SCRIPTS', path='modules', create=True), "
            "'dask[distributed]'])\" (a Linux distribution's Blender: its python3-dask and "
            "python3-distributed packages; see docs/batch.md)")


def require() -> Any:
    """The ``distributed`` module, or DaskError saying how to install it."""
    try:
        import distributed
    except ImportError as exc:
        raise DaskError(f"eegt: --dask needs the dask and distributed packages "
                        f"({exc.name or exc} is missing in {sys.executable}); "
                        f"{install_hint()}") from None
    return distributed


def parse_address(address: str) -> tuple[str, int | None]:
    """``("local", N)`` for ``local`` / ``local:N`` (N: None = one per core), else
    ``("remote", None)``."""
    if address == "local" or address.startswith("local:"):
        n = address.partition(":")[2]
        if not n:
            return "local", None
        if not n.isdigit() or int(n) < 1:
            raise DaskError(f"eegt: --dask {address}: local:N needs a whole number N >= 1")
        return "local", int(n)
    if not address.strip():
        raise DaskError("eegt: --dask needs a scheduler address (tcp://HOST:8786) or local:N")
    return "remote", None


def probe(address: str, timeout: float = CONNECT_TIMEOUT) -> None:
    """Open and close a TCP connection to a remote scheduler's port, so that a wrong
    address is one line within `timeout` seconds (DaskError) rather than after Dask's own
    retries; addresses of other transports are left to Dask."""
    scheme, sep, _ = address.partition("://")
    if sep and scheme not in TCP_SCHEMES:
        return
    parts = urllib.parse.urlsplit(address if sep else "tcp://" + address)
    try:
        host, port = parts.hostname, parts.port
    except ValueError:
        host, port = None, None
    if not host or port is None:
        raise DaskError(f"eegt: --dask {address}: a scheduler address is tcp://HOST:PORT "
                        "(its port is 8786 unless it was started with another)")
    try:
        socket.create_connection((host, port), timeout=timeout).close()
    except OSError as exc:
        why = f"no answer in {timeout:g} s" if isinstance(exc, TimeoutError) else \
            (exc.strerror or str(exc)).lower()
        raise DaskError(f"eegt: cannot connect to the Dask scheduler at {address}: {why} "
                        "(is `dask scheduler` running there?)") from None


@contextlib.contextmanager
def plain_main() -> Iterator[None]:
    """An empty ``__main__`` module while a local cluster lives: its worker processes are
    started by multiprocessing's spawn, which would otherwise run the parent's main script
    again in each of them (in Blender, the script that started the batch)."""
    saved = sys.modules.get("__main__")
    sys.modules["__main__"] = types.ModuleType("__main__")
    try:
        yield
    finally:
        if saved is not None:
            sys.modules["__main__"] = saved


def connect(address: str, default_workers: int) -> tuple[Any, Any]:
    """A connected ``Client`` and the ``LocalCluster`` it owns (None for a remote one);
    a local cluster must be started and closed inside ``plain_main()``."""
    distributed = require()
    kind, n = parse_address(address)
    cluster = None
    try:
        if kind == "local":
            # one thread per worker: each task runs one Blender at a time
            cluster = distributed.LocalCluster(
                n_workers=n or default_workers, threads_per_worker=1, processes=True,
                dashboard_address=None, silence_logs=logging.ERROR, memory_limit=0)
            return distributed.Client(cluster), cluster
        probe(address)
        return distributed.Client(address, timeout=f"{HANDSHAKE_TIMEOUT:g}s"), None
    except Exception as exc:
        if cluster is not None:
            cluster.close()
        what = "start a local Dask cluster" if kind == "local" else \
            f"connect to the Dask scheduler at {address}"
        raise DaskError(f"eegt: cannot {what}: {str(exc).splitlines()[0] if str(exc) else exc!r}"
                        ) from None


def ship_worker(client: Any) -> Callable[..., list[Result]]:
    """Send ``batch/worker.py`` to the scheduler and every worker (those joining later
    too) as the module ``eegt_batch_worker``, and return its ``run_chunk`` loaded here from
    the same file: a task then names its function by that module, which every worker can
    import (this package cannot be imported outside Blender)."""
    folder = tempfile.mkdtemp(prefix="eegt-dask-")
    try:
        path = os.path.join(folder, TASK_MODULE + ".py")
        shutil.copyfile(worker.__file__, path)
        spec = importlib.util.spec_from_file_location(TASK_MODULE, path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        sys.modules[TASK_MODULE] = module
        client.upload_file(path)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return module.run_chunk


def run_dask(client: Any, tasks: Sequence[dict[str, Any]],
             on_result: Callable[[Result], None], stop: Callable[[], bool],
             tick: Callable[[], None] | None = None, per_worker: int = 1) -> bool:
    """Submit the tasks (largest input first; `per_worker` files per Dask task, run by one
    Blender), hand each file's result to `on_result` as its task completes; when `stop()`
    turns true, cancel what is left (reported cancelled). Returns whether it was stopped."""
    from distributed import as_completed

    run_chunk = ship_worker(client)
    workers = len(client.scheduler_info().get("workers", {}))
    chunks = chunked(by_size(tasks), per_worker, workers)
    run_id = uuid.uuid4().hex[:8]
    futures = {}
    for rank, chunk in enumerate(chunks):
        fut = client.submit(run_chunk, chunk, per_worker, pure=False,
                            key=f"eegt-{run_id}-{chunk[0]['index']}",
                            priority=len(chunks) - rank)
        futures[fut.key] = (fut, chunk)
    pending = as_completed([f for f, _ in futures.values()])
    left = dict(futures)
    while left:
        if stop():
            client.cancel([f for f, _ in left.values()])
            for _, chunk in left.values():
                for task in chunk:
                    on_result(cancelled(task, "interrupted before its result came back"))
            return True
        for fut in pending.next_batch(block=False):
            _, chunk = left.pop(fut.key)
            for res in _outcome(fut, chunk):
                on_result(res)
        if tick is not None:
            tick()
        if left:
            time.sleep(POLL)
    return False


def chunked(ordered: list[dict[str, Any]], per_worker: int, workers: int
            ) -> list[list[dict[str, Any]]]:
    """Tasks (largest first) dealt round-robin into chunks of at most `per_worker`, at
    least one chunk per worker while there are files enough (a chunk runs in one Blender,
    one file after the other, so small chunks keep every worker busy)."""
    if per_worker <= 1 or not ordered:
        return [[t] for t in ordered]
    n = max(-(-len(ordered) // per_worker), min(max(workers, 1), len(ordered)))
    return [ordered[i::n] for i in range(n)]


def _outcome(fut: Any, chunk: list[dict[str, Any]]) -> list[Result]:
    """A finished future's results, or error results saying why the task itself failed
    (a worker lost, a task that could not be sent)."""
    if fut.status == "finished":
        return fut.result()
    try:
        exc = fut.exception()
    except Exception as err:  # cancelled futures raise here
        exc = err
    results = []
    for task in chunk:
        res = cancelled(task, f"the Dask task failed: {exc!r}"[:500])
        res.update(status="error", exit_code=1)
        results.append(res)
    return results
