"""Error types. Every error a user can cause is one of these, with a message
that names where the problem is; the CLI turns them into exit codes."""

from __future__ import annotations


class TreebakeError(Exception):
    """Base class. `exit_code` is what the CLI returns for it."""

    exit_code = 1


class InputError(TreebakeError):
    """Bad input from the user (grammar, scene, options): exit code 2."""

    exit_code = 2


class GrammarError(InputError):
    """A problem in a grammar file, located by file, line and column (1-based)."""

    def __init__(self, message: str, file: str = "<grammar>", line: int = 0, col: int = 0):
        self.message = message
        self.file = file
        self.line = line
        self.col = col
        super().__init__(str(self))

    def __str__(self) -> str:
        if self.line <= 0:  # found in the derived string, which has no line of the file
            return f"{self.file}: {self.message}"
        return f"{self.file}:{self.line}:{self.col}: {self.message}"


class OutputError(InputError):
    """An output path cannot be written (missing permission, a file where a
    folder should be, read-only file system): exit code 2, found before any
    expensive work."""


class BusyError(TreebakeError):
    """Another treebake run holds the job folder's lock: exit code 1."""


class LimitError(InputError):
    """A derivation or size limit was hit (module count, memory, iterations)."""


class SceneError(InputError):
    """A scene key is missing, of the wrong type or out of range."""

    def __init__(self, key: str, message: str, file: str = "<scene>"):
        self.key = key
        self.message = message
        self.file = file
        super().__init__(str(self))

    def __str__(self) -> str:
        if self.message.startswith("= "):  # "duration = -5 is out of range", not "duration: = -5"
            return f"{self.file}: {self.key} {self.message}"
        return f"{self.file}: {self.key}: {self.message}"


class SimulationError(TreebakeError):
    """The simulation went non-finite or unstable; nothing is written."""

    def __init__(self, message: str, tree: str = "", segment: int = -1, time: float = float("nan")):
        self.message = message
        self.tree = tree
        self.segment = segment
        self.time = time
        super().__init__(str(self))

    def __str__(self) -> str:
        return f"tree {self.tree!r}, segment {self.segment}, t = {self.time:.4f} s: {self.message}"
