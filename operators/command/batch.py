# SPDX-License-Identifier: GPL-3.0-or-later
"""``blender -b -c eegt INPUT... -o OUTDIR``: many files in one command.

A command line is a batch when it has many inputs, a folder or a glob pattern, an output
folder, or a batch flag (``--jobs``, ``--timeout``, ``--skip-existing``, ``--recursive``,
``--suffix``, ``--format``, ``--files-per-worker``, ``--dask``); otherwise the single-file
command runs as it always did. Every file of a batch is run by that single-file command in
its own ``blender -b`` (this Blender's binary; with ``--files-per-worker K`` one Blender runs
K files in turn, see ``serve``), at most ``--jobs`` at once or as tasks on a Dask cluster, so
that a crash, a hang or a memory blow-up in one file cannot take the others down. Everything
that can be checked before starting is (bad flags, no inputs, an output folder that is a
file, ``-o FILE`` for many inputs, two inputs writing one output, an output replacing its
input without ``--in-place``, a bad ``--dask`` value, Dask missing, no scheduler answering at
the ``--dask`` address): one line on stderr, exit 2, nothing started. Ctrl+C (or SIGTERM)
kills the running workers, removes their temporary files and still writes the report; exit
130.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import signal
import sys
import threading
import time
from typing import Any

import bpy

from ...batch import arguments, dask_pool, inputs, pool, summary, worker
from . import cli, report
from .parser import build_parser as single_file_parser
from .usage import EXIT_INTERNAL, EXIT_OK, EXIT_USAGE, OUTPUT_EXTENSIONS, UsageError, check_writable

DEFAULT_REPORT = "eegt_report.json"
REDRAW = 0.5  # seconds between progress-bar redraws on a terminal
LOG_EVERY = 10.0  # seconds between progress lines when the console is not a terminal


def build_parser() -> argparse.ArgumentParser:
    """The single-file parser with many inputs and the batch flags."""
    p = single_file_parser()
    arguments.add_batch_arguments(p)
    return p


def is_batch(argv: list[str]) -> bool:
    """Whether this command line is a batch (help shows the batch flags too), or a batch's
    worker Blender serving files."""
    if argv[:1] == [worker.SERVE_FLAG]:
        return True
    if arguments.batch_flag_in(argv) or "-h" in argv or "--help" in argv:
        return True
    try:
        ns = build_parser().parse_intermixed_args(argv)
    except UsageError:
        return False  # the single-file command reports it as it always did
    return arguments.is_batch(ns)


class _Plan:
    """What a batch will do, checked before anything starts."""

    def __init__(self) -> None:
        self.entries: list[dict[str, Any] | None] = []  # decided now (skipped, unreadable)
        self.tasks: list[dict[str, Any]] = []
        self.outdir: str | None = None
        self.report: str | None = None
        self.jobs = 1
        self.blender = ""


def _usage(message: str) -> UsageError:
    return UsageError(message)


def _check_flags(ns: argparse.Namespace) -> None:
    if ns.jobs is not None and ns.jobs < 1:
        raise _usage(f"eegt: --jobs must be at least 1 (got {ns.jobs})")
    if ns.files_per_worker is not None and ns.files_per_worker < 1:
        raise _usage(f"eegt: --files-per-worker must be at least 1 (got {ns.files_per_worker})")
    if ns.timeout is not None and not ns.timeout > 0:
        raise _usage(f"eegt: --timeout must be a positive number of seconds (got {ns.timeout:g})")
    if os.sep in ns.suffix or "/" in ns.suffix:
        raise _usage(f"eegt: --suffix '{ns.suffix}' must not contain a path separator")
    if ns.dask is not None and ns.jobs is not None:
        raise _usage("eegt: --jobs is for local workers; with --dask the cluster's workers run "
                     "the files (local:N sets their number)")
    if not ns.output:
        for flag, given in (("--skip-existing", ns.skip_existing), ("--suffix", ns.suffix),
                            ("--format", ns.format)):
            if given:
                raise _usage(f"eegt: {flag} needs -o OUTDIR (outputs to compare or name)")
    if ns.dask is not None:  # the value first: a bad one is exit 2 whatever is installed
        kind, _ = dask_pool.parse_address(ns.dask)
        dask_pool.require()
        if kind == "remote":
            dask_pool.probe(ns.dask)


def _output_kind(ns: argparse.Namespace) -> tuple[str | None, str | None]:
    """(output folder, output file); -o without a mesh extension is a folder."""
    out = ns.output
    if not out:
        return None, None
    ext = os.path.splitext(out)[1].lower()
    if os.path.isdir(out) or out.endswith(("/", os.sep)) or ext not in OUTPUT_EXTENSIONS:
        if os.path.lexists(out) and not os.path.isdir(out):
            raise _usage(f"eegt: output folder '{out}' is a file")
        return out, None
    if ns.suffix or ns.format:
        raise _usage(f"eegt: --suffix and --format name the outputs in an output folder; "
                     f"-o {out} is one file")
    return None, out


def plan(ns: argparse.Namespace, parser: argparse.ArgumentParser, argv: list[str]) -> _Plan:
    """Check everything and decide every file's fate; raises UsageError (exit 2)."""
    _check_flags(ns)
    outdir, outfile = _output_kind(ns)
    sources, notes = inputs.expand(ns.input, ns.recursive, [outdir] if outdir else [])
    if not sources:
        raise _usage("eegt: no input files: " + "; ".join(n.removeprefix("eegt: ")
                                                           for n in notes))
    for note in notes:
        print(note, file=sys.stderr, flush=True)
    if outfile and len(sources) > 1:
        raise _usage(f"eegt: -o {outfile} names one file but {len(sources)} inputs matched: "
                     "give an output folder")
    if outdir:
        outputs: list[str | None] = [inputs.output_path(s, outdir, ns.suffix, ns.format)
                                     for s in sources]
    elif ns.in_place and not outfile:  # each input written over itself
        outputs = [s.path for s in sources]
    else:
        outputs = [outfile] * len(sources)
    try:
        inputs.check_outputs(sources, outputs, ns.in_place)
    except inputs.PlanError as exc:
        raise _usage(str(exc)) from None
    p = _Plan()
    p.outdir = outdir
    p.report = ns.report or (os.path.join(outdir, DEFAULT_REPORT) if outdir else None)
    if outdir:
        try:
            os.makedirs(outdir, exist_ok=True)
        except OSError as exc:
            raise _usage(f"eegt: cannot create output folder '{outdir}': "
                         f"{(exc.strerror or str(exc)).lower()}") from None
    if p.report:
        check_writable(p.report, "report")
        check_writable(summary.csv_path_for(p.report), "report")
    args = arguments.passthrough(parser, argv)
    for i, (src, out) in enumerate(zip(sources, outputs, strict=True)):
        entry = None
        if src.problem:
            entry = summary.file_entry({"input": src.path, "output": out, "status": "error",
                                        "exit_code": EXIT_USAGE, "message": src.problem})
        elif ns.skip_existing and inputs.up_to_date(src.path, out):
            entry = summary.file_entry({"input": src.path, "output": out, "status": "skipped",
                                        "exit_code": 0, "message": "output is up to date"})
        else:
            p.tasks.append({"index": i, "input": src.path, "output": out, "args": args,
                            "timeout": ns.timeout, "blender": bpy.app.binary_path or None})
        p.entries.append(entry)
    if ns.dask is None:
        p.jobs = max(1, min(ns.jobs or pool.default_jobs(), len(p.tasks) or 1))
        blender, why = pool.local_blender(bpy.app.binary_path)
        if p.tasks and blender is None:
            raise _usage(f"eegt: cannot start workers: {why} (set EEGT_BLENDER to a Blender "
                         "binary with this extension)")
        p.blender = blender or ""
    return p


