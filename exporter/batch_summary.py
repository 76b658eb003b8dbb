"""A batch's summary: the machine-readable record (OUT/batch-summary.json,
`--json`) and the table `treebake batch` prints."""

from __future__ import annotations

from dataclasses import asdict

from . import __version__
from .batch_jobs import JobResult


def summary(results: list[JobResult], wall: float, workers: int) -> dict:
    """Machine-readable summary of a batch; `workers`: how many processes
    (or Dask workers, the most seen) actually ran jobs."""
    return {
        "tool": f"treebake {__version__}", "jobs": len(results), "wall_seconds": round(wall, 3),
        "workers": workers,
        "done": sum(r.status == "done" for r in results),
        "skipped": sum(r.status == "skipped" for r in results),
        "failed": sum(r.status == "failed" for r in results),
        "busy": sum(r.status == "busy" for r in results),
        "interrupted": sum(r.status == "interrupted" for r in results),
        "results": [{**asdict(r), "seconds": round(r.seconds, 3)} for r in results],
    }


def format_table(results: list[JobResult]) -> str:
    """One line per job: name, status, seconds, frames, segments, message."""
    width = max([len(r.name) for r in results] + [4])
    lines = [f"{'job':<{width}}  {'status':<11} {'s':>7}  {'frames':>6} {'segments':>8}  message"]
    for r in results:
        lines.append(f"{r.name:<{width}}  {r.status:<11} {r.seconds:>7.1f}  {r.frames:>6} "
                     f"{r.segments:>8}  {r.message}")
    return "\n".join(lines)
