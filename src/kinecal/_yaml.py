"""YAML with PyYAML's safe types, through libyaml when PyYAML was built with it.

libyaml's parser and emitter give the same documents and the same text 4-6x faster than
the pure-Python ones (a model file: 24 -> 6 ms to write, 38 -> 6 ms to read).

A key given twice in one mapping is an error (:class:`DuplicateKeyError`): YAML forbids
it, and PyYAML would silently keep the second value (``a: 330`` then ``a: 3300`` in a
hand-edited robot file gives a = 3300 without a word). A document whose aliases expand
it far beyond its text ("billion laughs") is an error too (:class:`AliasBombError`).

Numbers in exponent notation are numbers as YAML 1.2 reads them: PyYAML follows YAML
1.1, where a float needs a dot and a signed exponent, so ``1e-3``, ``2E5`` and ``1.5e3``
were strings ("expected a number; got '1e-3'" for the ``priors`` example of the robot
file's own documentation).
"""

from __future__ import annotations

from typing import Any

import yaml

from kinecal._yaml_aliases import check_expansion
from kinecal._yaml_float import EXPONENT_FLOAT, FIRST_CHARS

__all__ = ["AliasBombError", "DuplicateKeyError", "YAMLError", "dump", "load"]

YAMLError = yaml.YAMLError
_BASE_LOADER: Any = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_DUMPER: Any = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


class DuplicateKeyError(yaml.YAMLError):
    """A mapping of the document has the same key twice (one-line message with lines)."""


class AliasBombError(yaml.YAMLError):
    """The document's aliases expand it far beyond its text (:mod:`._yaml_aliases`)."""


class _Loader11(_BASE_LOADER):
    """The safe loader, refusing duplicate keys and alias bombs (YAML 1.1's numbers)."""

    def construct_document(self, node: Any) -> Any:
        try:
            check_expansion(node)
        except ValueError as exc:
            raise AliasBombError(str(exc)) from None
        return super().construct_document(node)

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:
        if isinstance(node, yaml.MappingNode):
            first: dict[Any, Any] = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    seen = first.setdefault(key, key_node)
                except TypeError:  # an unhashable key: the base class says so
                    continue
                if seen is not key_node:
                    raise DuplicateKeyError(
                        f"line {key_node.start_mark.line + 1}: duplicate key {key!r} "
                        f"(first on line {seen.start_mark.line + 1}); expected each key "
                        "once"
                    )
        return super().construct_mapping(node, deep=deep)


class _Loader(_Loader11):
    """:class:`_Loader11` with YAML 1.2's numbers in exponent notation."""


class _Dumper(_DUMPER):
    """The safe dumper, quoting the strings :class:`_Loader` would read as numbers."""


# YAML 1.2's floats that YAML 1.1 reads as strings: an exponent without a dot or
# without a sign ("1e-3", "2E5", "1.5e3"); what 1.1 already reads is unchanged. The
# dumper knows them too, so that the string '12e5' is written quoted and reads back.
for _cls in (_Loader, _Dumper):
    _cls.add_implicit_resolver("tag:yaml.org,2002:float", EXPONENT_FLOAT, FIRST_CHARS)


def load(text: str, *, exponents: bool = True) -> Any:
    """``yaml.safe_load``, refusing duplicate keys (:class:`DuplicateKeyError`), with
    numbers in exponent notation as YAML 1.2 reads them; ``exponents=False``: as YAML
    1.1 (PyYAML) reads them, for the files kinecal itself wrote before it quoted such
    strings (a model file's 16-digit hex fingerprint ``1234e5678...`` written plain)."""
    return yaml.load(text, Loader=_Loader if exponents else _Loader11)


def dump(doc: Any, **options: Any) -> str:
    """``yaml.safe_dump`` to a string."""
    return str(yaml.dump(doc, Dumper=_Dumper, **options))
