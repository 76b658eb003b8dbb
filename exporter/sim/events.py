"""What happened during a simulation, as records both solvers share.

An event is written to the bake's JSON as a record (time, tree, kind,
segment, detail) and rendered as text only for people (logs, reports).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

# kinds of event
CUT = "cut"  # felling: the notch is cut, the hinge holds
HINGE = "hinge snapped"  # felling: the hinge wood broke, the stem falls free
BROKE = "broke"  # a joint's bending moment passed its strength
UPROOTED = "uprooted"  # a root joint broke
AT_REST = "at rest"  # a fallen tree or a still one went to sleep
TIER = "tier"  # the planar LOD moved a tree from one engine to another
KINDS = (CUT, HINGE, BROKE, UPROOTED, AT_REST, TIER)


@dataclass(frozen=True)
class Event:
    """At `time` s, on `tree`, `kind` (KINDS) at `segment` (its limb path,
    e.g. "trunk/2:0"; "" for the whole tree), with `detail` for people."""

    time: float
    tree: str
    kind: str
    segment: str = ""
    detail: str = ""

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"unknown event kind {self.kind!r}")

    def record(self) -> dict:
        out = asdict(self)
        out["time"] = round(self.time, 6)
        return out

    @classmethod
    def from_record(cls, data: dict) -> Event:
        return cls(float(data["time"]), str(data["tree"]), str(data["kind"]),
                   str(data.get("segment", "")), str(data.get("detail", "")))

    def text(self) -> str:
        where = f"{self.segment}: " if self.segment else ""
        what = f"{self.kind} ({self.detail})" if self.detail else self.kind
        return f"t = {self.time:.3f} s: {where}{what}"


def summary(events_by_tree: dict[str, list[Event]]) -> list[str]:
    """For people (the bake's log): one line per tree and kind of event,
    with how many and when ("oak: 212 joints broke between 4.33 and 6.10 s")."""
    lines = []
    for tree, events in events_by_tree.items():
        for kind in KINDS:
            mine = [e for e in events if e.kind == kind]
            if mine:
                lines.append(f"{tree}: {_kind_line(kind, mine)}")
    return lines


# uprooted: its root joint broke, which the bake's count of broken joints includes
_WHAT = {BROKE: ("joint broke", "joints broke"),
         UPROOTED: ("uprooted (its root joint broke)", "uprooted (their root joints broke)"),
         CUT: ("cut", "cut"), HINGE: ("hinge snapped", "hinges snapped"),
         AT_REST: ("at rest", "at rest"), TIER: ("changed engine", "changed engine")}


def _kind_line(kind: str, events: list[Event]) -> str:
    first, last = events[0].time, events[-1].time
    one, many = _WHAT[kind]
    when = f"at {first:.2f} s" if len(events) == 1 else f"between {first:.2f} and {last:.2f} s"
    if kind == TIER:
        if len(events) == 1:
            return f"{one} {when} ({events[0].detail})"
        return f"{one} {len(events)} times {when} (first: {events[0].detail})"
    if kind in (BROKE,) or len(events) > 1:
        return f"{len(events)} {one if len(events) == 1 else many} {when}"
    return f"{one} {when}" + (f" ({events[0].detail})" if events[0].detail else "")
