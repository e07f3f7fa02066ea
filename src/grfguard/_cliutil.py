"""Helpers shared by the command-line modules: safe messages, input checks, the robot.

* Messages are printed as :class:`rich.text.Text`, never parsed as Rich markup: a path
  or a fault spec containing ``[...]`` is shown as typed.
* :func:`friendly` turns grfguard errors (and OS errors) into one ``error:`` line with
  exit code 2 and prints :class:`~grfguard.errors.GrfguardWarning` as ``warning:`` lines.
* :func:`read_toml` / :func:`check_monitor_toml` / :func:`check_thresholds_toml` validate
  a TOML file (exists, is a file, is UTF-8 text, parses, has the right tables and keys)
  before anything is computed; errors name the file, the key, what was expected and the fix.
* :func:`resolve_robot` / :func:`robot_for_log`: the robot comes from ``--robot`` (a TOML
  file or a shipped name) or from the log's metadata, never guessed.
"""

from __future__ import annotations

import dataclasses
import functools
import tomllib
import warnings
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.text import Text

from grfguard.errors import ConfigError, GrfguardError, GrfguardWarning, LogFormatError

__all__ = [
    "say",
    "friendly",
    "read_toml",
    "check_monitor_toml",
    "check_thresholds_toml",
    "check_faults_toml",
    "check_seed",
    "resolve_robot",
    "robot_for_log",
    "shipped_robot_names",
    "check_log_plausible",
    "ROBOT_HELP",
]

#: Help text of every ``--robot`` option.
ROBOT_HELP = "Robot: a robot TOML file or a shipped name (e.g. suralp)."

_TOML_MAX_BYTES = 10_000_000


def say(console: Console, message: str, label: str = "", style: str = "") -> None:
    """Print ``message`` (plain text, never markup) on ``console``, after an optional
    styled ``label`` such as ``error:``."""
    text = Text()
    if label:
        text.append(label, style=style)
        text.append(" ")
    text.append(str(message))
    console.print(text, highlight=False, soft_wrap=True)


def friendly(console: Console) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Decorator for typer commands: one red ``error:`` line and exit 2 on grfguard errors
    and OS errors; ``warning:`` lines for :class:`GrfguardWarning`."""
    import typer

    def deco(fn: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(fn)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", GrfguardWarning)
                try:
                    return fn(*args, **kwargs)
                except GrfguardError as exc:
                    _flush_warnings(console, caught)
                    say(console, str(exc), "error:", "bold red")
                    raise typer.Exit(2) from None
                except OSError as exc:
                    _flush_warnings(console, caught)
                    where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
                    say(console, f"{where}{exc.strerror or exc}", "error:", "bold red")
                    raise typer.Exit(2) from None
                finally:
                    _flush_warnings(console, caught)

        return wrapper

    return deco


def _flush_warnings(console: Console, caught: list[warnings.WarningMessage]) -> None:
    seen: set[str] = set()
    for w in caught:
        if issubclass(w.category, GrfguardWarning):
            msg = str(w.message)
            if msg not in seen:
                seen.add(msg)
                say(console, msg, "warning:", "bold yellow")
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    caught.clear()


# ----------------------------------------------------------------------------- seeds
def check_seed(seed: int, option: str = "--seed") -> int:
    """A seed must be an integer in ``[0, 2**63 - 1]`` (numpy's generators refuse negatives)."""
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**63:
        raise ConfigError(
            f"{option} = {seed!r} must be an integer from 0 to 2**63 - 1; pass e.g. {option} 0"
        )
    return seed


# ------------------------------------------------------------------------------ TOML
def read_toml(path: str | Path, what: str = "TOML file", option: str = "") -> dict[str, Any]:
    """Read ``path`` as TOML; every failure is a :class:`ConfigError` naming the file."""
    p = Path(path)
    lead = f"{option} {p}" if option else str(p)
    if not p.exists():
        raise ConfigError(f"{lead}: the {what} does not exist; check the path")
    if p.is_dir():
        raise ConfigError(f"{lead} is a directory; give the {what} (a .toml file) inside it")
    try:
        size = p.stat().st_size
        if size > _TOML_MAX_BYTES:
            raise ConfigError(f"{lead}: {size} bytes is too large for a {what}; is it a log?")
        data = p.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{lead}: cannot read the {what} ({exc.strerror or exc})") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise ConfigError(
            f"{lead} is not a text file (not UTF-8); give the {what} as TOML text"
        ) from None
    if "\x00" in text:
        raise ConfigError(f"{lead} is a binary file, not TOML; give the {what} as TOML text")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{lead} is not valid TOML ({exc}); fix the {what}") from None


def _type_name(v: Any) -> str:
    return {int: "an integer", float: "a number", str: "a string", bool: "a boolean",
            list: "an array"}.get(type(v), type(v).__name__)


def _check_table(doc: Mapping[str, Any], key: str, lead: str, known: Iterable[str],
                 header: str | None = None) -> None:
    header = header or f"[{key}]"
    if key not in doc:
        return
    table = doc[key]
    if not isinstance(table, dict):
        raise ConfigError(
            f"{lead}: key '{key}' must be a table ({header} followed by 'name = value' "
            f"lines), got {_type_name(table)} {table!r}; write it as a {header} table"
        )
    _check_keys(table, lead, header, known)


