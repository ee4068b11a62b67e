# SPDX-License-Identifier: GPL-3.0-or-later
"""One file, one ``blender -b -c eegt`` process: start it, watch its time, kill it, read its
report. The local pool drives many of these; a Dask task runs one to the end.

Standard library only and self-contained: Dask sends this module's functions to its workers
by value (a worker is a plain Python without Blender or this extension).

A task is a dict: ``index``, ``input``, ``output`` (None: nothing written), ``args`` (the
single-file flags), ``timeout`` (seconds or None) and ``blender`` (the binary the client
uses). The result is a dict: the task's ``index``/``input``/``output``, ``status`` (ok,
failed, error, timeout, crashed, cancelled), ``exit_code``, ``seconds``, ``message``,
``host``, ``pid``, ``report`` (the single-file JSON report, or None) and ``log`` (the
process's last lines when it did not end well).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from typing import Any

STATUS_OF_CODE = {0: "ok", 3: "failed", 2: "error", 1: "error"}
LOG_LINES = 12
# Blender's answer when no "eegt" command is registered (extension missing or disabled).
NO_COMMAND = 'Unrecognized command: "eegt"'
# Threads of the numeric libraries in a worker: parallelism is across files.
ONE_THREAD = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def find_blender(preferred: str | None) -> tuple[str | None, str]:
    """The Blender binary to run on this machine and, when there is none, why: $EEGT_BLENDER
    if set, else `preferred` (the client's) if it exists here, else ``blender`` on PATH."""
    env = os.environ.get("EEGT_BLENDER")
    if env:
        ok = os.path.isfile(env) and os.access(env, os.X_OK)
        return (env, "") if ok else (None, f"EEGT_BLENDER={env} is not an executable file")
    if preferred and os.path.isfile(preferred) and os.access(preferred, os.X_OK):
        return preferred, ""
    found = shutil.which("blender")
    if found:
        return found, ""
    return None, (f"no Blender binary (looked for {preferred or 'the client binary'}, "
                  "$EEGT_BLENDER and blender on PATH)")


def command(blender: str, task: dict[str, Any], report: str) -> list[str]:
    """The single-file command line of one task."""
    cmd = [blender, "-b", "-c", "eegt", task["input"]]
    if task.get("output"):
        cmd += ["-o", task["output"]]
    return [*cmd, "--report", report, "--quiet", *task.get("args", ())]


def _die_with_parent() -> Any:
    """A preexec function that makes the child get SIGKILL when its parent dies (Linux), so
    that a batch killed hard leaves no worker running; None elsewhere."""
    if not sys.platform.startswith("linux"):
        return None
    import ctypes
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    parent = os.getpid()

    def preexec() -> None:
        prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        if os.getppid() != parent:  # the parent died before prctl took effect
            os._exit(1)
    return preexec


def _result(task: dict[str, Any], **kw: Any) -> dict[str, Any]:
    res = {"index": task.get("index"), "input": task["input"], "output": task.get("output"),
           "status": "error", "exit_code": None, "seconds": 0.0, "message": "",
           "host": socket.gethostname(), "pid": None, "report": None, "log": ""}
    res.update(kw)
    return res


def precheck(task: dict[str, Any]) -> str | None:
    """What is wrong on this machine before starting Blender: the input missing (inputs and
    outputs must be on storage every worker sees) or the output folder not creatable."""
    host = socket.gethostname()
    if not os.path.exists(task["input"]):
        return (f"eegt: input '{task['input']}' not found on {host} (with --dask, inputs and "
                "outputs must be on storage every worker sees)")
    out = task.get("output")
    if out:
        try:
            os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
        except OSError as exc:
            return (f"eegt: cannot create the output folder of '{out}' on {host}: "
                    f"{(exc.strerror or str(exc)).lower()}")
    return None


class Run:
    """One running single-file process; `poll` gives its result once it has ended."""

    def __init__(self, task: dict[str, Any], blender: str, workdir: str,
                 env: dict[str, str] | None = None) -> None:
        self.task = task
        tag = f"{task.get('index', 0)}"
        self.report_path = os.path.join(workdir, f"{tag}.json")
        self.log_path = os.path.join(workdir, f"{tag}.log")
        self.timeout = task.get("timeout")
        e = dict(os.environ if env is None else env)
        for name in ONE_THREAD:
            e.setdefault(name, "1")
        kw: dict[str, Any] = {}
        if os.name == "posix":
            kw["start_new_session"] = True  # its own process group: killed as a whole
            kw["preexec_fn"] = _die_with_parent()
        else:
            kw["creationflags"] = getattr(subprocess, "CREATE_NEW_PROCESS_GROUP", 0)
        self.started = time.monotonic()
        with open(self.log_path, "wb") as log:
            self.proc = subprocess.Popen(command(blender, task, self.report_path),
                                         stdin=subprocess.DEVNULL, stdout=log,
                                         stderr=subprocess.STDOUT, env=e, **kw)
        self.result: dict[str, Any] | None = None

    @property
    def pid(self) -> int:
        return self.proc.pid

    def poll(self) -> dict[str, Any] | None:
        """The result once the process has ended (killed when past its timeout), else None."""
        if self.result is not None:
            return self.result
        code = self.proc.poll()
        elapsed = time.monotonic() - self.started
        if code is None:
            if self.timeout is not None and elapsed > self.timeout:
                self.kill("timeout", f"timed out after {self.timeout:g} s (worker killed)")
            return self.result
        self.result = self._finished(code, elapsed)
        return self.result

    def wait(self, step: float = 0.1) -> dict[str, Any]:
        """Poll until the process has ended."""
        while self.poll() is None:
            time.sleep(step)
        assert self.result is not None
        return self.result

    def kill(self, status: str, message: str) -> dict[str, Any]:
        """Kill the process (and anything it started), remove its temporary files; the
        result says `status` (timeout or cancelled)."""
        if self.proc.poll() is None:
            try:
                if os.name == "posix":
                    os.killpg(self.proc.pid, signal.SIGKILL)
                else:
                    self.proc.kill()
            except (ProcessLookupError, PermissionError):
                pass
        self.proc.wait()
        self._remove_temporaries()
        elapsed = time.monotonic() - self.started
        report = self._report()
        if report is not None and report.get("exit_code") is not None:
            # the command had finished (output and report in place), Blender was exiting
            self.result = self._from_report(int(report["exit_code"]), report, elapsed)
        else:
            self.result = _result(self.task, status=status, message=message,
                                  seconds=round(elapsed, 3), pid=self.proc.pid,
                                  log=self._log_tail())
        return self.result

    def _report(self) -> dict[str, Any] | None:
        """The single-file report, once the command has put it in place."""
        try:
            with open(self.report_path, encoding="utf-8") as fh:
                report = json.load(fh)
        except (OSError, ValueError):
            return None
        return report if isinstance(report, dict) else None

    def _remove_temporaries(self) -> None:
        """The output's temporary files this process may have left (it was killed while
        writing): ``.NAME.eegt-tmp-PID.EXT`` beside the output, and Blender's ``@`` file."""
        out = self.task.get("output")
        if not out:
            return
        real = os.path.realpath(out)
        folder, name = os.path.dirname(real), os.path.basename(real)
        prefix = f".{name}.eegt-tmp-{self.proc.pid}"
        try:
            names = os.listdir(folder)
        except OSError:
            return
        for n in names:
            if n.startswith(prefix):
                try:
                    os.remove(os.path.join(folder, n))
                except OSError:
                    pass

    def _log_tail(self) -> str:
        try:
            with open(self.log_path, "rb") as fh:
                fh.seek(max(0, os.path.getsize(self.log_path) - 16384))
                text = fh.read().decode("utf-8", "replace")
        except OSError:
            return ""
        lines = [ln.rstrip() for ln in text.splitlines() if ln.strip()]
        return "\n".join(lines[-LOG_LINES:])

    def _finished(self, code: int, elapsed: float) -> dict[str, Any]:
        report = self._report()
        log = self._log_tail()
        kw: dict[str, Any] = {"exit_code": code, "seconds": round(elapsed, 3),
                              "pid": self.proc.pid, "report": report}
        if code < 0:  # killed by a signal that was not ours
            self._remove_temporaries()
            name = _signal_name(-code)
            why = " (out of memory?)" if -code == signal.SIGKILL else ""
            return _result(self.task, status="crashed", log=log,
                           message=f"Blender was killed by {name}{why}", **kw)
        if report is None:
            self._remove_temporaries()
            if NO_COMMAND in log:
                msg = (f"the eegt_blender extension is not installed or not enabled for "
                       f"{self.proc.args[0]} on {socket.gethostname()}")
            else:
                last = log.splitlines()[-1] if log else "no output"
                msg = f"Blender exited with code {code} and no report: {last}"
            return _result(self.task, status="crashed" if code not in STATUS_OF_CODE
                           else "error", log=log, message=msg, **kw)
        return self._from_report(code, report, elapsed)

    def _from_report(self, code: int, report: dict[str, Any], elapsed: float
                     ) -> dict[str, Any]:
        status = STATUS_OF_CODE.get(code, "error")
        return _result(self.task, status=status, exit_code=code, seconds=round(elapsed, 3),
                       pid=self.proc.pid, report=report, message=_message(report, status),
                       log="" if status == "ok" else self._log_tail())


def _signal_name(num: int) -> str:
    try:
        return signal.Signals(num).name
    except ValueError:
        return f"signal {num}"


def _message(report: dict[str, Any], status: str) -> str:
    """The one line that says what went wrong with a file (empty when it went well)."""
    if report.get("error"):
        return str(report["error"])
    bad = [o for o in report.get("objects", []) if o.get("status") not in ("valid", "untangled")]
    return "; ".join(f"{o.get('object')}: {o.get('status')}: {o.get('message')}"
                     for o in bad) if status != "ok" else ""


def run_task(task: dict[str, Any]) -> dict[str, Any]:
    """Run one task to its end on this machine (what a Dask worker executes)."""
    problem = precheck(task)
    if problem:
        return _result(task, message=problem, exit_code=2)
    blender, why = find_blender(task.get("blender"))
    if blender is None:
        return _result(task, message=f"eegt: {why} on {socket.gethostname()}", exit_code=2)
    workdir = tempfile.mkdtemp(prefix="eegt-task-")
    try:
        return Run(task, blender, workdir).wait()
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
