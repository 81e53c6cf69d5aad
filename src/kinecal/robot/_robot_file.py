"""Reading a robot YAML file (and the text of any YAML file kinecal reads): UTF-8 with
or without a byte-order mark (Windows Notepad writes one: the file was taken for "a CSV
table" by its first line), and a clear refusal of UTF-16 or another 8-bit encoding that
names the line."""

from __future__ import annotations

from pathlib import Path

from kinecal.errors import ConfigError
from kinecal.robot._description import RobotDescription
from kinecal.robot._schema import robot_from_dict

__all__ = ["MAX_TEXT_BYTES", "load_robot_file", "read_bounded", "read_text_file"]

# The largest robot or model YAML read [bytes]: a model of 100 sets and markers is
# about 100 kB; PyYAML reads about 0.5 MB/s with kinecal's duplicate-key checks.
MAX_TEXT_BYTES = 8 << 20


def read_bounded(p: Path, limit: int, what: str) -> bytes:
    """The bytes of ``p``, at most ``limit`` of them (ConfigError beyond: 3.4 MB of
    YAML took 6.5 s to read, 200 MB minutes; /dev/zero never ended, it filled the
    memory). OSError is left to the caller."""
    with p.open("rb") as f:
        raw = f.read(limit + 1)
    if len(raw) > limit:
        size = f"more than {limit >> 20} MB (a device or a pipe)"
        if p.is_file():
            size = f"{p.stat().st_size / 2**20:.1f} MB"
        raise ConfigError(
            f"{p}: {size}; expected {what} of at most {limit >> 20} MB (kinecal's own "
            "and robots' are well under 1 MB)."
        )
    return raw


def read_text_file(p: Path, what: str) -> str:
    """The text of ``p`` (UTF-8, a leading byte-order mark dropped); ConfigError naming
    ``p`` and the line for UTF-16 or bytes that are not UTF-8. ``what``: the file
    expected ('a robot YAML (or a URDF)', 'a model.yaml'). OSError is left to the
    caller."""
    raw = read_bounded(p, MAX_TEXT_BYTES, what)
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff") or b"\0" in raw[:4096]:
        raise ConfigError(
            f"{p}: UTF-16 encoded (or binary); expected {what} as UTF-8 text: save it "
            "as UTF-8."
        )
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise ConfigError(
            f"{p}: line {line}: byte 0x{raw[exc.start]:02x} is not UTF-8 (a Latin-1 or "
            f"Windows-1252 file?); expected {what} as UTF-8 text: save it as UTF-8."
        ) from None


def load_robot_file(path: str | Path) -> RobotDescription:
    """Load and validate a robot YAML file (the schema: :mod:`kinecal.robot._schema`)."""
    from kinecal import _yaml as yaml

    p = Path(path)
    try:
        text = read_text_file(p, "a robot YAML (or a URDF)")
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read robot file ({exc.strerror}).") from exc
    try:
        data = yaml.load(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: not valid YAML ({exc}).".replace("\n", " ")) from exc
    if data is None:
        raise ConfigError(f"{p}: the robot file is empty.")
    return robot_from_dict(data, source=str(p))
