"""Reading a URDF file a user hands kinecal (``--robot``, ``import-urdf``,
``export-urdf --like``): one gate for every reader, before any element is looked at.

Refused, naming the file (and the line where there is one):

- a folder, a file over :data:`MAX_URDF_BYTES` (expat parses one long token, a comment
  of 40 MB, in quadratic time when fed in pieces: 13 s; 200 MB did not end), an empty
  file;
- bytes that are not UTF-8 without an XML declaration naming their encoding;
- XML entity declarations (``<!ENTITY``): a URDF has none; entities expand a document
  without bound ("billion laughs") or read other files (external entities); the refusal
  does not depend on the expat version's own limits;
- xacro: its elements, a ``xacro:`` prefix without its namespace, a ``${...}`` or ``$(...)``
  expression left in an attribute (a ``.xacro`` file or a half-expanded one).

The document is parsed in one piece (linear time).
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

from kinecal.errors import ConfigError
from kinecal.robot._robot_file import read_bounded

__all__ = ["MAX_URDF_BYTES", "read_urdf"]

# The largest URDF read [bytes]: the URDFs of industrial arms and humanoids are 10 kB to
# 1 MB (meshes are separate files); a 32 MB document parses in under a second.
MAX_URDF_BYTES = 32 << 20
_EXPAND = "expand it first: xacro FILE.xacro > FILE.urdf"


def _line(raw: bytes, pos: int) -> int:
    return raw.count(b"\n", 0, pos) + 1


def _text(raw: bytes, p: Path) -> str:
    """The document's text: UTF-16 with its byte-order mark, the encoding its XML
    declaration names, else UTF-8 (ConfigError naming the line of a byte that is not)."""
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
        return raw.decode("utf-16", errors="replace")
    decl = re.match(rb"(?:\xef\xbb\xbf)?\s*<\?xml[^>]*encoding=[\"']([\w.:-]+)", raw)
    enc = decl.group(1).decode("ascii").lower() if decl else "utf-8"
    if enc.replace("-", "").replace("_", "") not in ("utf8", "usascii", "ascii"):
        try:
            return raw.decode(enc, errors="replace")
        except LookupError:
            raise ConfigError(
                f"{p}: line 1: the XML declaration names encoding {enc!r}, which is not "
                "known; expected a URDF in UTF-8."
            ) from None
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"{p}: line {_line(raw, exc.start)}: byte 0x{raw[exc.start]:02x} is not "
            "UTF-8 and no XML declaration names another encoding (a Latin-1 or "
            "Windows-1252 file?); expected a URDF in UTF-8: save it as UTF-8."
        ) from None


def _no_comments(text: str) -> str:
    """``text`` with its XML comments blanked, line ends kept (lines still count)."""
    return re.sub(
        r"<!--.*?-->", lambda m: "\n" * m.group().count("\n"), text, flags=re.S
    )


def _code_line(code: str, at: int) -> int:
    return code.count("\n", 0, at) + 1


def _check_entities(code: str, p: Path) -> None:
    """Entity declarations (see the module) in ``code``: the text without comments."""
    ent = re.search(r"<!ENTITY\s+(%\s*)?([^\s>]*)", code)
    if ent is not None:
        raise ConfigError(
            f"{p}: line {_code_line(code, ent.start())}: declares the XML entity "
            f"{ent.group(2)!r} (<!ENTITY>); expected a URDF without entities (they can "
            "expand a file without bound or read other files)."
        )


def _check_expressions(code: str, p: Path) -> None:
    """xacro expressions left in ``code``, the text without comments (see the
    module)."""
    expr = re.search(r"\$[{(][^\"'<>]*?[})]", code)
    if expr is not None:
        raise ConfigError(
            f"{p}: line {_code_line(code, expr.start())}: {expr.group()!r} is a xacro "
            f"expression; expected a plain URDF ({_EXPAND})."
        )


def read_urdf(path: str | Path) -> tuple[str, ET.Element]:
    """The text of a URDF file and its root element (tags as written, namespaces kept).

    Raises
    ------
    ConfigError
        See the module docstring; or the XML is not well formed (its line and column).
    """
    p = Path(path)
    if p.is_dir():
        raise ConfigError(f"{p}: is a folder; expected a URDF file.")
    try:
        raw = read_bounded(p, MAX_URDF_BYTES, "a URDF (its meshes are separate files)")
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read URDF ({exc.strerror}).") from exc
    text = _text(raw, p)
    if not text.strip("\ufeff \t\r\n"):
        raise ConfigError(f"{p}: the file is empty; expected a URDF <robot> document.")
    first = text.lstrip("\ufeff \t\r\n")
    if not first.startswith("<"):  # a robot YAML, a CSV: 'not well-formed: line 1'
        head = first.splitlines()[0][:40] if first else ""
        raise ConfigError(
            f"{p}: not an XML document (it starts with {head!r}); expected a URDF "
            "<robot> document."
        )
    code = _no_comments(text)  # (once: both checks read it)
    _check_entities(code, p)
    try:
        root = ET.fromstring(raw)  # one piece: linear (ET.parse feeds 64 kB pieces)
    except ET.ParseError as exc:
        if "unbound prefix" in str(exc) and "xacro:" in text:
            raise ConfigError(
                f"{p}: cannot read URDF (line {exc.position[0]}: a xacro element "
                f"without the xacro namespace); expected a plain URDF ({_EXPAND})."
            ) from None
        raise ConfigError(f"{p}: cannot read URDF ({exc}).") from None
    macro = next((el for el in root.iter() if "xacro" in str(el.tag)), None)
    if macro is not None:
        name = macro.get("name") or macro.get("filename")
        raise ConfigError(
            f"{p}: holds xacro elements (<xacro:{str(macro.tag).split('}')[-1]}"
            f"{f' {name!r}' if name else ''}>); expected a plain URDF ({_EXPAND})."
        )
    _check_expressions(code, p)
    return text, root
