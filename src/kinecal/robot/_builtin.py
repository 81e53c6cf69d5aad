"""Built-in robot descriptions shipped with the package (``robot/data/*.yaml``)."""

from __future__ import annotations

from functools import cache
from pathlib import Path

from kinecal import _yaml as yaml
from kinecal.errors import ConfigError
from kinecal.robot._description import RobotDescription
from kinecal.robot._schema import load_robot_file, robot_from_dict

__all__ = ["builtin_robot_names", "load_robot"]

# The package's data folder, next to this module (a plain path rather than
# importlib.resources, whose import costs ~10 ms of every command's start).
_DATA = Path(__file__).resolve().parent / "data"


def builtin_robot_names() -> list[str]:
    """Names of the robots shipped with kinecal, sorted."""
    return sorted(p.name[:-5] for p in _DATA.iterdir() if p.name.endswith(".yaml"))


@cache
def _load_builtin(name: str) -> RobotDescription:
    text = (_DATA / f"{name}.yaml").read_text(encoding="utf-8")
    return robot_from_dict(yaml.load(text), source=name)


def load_robot(name_or_path: str | Path) -> RobotDescription:
    """A built-in robot by name (e.g. ``'fanuc-lrmate200id'``), a robot YAML file, or a
    URDF file (its unbranched chain from the root link, see :func:`robot_from_urdf`).

    Raises
    ------
    ConfigError
        Unknown name and no such file, or an invalid file.
    """
    s = str(name_or_path)
    if s in builtin_robot_names():
        return _load_builtin(s)
    p = Path(s)
    if p.suffix.lower() == ".urdf":
        if not p.exists():
            raise ConfigError(f"{p}: URDF file not found.")
        from kinecal.robot._urdf import robot_from_urdf

        return robot_from_urdf(p)
    if p.suffix.lower() in (".yaml", ".yml") or p.exists():
        if not p.exists():
            raise ConfigError(f"{p}: robot file not found.")
        return load_robot_file(p)
    raise ConfigError(
        f"unknown robot {s!r}: not a built-in ({', '.join(builtin_robot_names())}) "
        "and not a YAML or URDF file."
    )