def _check_keys(table: Mapping[str, Any], lead: str, header: str, known: Iterable[str]) -> None:
    names = sorted(set(known))
    unknown = sorted(set(table) - set(names))
    if unknown:
        raise ConfigError(
            f"{lead}: unknown key(s) {unknown} in {header}; allowed keys: {names}; "
            "remove or rename them"
        )


def _field_names(cls: Any, skip: Iterable[str] = ()) -> list[str]:
    return [f.name for f in dataclasses.fields(cls) if f.name not in set(skip)]


def check_monitor_toml(path: str | Path, option: str = "--config") -> Any:
    """Validate a monitor config TOML and return the :class:`MonitorConfig` it describes.

    Tables ``[monitor]``, ``[observer]``, ``[thresholds]``, ``[vfs]``; anything else, a key
    that is not a table, or an unknown key is an error naming the file and the key.
    """
    from grfguard.detect.monitor import MonitorConfig
    from grfguard.detect.observer import ObserverConfig
    from grfguard.detect.thresholds import Thresholds
    from grfguard.estimate.config import VFSConfig

    p = Path(path)
    lead = f"{option} {p}"
    doc = read_toml(p, "monitor config", option)
    tables = {
        "monitor": _field_names(MonitorConfig, ("thresholds", "observer", "vfs")),
        "observer": _field_names(ObserverConfig),
        "thresholds": _field_names(Thresholds),
        "vfs": _field_names(VFSConfig),
    }
    unknown = sorted(set(doc) - set(tables))
    if unknown:
        raise ConfigError(
            f"{lead}: unknown top-level key(s) {unknown}; a monitor config has the tables "
            f"{['[' + t + ']' for t in tables]}"
        )
    for key, known in tables.items():
        _check_table(doc, key, lead, known)
    _warn_disabled(doc.get("thresholds"), lead)
    return _build(lambda: MonitorConfig.from_toml(p), lead)


def check_thresholds_toml(path: str | Path, option: str = "--thresholds") -> Any:
    """Validate a thresholds TOML (``[thresholds]`` table or top-level keys) and return it."""
    from grfguard.detect.thresholds import Thresholds

    p = Path(path)
    lead = f"{option} {p}"
    doc = read_toml(p, "thresholds file", option)
    if "channels" in doc:  # ankle F/T channel thresholds of `grfguard calibrate` (issue 9)
        from grfguard.detect.channels import ChannelConfig

        return _build(lambda: ChannelConfig.from_toml_text(p.read_text(), str(p)), lead)
    known = [*_field_names(Thresholds), "const_samples"]  # legacy: a count at 1 kHz
    if "thresholds" in doc:
        _check_table(doc, "thresholds", lead, known)
        extra = sorted(set(doc) - {"thresholds", "model_corrections"})
        if extra:
            raise ConfigError(f"{lead}: unknown top-level key(s) {extra}; only a [thresholds] "
                              "table and the [model_corrections] of `grfguard calibrate "
                              "--model` are allowed")
    else:
        _check_keys(doc, lead, "the file", known)
    _warn_disabled(doc.get("thresholds", doc), lead)
    return _build(lambda: Thresholds.from_toml(p), lead)


def _warn_disabled(table: Any, lead: str) -> None:
    """An infinite threshold switches its test off: say so (it is never silent)."""
    if not isinstance(table, Mapping):
        return
    off = sorted(k for k, v in table.items() if isinstance(v, float) and v == float("inf"))
    if off:
        warnings.warn(
            f"{lead}: threshold(s) {off} = inf switch those tests off; use finite values "
            "(`grfguard calibrate`) to keep them on",
            GrfguardWarning,
            stacklevel=3,
        )


def check_faults_toml(path: str | Path, option: str = "--faults") -> list[Any]:
    """Validate and read a fault TOML file (``[[fault]]`` tables)."""
    from grfguard.errors import FaultSpecError
    from grfguard.faults import load_faults

    p = Path(path)
    lead = f"{option} {p}"
    read_toml(p, "fault file", option)
    try:
        return load_faults(p)
    except GrfguardError as exc:
        raise FaultSpecError(f"{lead}: {exc}") from None
    except (TypeError, ValueError, KeyError, AttributeError) as exc:
        raise FaultSpecError(
            f"{lead}: bad [[fault]] table ({exc}); each needs sensor, kind, start and "
            "optional value, end"
        ) from None


def _build(make: Callable[[], Any], lead: str) -> Any:
    try:
        return make()
    except GrfguardError as exc:
        raise type(exc)(f"{lead}: {exc}") from None
    except (TypeError, ValueError, KeyError, AttributeError) as exc:
        raise ConfigError(f"{lead}: a value has the wrong type ({exc}); see the README for "
                          "the expected keys and types") from None


