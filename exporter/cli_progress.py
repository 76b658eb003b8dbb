"""Progress on stderr for the `treebake` commands: a redrawn
bar on a terminal; elsewhere (logs, CI, `| tee`) plain lines every
PLAIN_PROGRESS_SECONDS and one at the end."""

from __future__ import annotations

import math
import sys
import time

PLAIN_PROGRESS_SECONDS = 5.0  # without a terminal: a plain progress line this often
# below this share done the rate is a few frames' noise: "estimating", not an
# ETA (preset:felling's first second read "510 s left" for a 65 s bake)
ETA_FROM_SHARE = 0.02


def plain_interval() -> float:
    """Seconds between plain progress lines (TREEBAKE_PROGRESS_SECONDS overrides)."""
    import os

    try:
        return max(0.0, float(os.environ.get("TREEBAKE_PROGRESS_SECONDS", "")))
    except ValueError:
        return PLAIN_PROGRESS_SECONDS


def progress_bar(label: str):
    """Progress on stderr: a redrawn bar on a terminal; elsewhere (logs, CI,
    `| tee`) a plain line every few seconds and one at the end."""
    tty = sys.stderr.isatty()
    start: list[float] = []  # when the first report came
    last = [time.perf_counter()]
    finished = [False]

    def show(done: float, total: float) -> None:
        # `done` and `total` in any units that grow (frames, the LOD's planned work)
        if finished[0]:
            return
        # the clock starts with the first report, not with the bar: the
        # stages before the work (growing and rigging a shot of 10,000
        # trees: 12 s) made the first ETA 1,966 s for a 96 s simulation
        if not start:
            start.append(time.perf_counter())
        elapsed = time.perf_counter() - start[0]
        share = min(1.0, done / total) if total > 0 else 1.0
        eta = elapsed / share * (1.0 - share) if share >= ETA_FROM_SHARE else float("nan")
        left = "estimating" if math.isnan(eta) else f"{eta:.0f} s left"
        finished[0] = share >= 1.0
        if not tty:
            if share >= 1.0:
                sys.stderr.write(f"{label}: done in {elapsed:.1f} s\n")
            elif time.perf_counter() - last[0] >= plain_interval():
                last[0] = time.perf_counter()
                sys.stderr.write(f"{label}: {100 * share:.0f} %, {left}\n")
            else:
                return
            sys.stderr.flush()
            return
        width = 30
        filled = int(width * share)
        sys.stderr.write(f"\r{label} [{'#' * filled}{'.' * (width - filled)}] "
                         f"{100 * share:3.0f} %, {left:>14} ")
        if share >= 1.0:
            sys.stderr.write("\n")
        sys.stderr.flush()

    return show


def stage_progress():
    """Progress on stderr for export stages: a bar on a terminal, plain
    lines (every few seconds and at each stage's end) elsewhere."""
    start = time.perf_counter()
    tty = sys.stderr.isatty()
    last = [start]

    def show(stage: str, done: int, total: int) -> None:
        elapsed = time.perf_counter() - start
        if not tty:
            if done >= total or time.perf_counter() - last[0] >= plain_interval():
                last[0] = time.perf_counter()
                sys.stderr.write(f"exporting {stage}: {done}/{total}, {elapsed:.1f} s\n")
                sys.stderr.flush()
            return
        width = 30
        filled = int(width * done / max(total, 1))
        sys.stderr.write(f"\rexporting {stage:<7} [{'#' * filled}{'.' * (width - filled)}] "
                         f"{done}/{total}  {elapsed:5.1f} s ")
        if done >= total:
            sys.stderr.write("\n")
        sys.stderr.flush()

    return show


def plural(n: int, word: str) -> str:
    """'1 tree', '2 trees', '28,334 segments'."""
    return f"{n} {word}" if n == 1 else f"{n:,} {word}s"


class BatchDisplay:
    """Progress of a batch on stderr: one line per finished (or retried) job;
    on a terminal a live line with every running job's frame count, else
    that status as a plain line every PLAIN_PROGRESS_SECONDS. Remembers
    the most workers the run reported (the summary's count)."""

    def __init__(self, total: int, quiet: bool = False) -> None:
        self.total, self.quiet = total, quiet
        self.tty = sys.stderr.isatty()
        self.running: dict[str, str] = {}
        self.finished = 0
        self.workers = 0
        self.last_plain = time.monotonic()

    def __call__(self, event: str, data) -> None:
        if event == "workers":
            self.workers = max(self.workers, int(data))
            return
        if event == "start":
            self.running[data] = "starting"
        elif event == "progress":
            name, done, total = data  # growing numbers in any unit: the share is done
            self.running[name] = f"{100 * done / total:.0f} %" if total else "starting"
        elif event == "retry":
            self._line(f"[{self.finished}/{self.total}] {data[0]}: {data[1]}")
        elif event == "end":
            self.running.pop(data.name, None)
            self.finished += 1
            line = f"[{self.finished}/{self.total}] {data.name}: {data.status}"
            if data.message:
                line += f" ({data.message})"
            self._line(line)
        if self.quiet or not self.running:
            return
        live = "  ".join(f"{k} {v}" for k, v in sorted(self.running.items()))
        if self.tty:
            sys.stderr.write(f"\r\033[K[{self.finished}/{self.total}] {live}"[:200])
            sys.stderr.flush()
        elif time.monotonic() - self.last_plain >= plain_interval():
            self.last_plain = time.monotonic()
            self._line(f"[{self.finished}/{self.total}] running: {live}"[:400])

    def _line(self, text: str) -> None:
        if self.quiet:
            return
        sys.stderr.write(("\r\033[K" if self.tty else "") + text + "\n")
        sys.stderr.flush()


class CaseDisplay:
    """Progress of a suite's runs on stderr (`treebake stability`): one line
    per run, `case 3/24 wind 70 m/s, planar draft: passed, 2.1 s (...)`. On
    a terminal the line shows from the run's start (`running, about 4 CPU
    s`) and is completed in place when it ends; elsewhere (logs, CI) it is
    written when the run ends. Call as `display(event, k, n, label, text)`,
    event "start" or "end"."""

    def __init__(self, quiet: bool = False) -> None:
        self.quiet = quiet
        self.tty = sys.stderr.isatty()
        self.open = False  # a start line waits for its end on the terminal

    def __call__(self, event: str, k: int, n: int, label: str, text: str = "") -> None:
        if self.quiet:
            return
        line = f"case {k}/{n} {label}: {text}"
        if event == "start":
            if self.tty:  # one terminal line, or `\r` cannot take it back
                import shutil

                sys.stderr.write(line[:max(20, shutil.get_terminal_size().columns - 1)])
                self.open = True
            else:
                return
        else:
            sys.stderr.write(("\r\033[K" if self.open else "") + line + "\n")
            self.open = False
        sys.stderr.flush()
