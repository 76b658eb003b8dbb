"""Compare two bakes (or two exported glTF files): which motion changed.

Topology first: the same trees with the same segments and parents, the same
frames; otherwise the difference is described and nothing is compared.
Then, per tree, segment and frame: the position error of both ends of the
segment (m, and % of the tree's height) and the rotation error (degrees).
The report gives the maximum and RMS, the first frame past the tolerance,
the worst segments by limb path, and whether the difference is only
float32 round-off ("noise").

An exported glTF is its bake after keyframe reduction, which may move any
joint or tip by up to the tolerances the file declares
(asset.extras.treebake.reduction): those are added to the user's
tolerances (and the report says so), so a glb and its own bake compare as
the same. A file listed in a manifest.json beside it must still match the
sha256 recorded there: a damaged or edited export is an error, not a diff.

When the motion differs and the bakes record different library versions
(meta["versions"], treebake.versions; "unknown" for a bake that records
none), the report lists them: a new MuJoCo may be the whole story.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .bake import Bake, TreeBake
from .bake_file import load_bake, tree_field, tree_info
from .errors import InputError
from .rotations import angle_between
from .sway import segment_ends
from .versions import version_differences

NOISE_RELATIVE = 4e-7  # float32 round-off on a coordinate, relative to its size
NOISE_ANGLE = 1e-4  # degrees


class TopologyError(InputError):
    """The two bakes do not describe the same trees, segments or frames."""


@dataclass
class SegmentError:
    tree: str
    segment: int
    path: str
    max_position: float  # m
    max_angle: float  # degrees
    frame: int  # where the larger of the two was largest


@dataclass
class DiffReport:
    frames: int
    segments: int
    max_position: float  # m
    max_position_percent: float  # % of the tree's height
    rms_position: float  # m
    max_angle: float  # degrees
    rms_angle: float  # degrees
    first_frame: int | None  # first frame past a tolerance (0-based), None if none
    first_time: float | None  # s
    worst: list[SegmentError]
    noise: bool  # everything within float32 round-off
    within: bool  # within the tolerances
    position_tolerance: float  # m, the user's
    angle_tolerance: float  # degrees, the user's
    position_allowance: float = 0.0  # m, added for keyframe reduction declared by glTF inputs
    angle_allowance: float = 0.0  # degrees, likewise
    allowance_note: str = ""  # where the allowance comes from
    curves: dict = field(default_factory=dict)  # worst segments' error per frame, for plots
    # "mujoco 3.13.0 -> 4.0.0" (A -> B) when the motion differs and the versions do
    version_differences: list[str] = field(default_factory=list)
    # trees whose drawn twigs (`@twig`) differ at rest, e.g. "oak: 412 vs 398 twigs";
    # twigs move with their segments, so only their rest shape can differ
    twig_differences: list[str] = field(default_factory=list)
    # the number A's first frame has in its exports (the text report's frame numbers)
    frame_start: int = 1

    def as_dict(self) -> dict:
        """The report for JSON: no curves; `version_differences` and
        `twig_differences` only when there are some."""
        out = {k: v for k, v in self.__dict__.items() if k != "curves"}
        out["worst"] = [w.__dict__ for w in self.worst]
        for key in ("version_differences", "twig_differences"):
            if not out[key]:
                del out[key]
        return out


def load_any(path: str | Path) -> Bake:
    """A bake (.npz, read lazily: its trees as they are asked for) or an
    exported glTF (.glb/.gltf) read back as a bake; a file listed in a
    manifest.json beside it is checked against its sha256."""
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{p}: is a folder, not a bake (.npz) or glTF export (.glb, .gltf)")
    if not p.is_file():
        raise InputError(f"{p}: file not found")
    if p.suffix.lower() in (".glb", ".gltf"):
        from .exchange.gltf_read import read_gltf_bake

        verify_against_manifest(p)
        return read_gltf_bake(p)
    return load_bake(p, lazy=True)  # the diff reads one tree at a time


def verify_against_manifest(path: Path) -> None:
    """Raise InputError if `path` is listed in the manifest.json of its folder
    with another size or sha256 (damaged or edited since the export)."""
    import json

    from .export import sha256

    manifest = path.parent / "manifest.json"
    try:
        files = json.loads(manifest.read_text(encoding="utf-8")).get("files", [])
    except (OSError, ValueError, AttributeError):
        return  # no (readable) manifest: the structure checks still apply
    for entry in files if isinstance(files, list) else []:
        if isinstance(entry, dict) and entry.get("path") == path.name:
            if path.stat().st_size != entry.get("bytes") or sha256(path) != entry.get("sha256"):
                raise InputError(f"{path}: does not match the size and sha256 recorded in "
                                 f"{manifest} (damaged or edited since the export); "
                                 "re-export it")
            return


def reduction_allowance(*bakes: Bake) -> tuple[float, float, str]:
    """(m, degrees, note): the keyframe-reduction tolerances the inputs
    declare (glTF files read back), summed: each may be that far from its
    bake."""
    pos = ang = 0.0
    names = []
    for b in bakes:
        r = b.meta.get("reduction")
        if isinstance(r, dict):
            pos += float(r.get("position_m", 0.0))
            ang += float(r.get("angle_deg", 0.0))
            names.append(Path(str(b.meta.get("source", "glTF"))).name)
    note = (f"keyframe reduction declared by {', '.join(names)}" if names and (pos or ang)
            else "")
    return pos, ang, note


def check_topology(a: Bake, b: Bake) -> None:
    """Raise TopologyError saying what differs, if anything structural does
    (reads each tree's info and parents only, not its motion)."""
    problems = []
    if len(a.times) != len(b.times):
        problems.append(f"frame counts differ: {len(a.times)} vs {len(b.times)} "
                        f"({a.times[-1]:.3f} vs {b.times[-1]:.3f} s: another duration or fps?)")
    elif not np.allclose(a.times, b.times, atol=1e-6):
        problems.append("frame times differ (another fps?)")
    info_a = [tree_info(a.trees, i) for i in range(len(a.trees))]
    info_b = [tree_info(b.trees, i) for i in range(len(b.trees))]
    names_a, names_b = [t["name"] for t in info_a], [t["name"] for t in info_b]
    if names_a != names_b:
        only_a = sorted(set(names_a) - set(names_b))
        only_b = sorted(set(names_b) - set(names_a))
        what = [f"only in A: {', '.join(only_a)}"] if only_a else []
        what += [f"only in B: {', '.join(only_b)}"] if only_b else []
        problems.append("trees differ (" + ("; ".join(what) or "same names, other order") + ")")
    else:
        for i, (ia, ib) in enumerate(zip(info_a, info_b)):
            name, paths = ia["name"], ia["paths"]
            if len(paths) != len(ib["paths"]):
                problems.append(f"tree {name!r}: {len(paths)} vs {len(ib['paths'])} segments")
                continue
            pa, pb = tree_field(a.trees, i, "seg_parent"), tree_field(b.trees, i, "seg_parent")
            if not np.array_equal(pa, pb):
                s = int(np.nonzero(pa != pb)[0][0])
                problems.append(f"tree {name!r}: segment {s} ({paths[s]}) hangs on "
                                f"{pa[s]} in A, {pb[s]} in B")
    if problems:
        raise TopologyError("cannot be compared frame by frame: " + "; ".join(problems))


def _tree_errors(ta: TreeBake, tb: TreeBake, frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Position error (F, S) m (worse of the two segment ends) and rotation
    error (F, S) degrees; static trees are held at their one frame."""
    segs = np.arange(ta.n_segments)
    # segments whose tip one side does not know (a glTF without tips): compare bases
    tipless = np.array(sorted(set(ta.info.get("tipless", [])) | set(tb.info.get("tipless", []))),
                       dtype=np.int64)

    def ends(t: TreeBake) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        base = t.positions.astype(float)
        tip = segment_ends(t, segs)
        if len(tipless):
            tip[:, tipless] = base[:, tipless]
        rot = t.rotations.astype(float)
        if t.positions.shape[0] == 1 and frames > 1:
            base, tip, rot = (np.repeat(x, frames, axis=0) for x in (base, tip, rot))
        return base, tip, rot

    base_a, tip_a, rot_a = ends(ta)
    base_b, tip_b, rot_b = ends(tb)
    pos = np.maximum(np.linalg.norm(base_a - base_b, axis=-1),
                     np.linalg.norm(tip_a - tip_b, axis=-1))
    ang = np.degrees(angle_between(rot_a, rot_b))
    return pos, ang


def _twig_difference(ta: TreeBake, tb: TreeBake, tolerance: float) -> str | None:
    """How tree ta's drawn twigs differ from tb's at rest (count, the
    segments they ride on, or an end moved more than `tolerance` m); None
    if they do not."""
    a, b = ta.twigs, tb.twigs
    if len(a) != len(b):
        return f"{ta.name}: {len(a)} vs {len(b)} twigs"
    if not len(a):
        return None
    if not np.array_equal(a.segment, b.segment):
        k = int(np.nonzero(a.segment != b.segment)[0][0])
        return f"{ta.name}: twig {k} rides on segment {a.segment[k]} in A, {b.segment[k]} in B"
    moved = np.maximum(np.linalg.norm(a.start.astype(float) - b.start, axis=1),
                       np.linalg.norm(a.end.astype(float) - b.end, axis=1))
    k = int(np.argmax(moved))
    if moved[k] > tolerance:
        return f"{ta.name}: twig {k} moved {moved[k]:.3g} m at rest"
    return None


def _read_back(bake: Bake) -> bool:
    """An exported file read back as a bake (glTF), which carries no twigs."""
    return "source" in bake.meta and "tool" not in bake.meta


def diff_bakes(a: Bake, b: Bake, position_tolerance: float = 1e-3,
               angle_tolerance: float = 0.1, worst: int = 5) -> DiffReport:
    """Compare two bakes of the same trees. Tolerances: metres and degrees,
    to which the keyframe-reduction tolerances glTF inputs declare are added.
    The trees are compared one at a time (a lazily read bake holds one in
    memory): memory follows the largest tree and the `worst` segments'
    curves, not the shot."""
    check_topology(a, b)
    allow_pos, allow_ang, note = reduction_allowance(a, b)
    user_pos, user_ang = position_tolerance, angle_tolerance
    tally = _Tally(len(a.times), user_pos + allow_pos, user_ang + allow_ang, worst)
    twigs = []
    for ta, tb in zip(a.trees, b.trees):
        tally.add(ta, *_tree_errors(ta, tb, tally.frames))
        twig = None if _read_back(a) or _read_back(b) else \
            _twig_difference(ta, tb, user_pos + allow_pos)
        twigs += [twig] if twig else []
    first = tally.first_frame()
    return DiffReport(
        frames=tally.frames, segments=tally.segments, max_position=tally.max_pos,
        max_position_percent=tally.max_pct, rms_position=tally.rms(tally.sum_pos2),
        max_angle=tally.max_ang, rms_angle=tally.rms(tally.sum_ang2), first_frame=first,
        first_time=float(a.times[first]) if first is not None else None,
        worst=tally.worst_rows(), noise=tally.noise() and not twigs,
        within=first is None and not twigs, twig_differences=twigs,
        position_tolerance=user_pos, angle_tolerance=user_ang, curves=tally.curves(),
        position_allowance=allow_pos, angle_allowance=allow_ang, allowance_note=note,
        version_differences=[] if first is None else version_differences(
            a.meta.get("versions"), b.meta.get("versions")),
        frame_start=_frame_start(a))


def _frame_start(bake: Bake) -> int:
    """The number a bake's first frame gets in its exports (scene key
    frame_start, default 1; export.frame_start)."""
    try:
        return int(bake.meta.get("frame_start", 1))
    except (TypeError, ValueError):
        return 1


class _Tally:
    """The diff's figures gathered tree by tree: maxima, sums of squares,
    the frames past a tolerance, and the `worst` segments (by the larger of
    position / tolerance and angle / tolerance; ties: the earlier segment)
    with their error curves."""

    def __init__(self, frames: int, position_tolerance: float, angle_tolerance: float,
                 worst: int):
        self.frames, self.tol_pos, self.tol_ang, self.keep = (frames, position_tolerance,
                                                              angle_tolerance, worst)
        self.segments = 0
        self.max_pos = self.max_ang = self.max_pct = self.sum_pos2 = self.sum_ang2 = 0.0
        self.scale = 1.0
        self.over = np.zeros(frames, dtype=bool)
        self.top: list[tuple[float, int, tuple]] = []  # (-score, segment number, row)

    def add(self, tree: TreeBake, pos: np.ndarray, ang: np.ndarray) -> None:
        """Tree `tree`'s position (F, S) m and angle (F, S) degree errors."""
        if pos.size:
            self.max_pos = max(self.max_pos, float(pos.max()))
            self.max_ang = max(self.max_ang, float(ang.max()))
            self.max_pct = max(self.max_pct, 100.0 * float(pos.max()) / max(tree.height, 1e-9))
        self.scale = max(self.scale, float(np.abs(tree.points).max(initial=0.0)))
        self.sum_pos2 += float(np.sum(pos**2))
        self.sum_ang2 += float(np.sum(ang**2))
        self.over |= ((pos > self.tol_pos) | (ang > self.tol_ang)).any(axis=1)
        score = np.maximum(pos.max(axis=0, initial=0.0) / self.tol_pos,
                           ang.max(axis=0, initial=0.0) / self.tol_ang)
        for s in np.argsort(-score, kind="stable")[:self.keep]:
            self.top.append((-float(score[s]), self.segments + int(s),
                             (tree.name, int(s), tree.paths[s], pos[:, s].copy(),
                              ang[:, s].copy())))
        self.top = sorted(self.top, key=lambda e: e[:2])[:self.keep]
        self.segments += pos.shape[1]

    def rms(self, sum_squares: float) -> float:
        return float(np.sqrt(sum_squares / max(self.frames * self.segments, 1)))

    def first_frame(self) -> int | None:
        bad = np.nonzero(self.over)[0]
        return int(bad[0]) if len(bad) else None

    def noise(self) -> bool:
        """Only float32 round-off: every error within it."""
        return bool(self.max_pos <= NOISE_RELATIVE * self.scale + 1e-9
                    and self.max_ang <= NOISE_ANGLE)

    def _moved(self):
        return [row for _, _, row in self.top if row[3].max() > 0 or row[4].max() > 0]

    def worst_rows(self) -> list[SegmentError]:
        out = []
        for name, s, path, p, g in self._moved():
            f = int(np.argmax(np.maximum(p / self.tol_pos, g / self.tol_ang)))
            out.append(SegmentError(name, s, path, float(p.max()), float(g.max()), f))
        return out

    def curves(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        return {f"{name} {path}": (p, g) for name, _, path, p, g in self._moved()}


def format_report(r: DiffReport, name_a: str = "A", name_b: str = "B") -> str:
    """The report as text."""
    if r.max_position == 0 and r.max_angle == 0 and not r.twig_differences:
        verdict = "identical"
    elif r.noise:
        verdict = "noise-level (float32 round-off)"
    elif r.within:
        verdict = "within tolerance"
    else:
        verdict = "DIFFERENT"
    lines = [f"{name_a} vs {name_b}: {verdict}",
             (f"  {r.segments} segments x {r.frames} frames ({r.frame_start}-"
              f"{r.frame_start + r.frames - 1}, as in the exports); tolerance "
              f"{r.position_tolerance:g} m, {r.angle_tolerance:g} deg" +
              (f" (+ {r.position_allowance:g} m, {r.angle_allowance:g} deg: "
               f"{r.allowance_note})" if r.allowance_note else "")),
             (f"  position: max {r.max_position:.3g} m ({r.max_position_percent:.3g} % of "
              f"height), rms {r.rms_position:.3g} m"),
             f"  rotation: max {r.max_angle:.3g} deg, rms {r.rms_angle:.3g} deg"]
    if r.first_frame is not None:  # numbered as in the exports, as a TD finds it in a DCC
        lines.append(f"  first frame past tolerance: {r.frame_start + r.first_frame} "
                     f"(t = {r.first_time:.3f} s)")
    if r.worst and (r.max_position > 0 or r.max_angle > 0):
        lines.append("  worst segments:")
        for w in r.worst:
            lines.append(f"    {w.tree} {w.path} (segment {w.segment}): {w.max_position:.3g} m, "
                         f"{w.max_angle:.3g} deg, worst at frame {r.frame_start + w.frame}")
    if r.twig_differences:
        lines.append("  twigs (drawn, not simulated) differ at rest:")
        lines += [f"    {line}" for line in r.twig_differences]
    if r.version_differences:
        lines.append(f"  made with other versions ({name_a} -> {name_b}):")
        lines += [f"    {line}" for line in r.version_differences]
    return "\n".join(lines)


def require_plots() -> None:
    """InputError unless matplotlib imports (--plot: asked before comparing)."""
    import importlib

    try:
        importlib.import_module("matplotlib")
    except ImportError:
        raise InputError("--plot needs matplotlib: pip install 'treebake[plots]'") from None


def plot_report(r: DiffReport, times: np.ndarray, path: str | Path) -> Path:
    """PNG of the worst segments' position and rotation error over time."""
    require_plots()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .fileio import atomic_path

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True)
    for label, (p, g) in r.curves.items():
        top.plot(times, p, label=label)
        bottom.plot(times, g, label=label)
    top.axhline(r.position_tolerance + r.position_allowance, color="0.5", ls="--", lw=0.8)
    bottom.axhline(r.angle_tolerance + r.angle_allowance, color="0.5", ls="--", lw=0.8)
    top.set_ylabel("position error, m")
    bottom.set_ylabel("rotation error, deg")
    bottom.set_xlabel("time, s")
    top.set_title("worst segments")
    if r.curves:
        top.legend(fontsize=7)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110, metadata={"Software": None})
    plt.close(fig)
    return Path(path)


def exit_code(r: DiffReport) -> int:
    return 0 if r.within else 1

