"""`treebake` command line. Thin: each subcommand parses options and calls
the pipeline. Exit codes: 0 ok, 1 failure, 2 bad usage or input.

The parser is a table (cli_parser.COMMANDS); the commands live in cli_tree
(derive, inspect, sway, list), cli_bake (bake, export, preview), cli_batch
(diff, batch) and cli_suites (accuracy, stability); progress display in
cli_progress. This module runs one command line (`main`)."""

from __future__ import annotations

import sys
import time

from .cli_bake import cmd_bake, cmd_export, cmd_preview, load_job
from .cli_batch import cmd_batch, cmd_diff
from .cli_parser import (
    ACCURACY_SCENARIOS,
    ACCURACY_SPECIES,
    COMMANDS,
    EXAMPLES,
    STABILITY_CASES,
    build_parser,
    unknown_arguments,
)
from .cli_suites import cmd_accuracy, cmd_stability
from .cli_tree import cmd_derive, cmd_inspect, cmd_list, cmd_sway, inspect_summary
from .errors import TreebakeError

__all__ = ["ACCURACY_SCENARIOS", "ACCURACY_SPECIES", "COMMANDS", "EXAMPLES", "STABILITY_CASES",
           "build_parser", "cmd_accuracy", "cmd_bake", "cmd_batch", "cmd_derive", "cmd_diff",
           "cmd_export", "cmd_inspect", "cmd_list", "cmd_preview", "cmd_stability", "cmd_sway",
           "inspect_summary", "load_job", "main"]


def main(argv: list[str] | None = None) -> int:
    _closed_streams_to_devnull()
    stderr = sys.stderr
    sys.stderr = _LogStream(stderr)
    try:
        return _run(argv)
    finally:
        sys.stderr = stderr


def _run(argv: list[str] | None) -> int:
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:  # the command's own usage and error, not the top level's
        command = getattr(args, "command_parser", parser)
        command.error(unknown_arguments(command, extra))
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    start = time.perf_counter()
    try:
        code = args.func(args)
        sys.stdout.flush()  # a closed pipe shows here, inside the handler below
    except TreebakeError as exc:
        print(f"treebake: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("treebake: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `treebake diff ... | head`: the reader left; not an error of ours
        _silence_stdout()
        return 141  # 128 + SIGPIPE, what a shell reports for a process killed by it
    except OSError as exc:  # disk full, a folder removed under us, ...: no traceback
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"treebake: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 1
    if getattr(args, "verbose", False):
        print(f"done in {time.perf_counter() - start:.2f} s", file=sys.stderr)
    return code


class _LogStream:
    """stderr for the log and progress lines: a reader that left (`bake ...
    2>&1 | head -1`) stops the lines, not the work (the bake was lost, exit
    141); what would follow goes to /dev/null. stdout keeps its BrokenPipe
    (exit 141 once the work is done): its report was the point."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._to_devnull()
            return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._to_devnull()

    def _to_devnull(self) -> None:
        import os

        try:  # the stream's own descriptor too: its buffer flushes at exit without an error
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self._stream.fileno())
            os.close(devnull)
            self._stream.flush()
        except (OSError, ValueError):
            self._stream = open(os.devnull, "w", encoding="utf-8")

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def _closed_streams_to_devnull() -> None:
    """A command run with stdout or stderr closed (`>&-`, `2>&-`) still does
    its work: what it would print goes to /dev/null."""
    import os

    for name in ("stdout", "stderr"):
        if getattr(sys, name) is None:
            setattr(sys, name, open(os.devnull, "w", encoding="utf-8"))


def _silence_stdout() -> None:
    """Point stdout at /dev/null so the interpreter's final flush cannot
    raise BrokenPipeError again at exit."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


if __name__ == "__main__":
    sys.exit(main())
