"""The stress suite's cases (`treebake stability`): trees built to be hard
and events on the production species, each a Case (a grammar, scene keys,
when the forcing stops, how long to run). What each case measures and the
pass criteria: exporter/stress.py."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .library import grammar_path, grammars_folder

WOOD = "density: 800\nmodulus: 8e9\ndamping: 0.05\n"


@dataclass
class Case:
    name: str
    what: str
    grammar: str  # grammar text, "species:NAME" (a bundled grammar) or "file:PATH"
    scene: dict  # scene keys (the tree is added)
    quiet: float  # s: when the forcing has stopped
    duration: float
    long: bool = False  # part of the full run only
    event: bool = False  # an event case: breaks and falls are expected
    # the tree the case is about: "species:NAME" or "file:PATH" (its grammar,
    # strengths dropped or not); "" for a case's own small tree
    tree: str = ""

    @property
    def kind(self) -> str:
        """The case without its tree's name: what CPU_SECONDS knows it by."""
        return "felling" if self.name.startswith("felling ") else self.name



def _unbreakable(path: Path, drop: tuple[str, ...] = ("rupture", "anchor")) -> str:
    """A grammar's text without its strengths (nothing breaks, nothing uproots)."""
    lines = [ln for ln in path.read_text().splitlines()
             if not any(ln.startswith(d + ":") for d in drop)]
    return "\n".join(lines) + "\n"


def _gust(speed: float, until: float) -> dict:
    return {"wind": {"speed": speed, "turbulence": 0.3, "ramp": 0.5, "end": until}}


def bundled_name(grammar: str | Path) -> str | None:
    """A grammar file's bundled name (`oak`, `forest/birch`); None outside
    the bundle."""
    try:
        return Path(grammar).resolve().relative_to(grammars_folder().resolve()).with_suffix(
            "").as_posix()
    except ValueError:
        return None


def tree_name(grammar: str | Path) -> str:
    """How the cases name a tree grown from `grammar` (a file): a bundled
    grammar by its name, any other by its file's stem."""
    return bundled_name(grammar) or Path(grammar).stem


def cases(long: bool = True, grammar: str | Path | None = None) -> list[Case]:
    """The stress cases; `long` adds the ten-minute runs and the events on
    the big species. With `grammar` (a file), every case on a tree of the
    bundled species (the sapling's wind, blasts, tornado and ten-minute
    runs, the felling, the crate) runs on that grammar's tree instead, and
    the six fellings are one; the cases on their own small trees stay."""
    out = _small_tree_cases() + _species_cases(grammar)
    return [c for c in out if long or not c.long]


def _small_tree_cases() -> list[Case]:
    """The cases on their own small trees: stiff joints, light twigs, cones,
    limbs drawn over each other, tiny segments, a long chain."""
    twig = "axiom: !(0.5)F(2)F(2)[&(60){k}@cone({cone})!({d})F(0.15)F(0.15)@leaves(1)F(0.1)]\n"
    out = []
    for factor in (1, 100, 10_000):
        k = "" if factor == 1 else f"@stiffness({1.6e3 * factor:g})"
        out.append(Case(f"stiff x{factor}", f"twig joints {factor}x the wood's stiffness",
                        WOOD + twig.format(k=k, cone=30, d=0.02), _gust(30, 2.0), 3.0, 8.0))
    for ratio, d in (("1:10^2", 0.05), ("1:10^4", 0.005)):
        out.append(Case(f"mass {ratio}", f"twig/trunk mass per length {ratio}, 2 deg cone, "
                        "stiff spring", WOOD + twig.format(k="@stiffness(2e4)", cone=2, d=d),
                        _gust(30, 2.0), 3.0, 8.0))
    for cone in (0.5, 5, 90):
        out.append(Case(f"cone {cone} deg", f"cone half-angle {cone} deg in a gale",
                        WOOD + twig.format(k="", cone=cone, d=0.02), _gust(30, 2.0), 3.0, 8.0))
    out.append(Case("overlapping", "limbs drawn over each other and folded back",
                    WOOD + "axiom: !(0.2)F(1)F(1)[!(0.05)F(1)][!(0.05)F(1)][!(0.05)F(1)]"
                           "[&(179)!(0.05)F(0.8)F(0.8)][&(90)!(0.04)F(0.5)&(180)F(0.5)]\n",
                    _gust(25, 2.0), 3.0, 8.0))
    out.append(Case("near-zero segments", "segments of 0, 1e-6 and 1e-4 m among normal ones",
                    WOOD + "axiom: !(0.2)F(1)F(0)F(1e-6)F(1)[&(45)!(0.03)F(1e-4)F(0.5)F(1e-6)"
                           "F(0.5)]F(1e-4)F(1)\n", _gust(25, 2.0), 3.0, 8.0))
    out.append(Case("1 mm between 1 m", "a 1 mm segment between 1 m ones, a branch on it, "
                    "pulled, then calm", WOOD + "axiom: !(0.1)F(1)F(1)!(0.05)F(0.001)"
                    "[&(50)!(0.03)F(1)F(1)]!(0.05)F(1)F(1)\n",
                    {"pull": [{"tree": 0, "force": [40.0, 0, 0], "release": 1.0, "at": 1.0,
                               "ramp": 0.5}]}, 1.0, 6.5))
    out.append(Case("200-segment chain", "a 5 m x 5 cm chain of 200 segments pulled with 7 N, "
                    "then released", WOOD + "axiom: !(0.05)" + "F(0.025)" * 200 + "\n",
                    {"pull": [{"tree": 0, "force": [7.0, 0, 0], "release": 1.5, "at": 1.0,
                               "ramp": 0.5}]}, 1.5, 6.5))
    return out


