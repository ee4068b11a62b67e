# SPDX-License-Identifier: GPL-3.0-or-later
"""One file, one run of the single-file ``eegt`` command in a ``blender -b`` process: start
it, watch its time, kill it, read its report. The local pool drives many of these; a Dask
task runs some to the end.

Two ways to run a file: ``Run`` starts a fresh ``blender -b -c eegt FILE ...`` for it (the
default), ``Server`` keeps one ``blender -b -c eegt --eegt-serve-stdin`` that runs the
single-file command for file after file read from its stdin (``--files-per-worker N``: the
start-up is paid once per N files). Either way a crash, a hang (``timeout``) or a memory
blow-up ends only that process: its current file is reported, and the next file gets a fresh
Blender.

Standard library only and self-contained: Dask workers, which are plain Python processes
without Blender or this extension, receive this file as a module of its own.

A task is a dict: ``index``, ``input``, ``output`` (None: nothing written), ``args`` (the
single-file flags), ``timeout`` (seconds or None) and ``blender`` (the binary the client
uses). A result is a dict: the task's ``index``/``input``/``output``, ``status`` (ok, failed,
error, timeout, crashed, cancelled), ``exit_code``, ``seconds``, ``message``, ``host``,
``pid``, ``report`` (the single-file JSON report, or None) and ``log`` (the process's last
lines when the file did not end well).
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

SERVE_FLAG = "--eegt-serve-stdin"  # `blender -b -c eegt SERVE_FLAG`: a Server's process
STATUS_OF_CODE = {0: "ok", 3: "failed", 2: "error", 1: "error"}
LOG_LINES = 12
# Blender's answer when no "eegt" command is registered (extension missing or disabled).
NO_COMMAND = 'Unrecognized command: "eegt"'
# Threads of the numeric libraries in a worker: parallelism is across files.
ONE_THREAD = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")

Task = dict[str, Any]
Result = dict[str, Any]


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


def file_args(task: Task, report: str) -> list[str]:
    """The single-file command's arguments for one task."""
    args = [task["input"]]
    if task.get("output"):
        args += ["-o", task["output"]]
    return [*args, "--report", report, "--quiet", *task.get("args", ())]


def command(blender: str, task: Task, report: str) -> list[str]:
    """The single-file command line of one task."""
    return [blender, "-b", "-c", "eegt", *file_args(task, report)]


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


def _spawn(cmd: list[str], log_path: str, env: dict[str, str] | None,
           stdin: Any = subprocess.DEVNULL) -> subprocess.Popen:
    """Start a Blender in its own process group (killed as a whole), output to a log file,
    numeric libraries on one thread."""
    e = dict(os.environ if env is None else env)
    for name in ONE_THREAD:
        e.setdefault(name, "1")
    kw: dict[str, Any] = {}
    if os.name == "posix":
        kw["start_new_session"] = True
        kw["preexec_fn"] = _die_with_parent()
    else:
        kw["creationflags"] = getattr(subprocess, "CREATE_NEW_PROCESS_GROUP", 0)
    with open(log_path, "ab") as log:
        return subprocess.Popen(cmd, stdin=stdin, stdout=log, stderr=subprocess.STDOUT,
                                env=e, **kw)


def _kill(proc: subprocess.Popen) -> None:
    """SIGKILL the process and its group; wait for it."""
    if proc.poll() is None:
        try:
            if os.name == "posix":
                os.killpg(proc.pid, signal.SIGKILL)
            else:
                proc.kill()
        except (ProcessLookupError, PermissionError):
            pass
    proc.wait()


def _remove_temporaries(output: str | None, pid: int) -> None:
    """The output's temporary files a killed process `pid` may have left:
    ``.NAME.eegt-tmp-PID.EXT`` beside the output, and Blender's ``@`` file."""
    if not output:
        return
    real = os.path.realpath(output)
    folder, name = os.path.dirname(real), os.path.basename(real)
    prefix = f".{name}.eegt-tmp-{pid}"
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


def _log_tail(path: str, start: int = 0) -> str:
    """The last lines of a log from byte `start` on."""
    try:
        size = os.path.getsize(path)
        with open(path, "rb") as fh:
            fh.seek(max(start, size - 16384))
            text = fh.read().decode("utf-8", "replace")
    except OSError:
        return ""
    lines = [ln.rstrip() for ln in text.splitlines() if ln.strip()]
    return "\n".join(lines[-LOG_LINES:])


def _read_report(path: str) -> dict[str, Any] | None:
    """A single-file report once the command has put it in place (it is renamed into place
    last, so it exists only whole)."""
    try:
        with open(path, encoding="utf-8") as fh:
            report = json.load(fh)
    except (OSError, ValueError):
        return None
    return report if isinstance(report, dict) and report.get("exit_code") is not None \
        else None


def _result(task: Task, **kw: Any) -> Result:
    res = {"index": task.get("index"), "input": task["input"], "output": task.get("output"),
           "status": "error", "exit_code": None, "seconds": 0.0, "message": "",
           "host": socket.gethostname(), "pid": None, "report": None, "log": ""}
    res.update(kw)
    return res