# ----------------------------------------------------------------------------- robot
def shipped_robot_names() -> list[str]:
    """Names ``--robot`` accepts besides a TOML file."""
    from grfguard.model import robot as robot_mod

    names = {"suralp"}
    registry = getattr(robot_mod, "SHIPPED_ROBOTS", None)
    if isinstance(registry, Mapping):
        names.update(str(k) for k in registry)
    lister = getattr(robot_mod, "shipped_robots", None)
    if callable(lister):
        try:
            names.update(str(k) for k in lister())
        except Exception:  # noqa: BLE001 - a broken registry must not hide the CLI error
            pass
    return sorted(names)


def resolve_robot(value: str | Path | None, option: str = "--robot") -> Any:
    """The robot named by ``--robot``: a TOML file path, or a shipped name; None if not given."""
    if value is None:
        return None
    from grfguard.model import robot as robot_mod

    text = str(value)
    p = Path(text)
    from grfguard.cli_robot import is_described_robot

    looks_like_path = p.suffix.lower() == ".toml" or p.exists() or "/" in text or "\\" in text
    if looks_like_path:
        read_toml(p, "robot TOML", option)  # a directory, binary or broken file: one line
    if text.lower() == "suralp":  # the built-in biped (its description file is for the sim)
        return robot_mod.SURALP
    if is_described_robot(text):  # Talos, G1 or a TOML with a model file
        from grfguard.model.description import load_description

        return _build(lambda: load_description(text), f"{option} {text}")
    if looks_like_path:
        return _build(lambda: robot_mod.RobotConfig.from_toml(p), f"{option} {p}")
    name = text.lower()
    if name == "suralp":
        return robot_mod.SURALP
    registry = getattr(robot_mod, "SHIPPED_ROBOTS", None)
    if isinstance(registry, Mapping) and name in registry:
        r = registry[name]
        return r() if callable(r) else r
    loader = getattr(robot_mod, "shipped_robot", None)
    if callable(loader):
        try:
            return loader(name)
        except GrfguardError:
            pass
    raise ConfigError(
        f"{option} {text!r} is neither a robot TOML file nor a shipped robot; shipped: "
        f"{shipped_robot_names()}; or write one with `grfguard robot show > my_robot.toml`"
    )


def robot_for_log(df: Any, robot: Any, where: str, option: str = "--robot") -> Any:
    """Attach ``robot`` (from ``--robot``) to ``df.attrs``, or check that the log's metadata
    names one. A log without robot metadata and no ``--robot`` is refused: grfguard never
    guesses the robot (a wrong mass flags every sensor)."""
    meta = df.attrs.get("robot")
    if robot is not None and hasattr(robot, "sensing"):  # a described robot
        df.attrs["robot"] = robot.to_dict()
        df.attrs["robot_name"] = robot.name
        df.attrs["sensing"] = robot.sensing
        return robot
    if robot is not None:
        if isinstance(meta, Mapping) and meta.get("mass") not in (None, robot.mass):
            warnings.warn(
                f"{where}: the log's metadata names robot {meta.get('name')!r} "
                f"({meta.get('mass')} kg); using {option} {robot.name!r} ({robot.mass} kg)",
                GrfguardWarning,
                stacklevel=2,
            )
        df.attrs["robot"] = robot.to_dict()
        return robot
    if meta is None:
        raise LogFormatError(
            f"{where} has no grfguard robot metadata (a plain CSV or a foreign log?): pass "
            f"the robot with {option} ROBOT.toml (write one with `grfguard robot show > "
            f"ROBOT.toml` and edit it) or {option} NAME ({', '.join(shipped_robot_names())})"
        )
    return None


def check_log_plausible(df: Any, robot: Any, where: str) -> None:
    """Refuse a log whose units or sensor wiring cannot be right for ``robot`` (forces in
    kN/kgf, acceleration in g, angles in degrees, a sensor on the wrong foot); warn about
    doubtful ones. ``robot`` None means the robot of ``df.attrs``."""
    from grfguard.io.plausibility import check_log

    if robot is None or hasattr(robot, "sensing"):
        robot = _robot_of_log(df)
        if robot is None:
            return
    issues = check_log(df, robot)
    for issue in issues:
        if issue.severity != "error":
            warnings.warn(f"{where}: {issue.message}", GrfguardWarning, stacklevel=2)
    errors = [i for i in issues if i.severity == "error"]
    if errors:
        more = f" (and {len(errors) - 1} more finding(s))" if len(errors) > 1 else ""
        raise LogFormatError(
            f"{where}: {errors[0].message}{more}; if the log is right, pass --no-unit-check"
        )


def _robot_of_log(df: Any) -> Any:
    """Something with the robot's ``mass`` [kg] from the log's metadata, or None."""
    import json
    from types import SimpleNamespace

    from grfguard.model.robot import RobotConfig

    mass = df.attrs.get("mass")
    if "sensing" in df.attrs and isinstance(mass, (int, float)) and mass > 0:
        return SimpleNamespace(mass=float(mass))  # a described robot (Talos, G1, ...)
    meta = df.attrs.get("robot")
    try:
        if isinstance(meta, str):
            meta = json.loads(meta)
        if isinstance(meta, Mapping):
            return RobotConfig.from_dict(dict(meta))
    except (GrfguardError, TypeError, ValueError):
        return None
    return None