def _species_cases(grammar: str | Path | None) -> list[Case]:
    """The cases on the bundled species (or on `grammar`'s tree): strong
    wind, blasts, fellings, a crate, a blast and a tornado that break it,
    ten-minute runs."""
    out = []
    if grammar is None:
        small, plain = "sapling", _unbreakable(grammar_path("sapling"))
        a_small = "a sapling"
        fellings = (("sapling", False), ("spruce", False), ("oak", True), ("willow", True),
                    ("palm", True), ("bamboo", True))
        crate = "oak"

        def source(species: str) -> str:
            return f"species:{species}"
    else:
        path = Path(grammar).resolve()
        small = crate = tree_name(path)
        plain, fellings = _unbreakable(path), ((small, False),)
        a_small = f"the {small}"

        def source(species: str) -> str:
            return f"file:{path}"
    for speed in (45, 70):
        out.append(Case(f"wind {speed} m/s", f"{small} in {speed} m/s gusts (no breaking)",
                        plain, _gust(speed, 3.0), 4.0, 9.0, tree=source(small)))
    for charge, dist in ((2, 6), (50, 5), (500, 6)):
        out.append(Case(f"blast {charge} kg at {dist} m",
                        f"{charge} kg TNT {dist} m from {a_small} (no breaking)", plain,
                        {"explosion": [{"position": [dist, 0.0, 1.0], "time": 0.5,
                                        "charge": charge}]}, 1.5, 7.0, tree=source(small)))
    # events: breaking and felling with the species' own strengths
    for species, long_case in fellings:
        out.append(Case(f"felling {species}", f"{species} cut at its base, falls on its hinge",
                        source(species), {"cut": [{"tree": 0, "time": 0.5, "direction": 30.0}]},
                        7.0, 9.0, long=long_case, event=True, tree=source(species)))
    out.append(Case("crate breaks a stem", f"a 150 kg crate at 11 m/s into the {crate}'s stem",
                    source(crate), {"projectile": [{"shape": "box", "size": 0.8, "mass": 150.0,
                                                    "position": [0.0, -9.0, 3.0],
                                                    "velocity": [0.0, 11.0, 3.0],
                                                    "time": 0.5}]},
                    4.0, 6.0, long=True, event=True, tree=source(crate)))
    out.append(Case("blast breaks branches", f"10 kg TNT 4 m from {a_small}, breaking on",
                    source(small), {"explosion": [{"position": [4.0, 0.0, 1.0], "time": 0.5,
                                                   "charge": 10.0}]}, 3.0, 6.0, event=True,
                    tree=source(small)))
    out.append(Case("tornado uproots", f"an EF2 vortex through {a_small}, breaking on",
                    source(small), {"vortex": [{"start": [-30.0, 0.0], "velocity": [12.0, 0.0],
                                                "max_speed": 55.0, "core_radius": 15.0,
                                                "end": 4.0}]}, 4.0, 7.0, event=True,
                    tree=source(small)))
    out.append(Case("10 min gusty", "ten minutes of gusts, then ten seconds of calm",
                    plain, _gust(12, 600.0), 602.0, 612.0, long=True, tree=source(small)))
    out.append(Case("10 min calm", "ten minutes after a pull, prestressed, no wind",
                    plain, {"pull": [{"tree": 0, "force": [5.0, 0, 0], "release": 1.0}]},
                    1.0, 600.0, long=True, tree=source(small)))
    return out


