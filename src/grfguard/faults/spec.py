"""Fault specifications: parse ``SENSOR=KIND[:VALUE]@START[-END]`` and TOML lists.

A :class:`FaultSpec` says which sole sensor fails, how, from when to when [s] and
with which size. Units of ``value`` depend on the kind:

=============  ===========================================  ==============
kind           effect on the measured force                 ``value``
=============  ===========================================  ==============
``offset``     ``N_meas = N + value``                       [N], required
``drift``      ``N_meas = N + value * (t - start)``         [N/s], required
``frozen``     ``N_meas = value``                           [N], default 0
``stuck``      ``N_meas = N(last sample before start)``     none
``gain``       ``N_meas = value * N``                       [-], required
``noise``      ``N_meas = N + value * w``, ``w ~ N(0, 1)``  σ [N], required
``spikes``     ``N_meas = N + ±value`` at random samples    [N], required
``dropout``    ``N_meas = NaN``                             none
``saturation`` ``N_meas = min(N, value)``                   [N], required
=============  ===========================================  ==============
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from grfguard.errors import FaultSpecError
from grfguard.io.schema import FAULT_KINDS
from grfguard.model.robot import SENSOR_NAMES

__all__ = [
    "FAULT_KIND_NAMES",
    "FaultSpec",
    "parse_fault_spec",
    "parse_faults",
    "faults_from_toml",
    "faults_to_toml",
    "load_faults",
]

#: Injectable fault kinds (``none`` and ``unknown`` are classification outputs only).
FAULT_KIND_NAMES: tuple[str, ...] = tuple(k for k in FAULT_KINDS if k not in ("none", "unknown"))
_VALUE_REQUIRED = {"offset", "drift", "gain", "noise", "spikes", "saturation"}
_VALUE_FORBIDDEN = {"stuck", "dropout"}
_DEFAULT_VALUE = {"frozen": 0.0, "stuck": 0.0, "dropout": 0.0}
_UNITS = {
    "offset": "[N]",
    "drift": "[N/s]",
    "frozen": "[N]",
    "gain": "[-]",
    "noise": "sigma [N]",
    "spikes": "amplitude [N]",
    "saturation": "[N]",
}
#: Default rate of spikes [1/s].
DEFAULT_SPIKE_RATE_HZ = 5.0

_FORMS = (
    "accepted forms: SENSOR=KIND[:VALUE]@START[-END], e.g. 'r2=offset:100@5', "
    "'r3=drift:15@5', 'r1=frozen:0@5', 'r4=stuck@5', 'l2=noise:20@3-9'; "
    f"SENSOR in {', '.join(SENSOR_NAMES)}; KIND in {', '.join(FAULT_KIND_NAMES)}"
)

_NUM = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|[+-]?inf"
_SPEC_RE = re.compile(
    r"^\s*(?P<sensor>[^=\s]+)\s*=\s*(?P<kind>[A-Za-z_]+)\s*(?::\s*(?P<value>[^@]*?))?\s*"
    r"@\s*(?P<start>\S+?)\s*(?:-\s*(?P<end>" + _NUM + r"|\S+))?\s*$"
)


@dataclass(frozen=True)
class FaultSpec:
    """One injected sensor fault.

    Attributes:
        sensor: Sensor name (``r1`` ... ``l4``).
        kind: Fault kind, one of :data:`FAULT_KIND_NAMES`.
        value: Size of the fault; unit by kind (see the module docstring).
        start: Onset time in [s] (log ``time``), inclusive.
        end: End time in [s], exclusive; ``inf`` for a permanent fault.
        rate: Spike rate in [1/s] (``spikes`` only).
    """

    sensor: str
    kind: str
    value: float = 0.0
    start: float = 0.0
    end: float = math.inf
    rate: float = DEFAULT_SPIKE_RATE_HZ

    def __post_init__(self) -> None:
        where = f"fault {self.sensor}={self.kind}"
        if self.sensor not in SENSOR_NAMES:
            raise FaultSpecError(f"{where}: unknown sensor {self.sensor!r}; {_FORMS}")
        if self.kind not in FAULT_KIND_NAMES:
            raise FaultSpecError(f"{where}: unknown fault kind {self.kind!r}; {_FORMS}")
        for name in ("value", "start", "end", "rate"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v):
                raise FaultSpecError(f"{where}: {name} must be a number, got {v!r}; {_FORMS}")
            object.__setattr__(self, name, float(v))
        if not math.isfinite(self.value) or not math.isfinite(self.start):
            raise FaultSpecError(f"{where}: value and start must be finite; {_FORMS}")
        if self.end <= self.start:
            raise FaultSpecError(
                f"{where}: end {self.end} s must be later than start {self.start} s; {_FORMS}"
            )
        if self.kind == "noise" and self.value <= 0:
            raise FaultSpecError(f"{where}: noise sigma must be > 0 N, got {self.value}")
        if self.kind == "spikes" and self.rate <= 0:
            raise FaultSpecError(f"{where}: spike rate must be > 0 1/s, got {self.rate}")

    @property
    def window(self) -> tuple[float, float]:
        """``(start, end)`` in [s]."""
        return (self.start, self.end)

    def to_spec_string(self) -> str:
        """The ``SENSOR=KIND[:VALUE]@START[-END]`` form of this fault."""
        val = "" if self.kind in _VALUE_FORBIDDEN else f":{self.value:g}"
        end = "" if math.isinf(self.end) else f"-{self.end:g}"
        return f"{self.sensor}={self.kind}{val}@{self.start:g}{end}"

    def to_dict(self) -> dict[str, Any]:
        """Plain dict (``end`` omitted when permanent), for TOML/JSON."""
        d = asdict(self)
        if math.isinf(self.end):
            d.pop("end")
        if self.kind != "spikes":
            d.pop("rate")
        return d


def _number(text: str | None, what: str, spec: str) -> float:
    try:
        return float(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise FaultSpecError(f"fault {spec!r}: {what} {text!r} is not a number; {_FORMS}") from None


def parse_fault_spec(spec: str) -> FaultSpec:
    """Parse one fault string ``SENSOR=KIND[:VALUE]@START[-END]``.

    Args:
        spec: For example ``"r2=offset:100@5"`` or ``"l2=noise:20@3-9"``.

    Returns:
        The parsed :class:`FaultSpec`.

    Raises:
        FaultSpecError: If the string does not follow the form, names an unknown sensor or
            kind, has a bad number, ``end <= start`` or lacks a required value.
    """
    if not isinstance(spec, str):
        raise FaultSpecError(f"fault spec must be a string, got {spec!r}; {_FORMS}")
    m = _SPEC_RE.match(spec)
    if m is None:
        raise FaultSpecError(f"cannot parse fault {spec!r}; {_FORMS}")
    sensor = m["sensor"].strip().lower()
    kind = m["kind"].strip().lower()
    if sensor not in SENSOR_NAMES:
        raise FaultSpecError(f"fault {spec!r}: unknown sensor {sensor!r}; {_FORMS}")
    if kind not in FAULT_KIND_NAMES:
        raise FaultSpecError(f"fault {spec!r}: unknown fault kind {kind!r}; {_FORMS}")
    vtext = m["value"]
    if vtext is not None and vtext.strip() == "":
        vtext = None
    if vtext is None:
        if kind in _VALUE_REQUIRED:
            raise FaultSpecError(
                f"fault {spec!r}: kind {kind!r} needs a value {_UNITS[kind]}, "
                f"e.g. '{sensor}={kind}:10@{m['start']}'; {_FORMS}"
            )
        value = _DEFAULT_VALUE.get(kind, 0.0)
    else:
        if kind in _VALUE_FORBIDDEN:
            raise FaultSpecError(
                f"fault {spec!r}: kind {kind!r} takes no value, write '{sensor}={kind}@...'"
            )
        value = _number(vtext, "value", spec)
    start = _number(m["start"], "start time", spec)
    end = math.inf if m["end"] is None else _number(m["end"], "end time", spec)
    return FaultSpec(sensor=sensor, kind=kind, value=value, start=start, end=end)


def _from_mapping(d: Mapping[str, Any], where: str) -> FaultSpec:
    allowed = {"sensor", "kind", "value", "start", "end", "rate"}
    extra = set(d) - allowed
    if extra:
        raise FaultSpecError(f"{where}: unknown keys {sorted(extra)}; allowed {sorted(allowed)}")
    for key in ("sensor", "kind", "start"):
        if key not in d:
            raise FaultSpecError(f"{where}: missing key {key!r} (needs sensor, kind, start)")
    kind = str(d["kind"]).lower()
    if "value" not in d and kind in _VALUE_REQUIRED:
        raise FaultSpecError(
            f"{where}: kind {kind!r} needs 'value' {_UNITS.get(kind, '')}; {_FORMS}"
        )
    kwargs = {k: d[k] for k in ("value", "start", "end", "rate") if k in d}
    if "value" not in kwargs:
        kwargs["value"] = _DEFAULT_VALUE.get(kind, 0.0)
    return FaultSpec(sensor=str(d["sensor"]).lower(), kind=kind, **kwargs)


def parse_faults(faults: Iterable[str | FaultSpec | Mapping[str, Any]] | str) -> list[FaultSpec]:
    """Normalise strings, dicts and :class:`FaultSpec` objects into a list of specs.

    A single string may hold several faults separated by commas or semicolons.
    """
    if isinstance(faults, str):
        faults = [p for p in re.split(r"[;,]", faults) if p.strip()]
    out: list[FaultSpec] = []
    for i, f in enumerate(faults):
        if isinstance(f, FaultSpec):
            out.append(f)
        elif isinstance(f, str):
            out.append(parse_fault_spec(f))
        elif isinstance(f, Mapping):
            out.append(_from_mapping(f, f"fault #{i + 1}"))
        else:
            raise FaultSpecError(f"fault #{i + 1}: cannot use {f!r}; {_FORMS}")
    return out


def faults_from_toml(text: str) -> list[FaultSpec]:
    """Parse a TOML document with a ``[[fault]]`` array of tables.

    Each table has ``sensor``, ``kind``, ``start`` [s] and optionally ``value``,
    ``end`` [s] and ``rate`` [1/s].
    """
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise FaultSpecError(f"fault TOML is not valid TOML: {exc}") from exc
    items = doc.get("fault")
    if not isinstance(items, list):
        raise FaultSpecError(
            "fault TOML needs a [[fault]] array, e.g. "
            "'[[fault]]\\nsensor = \"r2\"\\nkind = \"offset\"\\nvalue = 100\\nstart = 5'"
        )
    return [_from_mapping(d, f"[[fault]] #{i + 1}") for i, d in enumerate(items)]


def faults_to_toml(faults: Iterable[FaultSpec]) -> str:
    """Write faults as a ``[[fault]]`` TOML document (inverse of :func:`faults_from_toml`)."""
    lines: list[str] = []
    for f in faults:
        lines.append("[[fault]]")
        for k, v in f.to_dict().items():
            lines.append(f'{k} = "{v}"' if isinstance(v, str) else f"{k} = {v!r}")
        lines.append("")
    return "\n".join(lines)


def load_faults(path: str | Path) -> list[FaultSpec]:
    """Read a fault TOML file (see :func:`faults_from_toml`)."""
    p = Path(path)
    if not p.is_file():
        raise FaultSpecError(f"fault file {str(p)!r} does not exist")
    return faults_from_toml(p.read_text())