class _Stopper:
    """SIGINT/SIGTERM handlers that ask the batch to stop (Blender's own SIGINT handler only
    flags a break); the previous handlers come back on exit."""

    def __init__(self) -> None:
        self.signum: int | None = None
        self.saved: dict[int, Any] = {}

    def __enter__(self) -> _Stopper:
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                try:
                    self.saved[sig] = signal.signal(sig, self._handle)
                except (ValueError, OSError):
                    pass
        return self

    def _handle(self, signum: int, _frame: Any) -> None:
        if self.signum is None:
            print("\neegt: interrupted: stopping the workers, writing the report",
                  file=sys.stderr, flush=True)
        self.signum = signum

    def __call__(self) -> bool:
        return self.signum is not None

    def __exit__(self, *exc: Any) -> None:
        for sig, old in self.saved.items():
            if old is None:  # a handler set outside Python (Blender's): the default one
                old = signal.default_int_handler if sig == signal.SIGINT else signal.SIG_DFL
            signal.signal(sig, old)


class _Console:
    """The progress bar on a terminal, else a line per file and a progress line now and
    then; failures are always printed."""

    def __init__(self, total: int, quiet: bool) -> None:
        self.progress = summary.Progress(total)
        self.quiet = quiet
        self.tty = sys.stdout.isatty()
        self.last = time.monotonic()

    def result(self, entry: dict[str, Any]) -> None:
        self.progress.add(entry)
        bad = entry["status"] not in ("ok", "skipped")
        if bad or (not self.quiet and not self.tty):
            msg = entry.get("message") or ""
            line = (f"eegt: [{self.progress.done}/{self.progress.total}] "
                    f"{entry['status']:<9} {entry['input']} ({entry.get('seconds', 0):.1f} s)"
                    + (f": {msg}" if msg and bad else ""))
            self._clear()
            print(line, flush=True)
        self.tick(force=True)

    def tick(self, force: bool = False) -> None:
        if self.quiet:
            return
        now = time.monotonic()
        if self.tty and (force or now - self.last >= REDRAW):
            sys.stdout.write("\r\033[K" + self.progress.line(now))
            sys.stdout.flush()
            self.last = now
        elif not self.tty and now - self.last >= LOG_EVERY:
            print("eegt: " + self.progress.line(now), flush=True)
            self.last = now

    def _clear(self) -> None:
        if self.tty and not self.quiet:
            sys.stdout.write("\r\033[K")

    def close(self) -> None:
        if self.tty and not self.quiet:
            sys.stdout.write("\n")
            sys.stdout.flush()