def _stamp(result: Result | None, clock: float) -> Result | None:
    """The result with the time its file started (seconds since the epoch)."""
    if result is not None:
        result.setdefault("started", round(clock, 3))
    return result


def _from_report(task: Task, report: dict[str, Any], elapsed: float, pid: int,
                 log: str) -> Result:
    code = int(report["exit_code"])
    status = STATUS_OF_CODE.get(code, "error")
    return _result(task, status=status, exit_code=code, seconds=round(elapsed, 3), pid=pid,
                   report=report, message=_message(report, status),
                   log="" if status == "ok" else log)


def _from_exit(task: Task, code: int, elapsed: float, pid: int, log: str,
               blender: str) -> Result:
    """The result of a process that ended (or died) without a report."""
    kw: dict[str, Any] = {"exit_code": code, "seconds": round(elapsed, 3), "pid": pid,
                          "log": log}
    if code < 0:  # killed by a signal that was not ours
        why = " (out of memory?)" if -code == signal.SIGKILL else ""
        return _result(task, status="crashed",
                       message=f"Blender was killed by {_signal_name(-code)}{why}", **kw)
    if NO_COMMAND in log:  # a set-up problem, like a missing Blender: exit code 2
        kw["exit_code"] = 2
        msg = (f"the eegt_blender extension is not installed or not enabled for {blender} "
               f"on {socket.gethostname()}")
    else:
        last = log.splitlines()[-1] if log else "no output"
        msg = f"Blender exited with code {code} and no report: {last}"
    return _result(task, status="error" if code in STATUS_OF_CODE else "crashed",
                   message=msg, **kw)


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


def precheck(task: Task) -> str | None:
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
    """One file in a fresh ``blender -b -c eegt`` process; `poll` gives its result once the
    process has ended."""

    def __init__(self, task: Task, blender: str, workdir: str,
                 env: dict[str, str] | None = None) -> None:
        self.task, self.blender = task, blender
        tag = f"{task.get('index', 0)}"
        self.report_path = os.path.join(workdir, f"{tag}.json")
        self.log_path = os.path.join(workdir, f"{tag}.log")
        self.timeout = task.get("timeout")
        self.started, self.clock = time.monotonic(), time.time()
        self.proc = _spawn(command(blender, task, self.report_path), self.log_path, env)
        self.result: Result | None = None

    def poll(self) -> Result | None:
        """The result once the process has ended (killed when past its timeout), else None;
        it says when the file started (``started``, seconds since the epoch)."""
        return _stamp(self._poll(), self.clock)

    def _poll(self) -> Result | None:
        if self.result is not None:
            return self.result
        code = self.proc.poll()
        elapsed = time.monotonic() - self.started
        if code is None:
            if self.timeout is not None and elapsed > self.timeout:
                self.kill("timeout", f"timed out after {self.timeout:g} s (worker killed)")
            return self.result
        report = _read_report(self.report_path)
        log = _log_tail(self.log_path)
        if report is not None:
            self.result = _from_report(self.task, report, elapsed, self.proc.pid, log)
        else:
            _remove_temporaries(self.task.get("output"), self.proc.pid)
            self.result = _from_exit(self.task, code, elapsed, self.proc.pid, log, self.blender)
        return self.result

    def wait(self, step: float = 0.1) -> Result:
        """Poll until the process has ended."""
        while self.poll() is None:
            time.sleep(step)
        assert self.result is not None
        return self.result

    def kill(self, status: str, message: str) -> Result:
        """Kill the process, remove its temporary files; the result says `status` (timeout
        or cancelled), unless the command had finished and Blender was only exiting."""
        return _stamp(self._stop(status, message), self.clock)

    def _stop(self, status: str, message: str) -> Result:
        _kill(self.proc)
        _remove_temporaries(self.task.get("output"), self.proc.pid)
        elapsed = time.monotonic() - self.started
        report = _read_report(self.report_path)
        log = _log_tail(self.log_path)
        if report is not None:
            self.result = _from_report(self.task, report, elapsed, self.proc.pid, log)
        else:
            self.result = _result(self.task, status=status, message=message,
                                  seconds=round(elapsed, 3), pid=self.proc.pid, log=log)
        return self.result


