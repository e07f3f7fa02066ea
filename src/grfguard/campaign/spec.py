"""Campaign specs: a TOML file expanded into cells with stable ids.

A campaign is data (STYLE.md item 11). The TOML has a ``[campaign]`` table and one or
more ``[[group]]`` tables; each group is a full product grid, the campaign the union
of its groups::

    [campaign]
    name = "paper-onset"
    tolerance_s = 1.0                 # alarms this long after a window still count

    [[group]]
    name = "sizes"
    methods = ["default", "paper"]
    threshold_scales = [1.0]          # multiplies every detector threshold
    sensors = ["r2"]
    onsets_s = [5.0, 5.5, 6.0, 6.5]   # fault onsets [s] (phase of the stride)
    window_s = 4.0                    # each cell sees the walk up to onset + window_s
    fault_free = false                # true: one fault-free cell per walk (no grid)
    [group.faults]                    # kind -> sizes (unit by kind, grfguard.faults)
    offset = [5.0, 10.0, 20.0]
    stuck = []                        # kinds without a size: an empty list
    [group.walks]
    robot = "suralp"
    gaits = [[0.12, 1.0]]             # [step_length_m, step_period_s]
    seeds = [0, 1, 2]                 # simulation seed (sensor noise)
    duration_s = 11.0                 # simulated walk [s]

A :class:`Cell` is one detector run on one walk; its id hashes every parameter that
changes its result, so ids do not depend on the order in the file and a cell shared
by two campaigns has the same id. A :class:`Walk` is one fault-free simulation; its
id starts with the versioned scenario id (``suralp-walk-v1``), and every cell that
injects into it shares it.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from grfguard.errors import ConfigError
from grfguard.faults.spec import FAULT_KIND_NAMES
from grfguard.model.robot import SENSOR_NAMES

__all__ = ["Walk", "Cell", "Group", "CampaignSpec", "load_spec", "parse_spec", "size_magnitude"]

_METHODS = ("default", "paper")
_ROBOTS = ("suralp",)
#: Kinds whose ``value`` is not set by the user.
_SIZELESS = ("stuck", "dropout")


def _hash(data: dict[str, Any]) -> str:
    text = json.dumps(data, sort_keys=True, separators=(",", ":"), allow_nan=True)
    return hashlib.sha1(text.encode()).hexdigest()[:12]


def size_magnitude(kind: str, size: float) -> float:
    """How far a fault of ``kind`` and ``size`` is from no fault (for "smallest").

    ``|size - 1|`` for ``gain``, ``|size|`` for additive kinds; NaN where size has no
    order (``frozen``, ``stuck``, ``dropout``, ``saturation``, ``none``).
    """
    if kind == "gain":
        return abs(size - 1.0)
    if kind in ("offset", "drift", "noise", "spikes"):
        return abs(size)
    return math.nan


@dataclass(frozen=True)
class Walk:
    """One fault-free simulated walk (simulated once per campaign, shared by its cells).

    Attributes:
        robot: Robot name (``suralp``).
        step_length_m: Step length [m].
        step_period_s: Step period [s].
        duration_s: Simulated time [s].
        seed: Seed of the sensor noise.
    """

    robot: str
    step_length_m: float
    step_period_s: float
    duration_s: float
    seed: int

    @property
    def scenario(self) -> str:
        """Versioned scenario id of the simulation (``suralp-walk-v1``)."""
        from grfguard.sim import SCENARIO

        return SCENARIO if self.robot == "suralp" else f"{self.robot}-walk-v1"

    @property
    def walk_id(self) -> str:
        """``<scenario>-<hash of the parameters>``."""
        return f"{self.scenario}-{_hash({'scenario': self.scenario, **asdict(self)})}"


@dataclass(frozen=True)
class Cell:
    """One detector run: a walk, optionally one injected fault, a method, a threshold scale.

    Attributes:
        walk: The fault-free walk the fault is injected into.
        method: ``default`` or ``paper``.
        threshold_scale: Factor on every detector threshold (1 = shipped thresholds).
        kind: Fault kind, or ``none`` for a fault-free cell.
        size: Fault value (unit by kind; NaN when the kind has none).
        sensor: Faulty sensor (``""`` when fault-free).
        onset_s: Fault onset [s] (NaN when fault-free).
        end_s: The cell sees the walk up to this time [s].
        tolerance_s: Alarms this long after a fault window still belong to it [s].
        group: Name of the spec group that made the cell (not part of the id).
    """

    walk: Walk
    method: str
    threshold_scale: float
    kind: str
    size: float
    sensor: str
    onset_s: float
    end_s: float
    tolerance_s: float
    group: str = field(default="", compare=False)

    def params(self) -> dict[str, Any]:
        """Every parameter that changes the result (the id's input)."""
        d = asdict(self)
        d.pop("group")
        d["walk"] = self.walk.walk_id
        return d

    @property
    def cell_id(self) -> str:
        """Stable id ``<kind>-<hash>``: same parameters, same id, in any campaign."""
        return f"{self.kind}-{_hash(self.params())}"

    def fault_string(self) -> str:
        """The fault as ``SENSOR=KIND[:VALUE]@START`` (``""`` when fault-free)."""
        if self.kind == "none":
            return ""
        val = "" if self.kind in _SIZELESS else f":{self.size!r}"
        return f"{self.sensor}={self.kind}{val}@{self.onset_s!r}"


def _list(where: str, key: str, value: Any, typ: type | tuple[type, ...]) -> list:
    if not isinstance(value, list) or not value:
        raise ConfigError(f"{where}: {key} must be a non-empty list, got {value!r}")
    for v in value:
        if isinstance(v, bool) or not isinstance(v, typ):
            raise ConfigError(f"{where}: every entry of {key} must be {typ}, got {v!r}")
    return value


def _walks(where: str, d: dict[str, Any]) -> list[Walk]:
    allowed = {"robot", "gaits", "seeds", "duration_s"}
    extra = set(d) - allowed
    if extra:
        raise ConfigError(f"{where}.walks: unknown keys {sorted(extra)}; allowed {sorted(allowed)}")
    robot = d.get("robot", "suralp")
    if robot not in _ROBOTS:
        raise ConfigError(f"{where}.walks: robot {robot!r} unknown; use one of {list(_ROBOTS)}")
    gaits = _list(f"{where}.walks", "gaits", d.get("gaits", [[0.12, 1.0]]), list)
    seeds = _list(f"{where}.walks", "seeds", d.get("seeds", [0]), int)
    dur = d.get("duration_s")
    if isinstance(dur, bool) or not isinstance(dur, (int, float)) or not 2.0 <= dur <= 3600.0:
        raise ConfigError(f"{where}.walks: duration_s = {dur!r} must be a number in [2, 3600] s")
    out = []
    for g in gaits:
        if len(g) != 2 or not all(isinstance(x, (int, float)) for x in g):
            raise ConfigError(
                f"{where}.walks: a gait is [step_length_m, step_period_s], got {g!r}"
            )
        for seed in seeds:
            out.append(Walk(robot, float(g[0]), float(g[1]), float(dur), int(seed)))
    return out


@dataclass(frozen=True)
class Group:
    """One product grid of a campaign (see the module docstring)."""

    name: str
    walks: tuple[Walk, ...]
    methods: tuple[str, ...]
    threshold_scales: tuple[float, ...]
    faults: tuple[tuple[str, float], ...]
    sensors: tuple[str, ...]
    onsets_s: tuple[float, ...]
    window_s: float
    fault_free: bool

    def cells(self, tolerance_s: float) -> list[Cell]:
        """Every cell of the grid."""
        out = []
        for walk, method, scale in itertools.product(
            self.walks, self.methods, self.threshold_scales
        ):
            if self.fault_free:
                out.append(Cell(walk, method, scale, "none", math.nan, "", math.nan,
                                walk.duration_s, tolerance_s, self.name))
                continue
            for (kind, size), sensor, onset in itertools.product(
                self.faults, self.sensors, self.onsets_s
            ):
                out.append(Cell(walk, method, scale, kind, size, sensor, onset,
                                onset + self.window_s, tolerance_s, self.name))
        return out


def _group(i: int, d: dict[str, Any]) -> Group:
    name = d.get("name", f"group{i}")
    where = f"group {name!r}"
    allowed = {"name", "methods", "threshold_scales", "faults", "sensors", "onsets_s",
               "window_s", "fault_free", "walks"}
    extra = set(d) - allowed
    if extra:
        raise ConfigError(f"{where}: unknown keys {sorted(extra)}; allowed {sorted(allowed)}")
    if "walks" not in d:
        raise ConfigError(f"{where}: needs a [group.walks] table (gaits, seeds, duration_s)")
    walks = _walks(where, d["walks"])
    methods = _list(where, "methods", d.get("methods", list(_METHODS)), str)
    for m in methods:
        if m not in _METHODS:
            raise ConfigError(f"{where}: method {m!r} unknown; use {list(_METHODS)}")
    scales = _list(where, "threshold_scales", d.get("threshold_scales", [1.0]), (int, float))
    if any(not 0.05 <= s <= 20 for s in scales):
        raise ConfigError(f"{where}: threshold_scales {scales} must lie in [0.05, 20]")
    fault_free = bool(d.get("fault_free", False))
    faults: list[tuple[str, float]] = []
    sensors: list[str] = []
    onsets: list[float] = []
    window = 0.0
    if not fault_free:
        fdict = d.get("faults")
        if not isinstance(fdict, dict) or not fdict:
            raise ConfigError(f"{where}: needs [group.faults] (kind = [sizes]) or fault_free")
        for kind, sizes in fdict.items():
            if kind not in FAULT_KIND_NAMES:
                raise ConfigError(f"{where}: fault kind {kind!r} unknown; use {FAULT_KIND_NAMES}")
            if kind in _SIZELESS:
                faults.append((kind, math.nan))
                continue
            for s in _list(where, f"faults.{kind}", sizes, (int, float)):
                faults.append((kind, float(s)))
        sensors = _list(where, "sensors", d.get("sensors", ["r2"]), str)
        for s in sensors:
            if s not in SENSOR_NAMES:
                raise ConfigError(f"{where}: sensor {s!r} unknown; use {list(SENSOR_NAMES)}")
        onsets = [float(x) for x in _list(where, "onsets_s", d.get("onsets_s"), (int, float))]
        window = d.get("window_s", 4.0)
        if isinstance(window, bool) or not isinstance(window, (int, float)) or window <= 0:
            raise ConfigError(f"{where}: window_s = {window!r} must be a number > 0 s")
        for w in walks:
            if max(onsets) + window > w.duration_s + 1e-9:
                raise ConfigError(
                    f"{where}: onset {max(onsets)} s + window_s {window} s is past the end "
                    f"of the {w.duration_s} s walk; lengthen walks.duration_s"
                )
    return Group(name, tuple(walks), tuple(methods), tuple(float(s) for s in scales),
                 tuple(faults), tuple(sensors), tuple(onsets), float(window), fault_free)


@dataclass(frozen=True)
class CampaignSpec:
    """A parsed campaign: name, groups, matching tolerance.

    Attributes:
        name: Campaign name.
        description: Free text.
        tolerance_s: Alarms this long after a fault window still belong to it [s].
        groups: The product grids.
        text: The TOML source (copied next to the results).
    """

    name: str
    description: str
    tolerance_s: float
    groups: tuple[Group, ...]
    text: str = ""

    def cells(self) -> list[Cell]:
        """All cells, duplicates (same id) removed, in a stable order."""
        seen: dict[str, Cell] = {}
        for g in self.groups:
            for c in g.cells(self.tolerance_s):
                seen.setdefault(c.cell_id, c)
        return list(seen.values())

    def walks(self) -> list[Walk]:
        """The distinct walks the cells need."""
        seen: dict[str, Walk] = {}
        for c in self.cells():
            seen.setdefault(c.walk.walk_id, c.walk)
        return list(seen.values())


def parse_spec(text: str, source: str = "<text>") -> CampaignSpec:
    """Parse a campaign TOML text.

    Raises:
        ConfigError: Saying which key of which group is wrong and what is allowed.
    """
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"campaign spec {source}: not valid TOML: {exc}") from exc
    head = doc.get("campaign")
    if not isinstance(head, dict) or "name" not in head:
        raise ConfigError(f"campaign spec {source}: needs a [campaign] table with a name")
    extra = set(doc) - {"campaign", "group"}
    if extra:
        raise ConfigError(f"campaign spec {source}: unknown tables {sorted(extra)}; "
                          "use [campaign] and [[group]]")
    groups = doc.get("group")
    if not isinstance(groups, list) or not groups:
        raise ConfigError(f"campaign spec {source}: needs at least one [[group]]")
    tol = head.get("tolerance_s", 1.0)
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or tol < 0:
        raise ConfigError(f"campaign spec {source}: tolerance_s = {tol!r} must be >= 0 s")
    try:
        parsed = tuple(_group(i, g) for i, g in enumerate(groups))
    except ConfigError as exc:
        raise ConfigError(f"campaign spec {source}: {exc}") from None
    return CampaignSpec(str(head["name"]), str(head.get("description", "")), float(tol),
                        parsed, text)


def load_spec(path: str | Path) -> CampaignSpec:
    """Read and parse a campaign TOML file."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"campaign spec {str(p)!r} does not exist; see campaigns/*.toml")
    return parse_spec(p.read_text(), str(p))