def serve(lines: Any = None) -> int:
    """A batch's worker Blender (``--files-per-worker``): run the single-file command for
    every command line read from stdin (one JSON list a line) until it closes. Each run puts
    its report in place last, which tells the batch the file is done; when a run could not
    write its report, this writes a short one, and exits when even that fails."""
    for line in sys.stdin if lines is None else lines:
        try:
            argv = json.loads(line)
        except ValueError:
            continue
        code, rep = cli.run([str(a) for a in argv])
        path = argv[argv.index("--report") + 1] if "--report" in argv else None
        if path and not os.path.exists(path):
            try:
                with open(path, "w", encoding="utf-8") as fh:
                    json.dump({"exit_code": code, "error": rep.get("error"), "objects": [],
                               "written": False}, fh)
            except OSError:
                return code or EXIT_INTERNAL
    return EXIT_OK


def run(argv: list[str]) -> int:
    """Parse, plan, run every file, write the reports; the batch's exit code."""
    if argv[:1] == [worker.SERVE_FLAG]:
        return serve()
    t0 = time.monotonic()
    started = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    parser = build_parser()
    try:
        ns = parser.parse_intermixed_args(argv)  # inputs may come after flags too
        p = plan(ns, parser, argv)
    except UsageError as exc:
        if str(exc):
            print(str(exc), file=sys.stdout if exc.code == EXIT_OK else sys.stderr,
                  flush=True)
        return exc.code
    except dask_pool.DaskError as exc:
        print(str(exc), file=sys.stderr, flush=True)
        return EXIT_USAGE
    entries = p.entries
    console = _Console(len(entries), ns.quiet)
    decided = [e for e in entries if e is not None]
    where = f"dask {ns.dask}" if ns.dask else f"{p.jobs} worker{'s' * (p.jobs > 1)}"
    print(f"eegt: {len(entries)} files: {len(p.tasks)} to run ({where}), "
          f"{sum(e['status'] == 'skipped' for e in decided)} up to date, "
          f"{sum(e['status'] == 'error' for e in decided)} unreadable"
          + (f"; outputs in {p.outdir}" if p.outdir else ""), flush=True)
    for e in decided:
        console.result(e)

    def on_result(res: dict[str, Any]) -> None:
        entry = summary.file_entry(res)
        entries[res["index"]] = entry
        console.result(entry)

    interrupted = False
    with _Stopper() as stop:
        try:
            if ns.dask is not None and p.tasks:
                interrupted = _run_dask(ns.dask, p, on_result, stop, console,
                                        ns.files_per_worker or 1)
            elif p.tasks:
                _remove_stale(p)
                interrupted = pool.run_local(p.tasks, p.jobs, p.blender, on_result, stop,
                                             console.tick, ns.files_per_worker or 1)
        except dask_pool.DaskError as exc:
            console.close()
            print(str(exc), file=sys.stderr, flush=True)
            return EXIT_USAGE
    console.close()
    files = [e for e in entries if e is not None]
    code = summary.batch_exit(files, interrupted)
    data = {"tool": "eegt_blender", "kind": "batch", "version": report.extension_version(),
            "blender_version": bpy.app.version_string, "python": platform.python_version(),
            "argv": list(argv), "started": started, "seconds": round(time.monotonic() - t0, 3),
            "mode": "dask" if ns.dask else "local", "jobs": None if ns.dask else p.jobs,
            "files_per_worker": ns.files_per_worker or 1,
            "dask": ns.dask, "timeout": ns.timeout, "outdir": p.outdir,
            "interrupted": interrupted, "counts": summary.counts(files),
            "kinds": summary.kinds(files), "exit_code": code,
            "files": files}
    written = ""
    if p.report:
        try:
            csv_path = summary.write_reports(p.report, data)
            written = f"; report {p.report}, {csv_path}"
        except OSError as exc:
            print(f"eegt: cannot write report '{p.report}': {(exc.strerror or str(exc)).lower()}",
                  file=sys.stderr, flush=True)
            code = code if code in (EXIT_INTERNAL, summary.EXIT_INTERRUPTED) else \
                EXIT_USAGE
    c = data["counts"]
    parts = ", ".join(f"{n} {s}" for s, n in c.items() if n)
    print(f"eegt: {len(files)} files in {summary.duration(data['seconds'])}: {parts} "
          f"(exit {code}){written}", flush=True)
    return code


def _remove_stale(p: _Plan) -> None:
    """Remove temporary files left in the output folders by runs killed hard (their
    process is gone)."""
    folders = {os.path.dirname(os.path.realpath(t["output"])) for t in p.tasks if t["output"]}
    stale = inputs.stale_temporaries(folders)
    for path in stale:
        try:
            os.remove(path)
        except OSError:
            pass
    if stale:
        print(f"eegt: removed {len(stale)} temporary file{'s' * (len(stale) > 1)} left by "
              "an interrupted run", flush=True)


def _run_dask(address: str, p: _Plan, on_result: Any, stop: Any, console: _Console,
              per_worker: int) -> bool:
    with dask_pool.plain_main():
        client, cluster = dask_pool.connect(address, pool.default_jobs())
        try:
            n = len(client.scheduler_info().get("workers", {}))
            print(f"eegt: Dask cluster {client.scheduler.address}: {n} worker"
                  f"{'s' * (n != 1)}", flush=True)
            return dask_pool.run_dask(client, p.tasks, on_result, stop, console.tick,
                                      per_worker)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
                _remove_stale(p)  # tasks of workers killed by the close
