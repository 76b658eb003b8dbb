"""`treebake diff` and `batch`: regression diffs between bakes, and many
bakes from a job file (docs/batch.md)."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from .cli_grammar import warn_grammar
from .cli_progress import BatchDisplay, plural
from .errors import InputError, OutputError, TreebakeError
from .fileio import write_text

BUSY_EXIT = 75  # sysexits.h EX_TEMPFAIL: nothing failed, but not every job is finished yet


def cmd_diff(args) -> int:
    from .diff import (TopologyError, diff_bakes, exit_code, format_report, load_any,
                       plot_report, require_plots)

    for flag, value in (("--position-tolerance", args.position_tolerance),
                        ("--angle-tolerance", args.angle_tolerance)):
        if not value >= 0.0:  # NaN too
            raise InputError(f"{flag} must be >= 0, got {value}")
    if args.plot:  # before the comparison, not after it
        require_plots()
    a, b = load_any(args.a), load_any(args.b)
    try:
        report = diff_bakes(a, b, args.position_tolerance, args.angle_tolerance, args.worst)
    except TopologyError as exc:  # which two files, A and B in its text
        raise TopologyError(f"{args.a} (A) and {args.b} (B) {exc}") from None
    if args.plot:
        plot_report(report, a.times, args.plot)
    if args.json:
        print(json.dumps(report.as_dict()))
    else:
        print(format_report(report, args.a, args.b))
    return exit_code(report)


def _warn_grammars(jobs, strict: bool) -> None:
    """warn_grammar for every grammar file the jobs read, once per file. A
    job whose scene or grammar does not load is passed over here: it fails
    on its own, without stopping the batch."""
    from .lsystem import load_grammar

    seen: set[Path] = set()
    for job in jobs:
        try:
            files = [p for p in job.inputs() if not job.scene or p != Path(job.scene)]
        except (TreebakeError, OSError):
            continue
        for path in files:
            if path in seen:
                continue
            seen.add(path)
            try:
                grammar = load_grammar(path)
            except TreebakeError:
                continue
            warn_grammar(grammar, strict)


def cmd_batch(args) -> int:
    import os

    from .batch import format_table, load_jobs, run_batch, summary
    from .fileio import check_writable, check_writable_file

    jobs = load_jobs(args.jobs_file)
    _warn_grammars(jobs, args.strict)
    workers = (os.cpu_count() or 1) if args.jobs is None else args.jobs
    if workers < 1:
        raise InputError(f"--jobs must be >= 1, got {args.jobs}")
    summary_path = Path(args.summary or Path(args.out) / "batch-summary.json")
    check_writable(args.out)
    check_writable_file(summary_path)
    show = BatchDisplay(len(jobs), quiet=args.json)
    start = time.perf_counter()
    results = run_batch(jobs, args.out, workers, args.force, args.executor, args.scheduler,
                        report=show, worker_timeout=args.worker_timeout)
    data = summary(results, time.perf_counter() - start, show.workers)
    unwritten = None
    try:
        write_text(summary_path, json.dumps(data, indent=2) + "\n")
    except OutputError as exc:  # a full disk: the table below still says what happened
        unwritten = exc
    if args.json:
        print(json.dumps(data))
    else:
        print(format_table(results))
        line = (f"{data['done']} done, {data['skipped']} skipped, {data['failed']} failed")
        for extra in ("busy", "interrupted"):
            if data[extra]:
                line += f", {data[extra]} {extra}"
        print(f"{line} in {data['wall_seconds']:.1f} s with {plural(data['workers'], 'worker')}"
              + ("; summary not written" if unwritten else f"; summary: {summary_path}"))
    if unwritten:
        print(f"treebake: error: {unwritten}", file=sys.stderr)
        return 1
    if data["interrupted"]:
        print("treebake: interrupted; rerun the same command to resume", file=sys.stderr)
        return 130
    if data["failed"]:
        return 1
    if data["busy"]:
        print(f"treebake: {plural(data['busy'], 'job')} still being written by another run; "
              "rerun the same command later to check them (finished jobs are skipped)",
              file=sys.stderr)
        return BUSY_EXIT
    return 0