class Server:
    """One ``blender -b -c eegt SERVE_FLAG`` that runs the single-file command for up to
    `limit` files, one after the other, each named by a JSON line on its stdin; a file is
    done when its report is in place."""

    def __init__(self, blender: str, workdir: str, limit: int, tag: str,
                 env: dict[str, str] | None = None) -> None:
        self.blender, self.workdir, self.limit = blender, workdir, limit
        self.log_path = os.path.join(workdir, f"server-{tag}.log")
        self.proc = _spawn([blender, "-b", "-c", "eegt", SERVE_FLAG], self.log_path, env,
                           stdin=subprocess.PIPE)
        self.count = 0
        self.broken = False

    def usable(self) -> bool:
        """Whether it can take another file."""
        return not self.broken and self.count < self.limit and self.proc.poll() is None

    def submit(self, task: Task) -> Served:
        """Send one file; its handle."""
        self.count += 1
        served = Served(self, task)
        if self.count >= self.limit:
            self.close(wait=0.0)  # it exits once this last file is done
        return served

    def close(self, wait: float = 30.0) -> None:
        """No more files: let it finish and exit (killed if it does not in `wait` s)."""
        try:
            if self.proc.stdin and not self.proc.stdin.closed:
                self.proc.stdin.close()
        except OSError:
            pass
        if wait <= 0:
            return
        try:
            self.proc.wait(timeout=wait)
        except subprocess.TimeoutExpired:
            _kill(self.proc)

    def kill(self) -> None:
        self.broken = True
        _kill(self.proc)


class Served:
    """One file sent to a Server; `poll` gives its result once its report is in place, the
    server died, or its time ran out (the server is then killed)."""

    def __init__(self, server: Server, task: Task) -> None:
        self.server, self.task = server, task
        self.report_path = os.path.join(server.workdir, f"{task.get('index', 0)}.json")
        if os.path.exists(self.report_path):
            os.remove(self.report_path)
        self.timeout = task.get("timeout")
        self.log_start = os.path.getsize(server.log_path) if \
            os.path.exists(server.log_path) else 0
        self.started, self.clock = time.monotonic(), time.time()
        self.result: Result | None = None
        line = json.dumps(file_args(task, self.report_path)) + "\n"
        try:
            assert server.proc.stdin is not None
            server.proc.stdin.write(line.encode("utf-8"))
            server.proc.stdin.flush()
        except (OSError, ValueError):  # it died before it could take the file
            server.broken = True

    def poll(self) -> Result | None:
        return _stamp(self._poll(), self.clock)

    def _poll(self) -> Result | None:
        if self.result is not None:
            return self.result
        elapsed = time.monotonic() - self.started
        report = _read_report(self.report_path)
        if report is not None:
            self.result = _from_report(self.task, report, elapsed, self.server.proc.pid,
                                       self._log())
            return self.result
        code = self.server.proc.poll()
        if code is not None:
            report = _read_report(self.report_path)  # written just before it exited
            if report is not None:
                self.result = _from_report(self.task, report, elapsed, self.server.proc.pid,
                                           self._log())
            else:
                self.server.broken = True
                _remove_temporaries(self.task.get("output"), self.server.proc.pid)
                self.result = _from_exit(self.task, code, elapsed, self.server.proc.pid,
                                         self._log(), self.server.blender)
            return self.result
        if self.timeout is not None and elapsed > self.timeout:
            self.kill("timeout", f"timed out after {self.timeout:g} s (worker killed)")
        return self.result

    def kill(self, status: str, message: str) -> Result:
        """Kill the server (and this file's run in it); see Run.kill."""
        return _stamp(self._stop(status, message), self.clock)

    def _stop(self, status: str, message: str) -> Result:
        self.server.kill()
        _remove_temporaries(self.task.get("output"), self.server.proc.pid)
        elapsed = time.monotonic() - self.started
        report = _read_report(self.report_path)
        if report is not None:
            self.result = _from_report(self.task, report, elapsed, self.server.proc.pid,
                                       self._log())
        else:
            self.result = _result(self.task, status=status, message=message,
                                  seconds=round(elapsed, 3), pid=self.server.proc.pid,
                                  log=self._log())
        return self.result

    def _log(self) -> str:
        return _log_tail(self.server.log_path, self.log_start)


def run_task(task: Task) -> Result:
    """Run one task to its end on this machine in a fresh Blender (what a Dask worker
    executes with --files-per-worker 1)."""
    return run_chunk([task])[0]


def run_chunk(tasks: list[Task], per_worker: int = 1) -> list[Result]:
    """Run tasks one after the other on this machine, `per_worker` files per Blender (a
    fresh one after a crash or a timeout); what a Dask worker executes."""
    results: list[Result] = []
    workdir = tempfile.mkdtemp(prefix="eegt-task-")
    server: Server | None = None
    try:
        for n, task in enumerate(tasks):
            problem = precheck(task)
            blender, why = find_blender(task.get("blender"))
            if problem or blender is None:
                msg = problem or f"eegt: {why} on {socket.gethostname()}"
                results.append(_result(task, message=msg, exit_code=2))
                continue
            if per_worker <= 1:
                results.append(Run(task, blender, workdir).wait())
                continue
            if server is None or not server.usable():
                if server is not None:
                    server.close()
                server = Server(blender, workdir, per_worker, str(n))
            served = server.submit(task)
            while served.poll() is None:
                time.sleep(0.05)
            assert served.result is not None
            results.append(served.result)
    finally:
        if server is not None:
            server.close()
        shutil.rmtree(workdir, ignore_errors=True)
    return results
