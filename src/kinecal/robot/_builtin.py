"""Built-in robot descriptions shipped with the package (``robot/data/*.yaml``).

The YAML files are the source (with their comments and provenance). ``data/builtin.json``
holds the same documents, parsed, so a command on a built-in robot (``kinecal fk``) does
not import PyYAML (9 ms of its start); ``python -m kinecal.robot._builtin`` writes it
again after a YAML file changed, and a test checks the two agree.
"""

from __future__ import annotations

import json
import sys
from functools import cache
from pathlib import Path
from typing import Any

from kinecal.errors import ConfigError
from kinecal.robot._description import RobotDescription
from kinecal.robot._robot_file import load_robot_file
from kinecal.robot._schema import robot_from_dict

__all__ = ["builtin_robot_names", "load_robot"]

# The package's data folder, next to this module (a plain path rather than
# importlib.resources, whose import costs ~10 ms of every command's start).
_DATA = Path(__file__).resolve().parent / "data"


def builtin_robot_names() -> list[str]:
    """Names of the robots shipped with kinecal, sorted."""
    return sorted(p.name[:-5] for p in _DATA.iterdir() if p.name.endswith(".yaml"))


_JSON = _DATA / "builtin.json"


@cache
def _documents() -> dict[str, Any]:
    """The parsed YAML documents of the built-in robots, by name (``builtin.json``)."""
    docs: dict[str, Any] = json.loads(_JSON.read_text(encoding="utf-8"))["robots"]
    return docs


@cache
def _load_builtin(name: str) -> RobotDescription:
    doc = _documents().get(name)
    if doc is None:  # a YAML file newer than builtin.json: read it
        from kinecal import _yaml as yaml

        doc = yaml.load((_DATA / f"{name}.yaml").read_text(encoding="utf-8"))
    return robot_from_dict(doc, source=name)


def parsed_yaml_documents() -> dict[str, Any]:
    """Each built-in robot's YAML file, parsed (what ``builtin.json`` must hold)."""
    from kinecal import _yaml as yaml

    return {
        name: yaml.load((_DATA / f"{name}.yaml").read_text(encoding="utf-8"))
        for name in builtin_robot_names()
    }


def write_builtin_json() -> Path:
    """Write ``builtin.json`` from the YAML files."""
    doc = {
        "generated": "by python -m kinecal.robot._builtin from the *.yaml files of this "
        "folder; edit those, then run it again",
        "robots": parsed_yaml_documents(),
    }
    _JSON.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    return _JSON


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
    if p.suffix.lower() in (".urdf", ".xacro") or _xml(p):  # (xacro: refused as one)
        if not p.exists():
            raise ConfigError(f"{p}: URDF file not found.")
        from kinecal.robot._urdf import robot_from_urdf

        return robot_from_urdf(p)
    if p.suffix.lower() in (".yaml", ".yml") or p.exists():
        if not p.exists():
            raise ConfigError(f"{p}: robot file not found.")
        _not_a_robot_file(p)
        return load_robot_file(p)
    raise ConfigError(
        f"unknown robot {s!r}: not a built-in ({', '.join(builtin_robot_names())}) "
        "and not a YAML or URDF file."
    )


def _xml(p: Path) -> bool:
    """Whether the file ``p`` (of another extension, or none) starts as an XML document
    (a URDF saved as robot.txt or robot: read as YAML, it was "expected a mapping; got
    str")."""
    try:
        with p.open("rb") as f:
            head = f.read(512)
    except OSError:
        return False
    head = head.removeprefix(b"\xef\xbb\xbf").lstrip()
    return head.startswith((b"<?xml", b"<robot", b"<!--", b"<!DOCTYPE"))


def _not_a_robot_file(p: Path) -> None:
    """Refuse the files a user hands ``--robot`` by mistake, naming what they are: a
    model.yaml of ``kinecal calibrate`` (was: "unknown key 'kinecal_model'"), a
    measurement or pose CSV (was: "expected a mapping; got str")."""
    try:
        with p.open("rb") as f:
            raw = f.read(4096)
    except OSError:
        return  # (the reader says why)
    if b"\0" in raw:  # UTF-16 or binary: the reader says so
        return
    head = raw.decode("utf-8-sig", "replace")  # (a byte-order mark: Notepad)
    if any(ln.startswith("kinecal_model:") for ln in head.splitlines()):
        raise ConfigError(
            f"{p}: a calibrated model (kinecal_model), not a robot file; expected a "
            "robot YAML or URDF (`kinecal export-urdf MODEL --format yaml-dh` writes the "
            "calibrated robot as one; evaluate, compensate, fk take the model as --model)."
        )
    first = next((ln for ln in head.splitlines() if ln.strip()), "")
    table = "," in first and ":" not in first and not first.startswith("#")
    if p.suffix.lower() in (".csv", ".txt") or table:
        raise ConfigError(
            f"{p}: a CSV table (first line {first[:60]!r}), not a robot file; expected a "
            "robot YAML or URDF, or a built-in name (kinecal robots)."
        )


if __name__ == "__main__":
    print(f"wrote {write_builtin_json()}")
    sys.exit(0)
