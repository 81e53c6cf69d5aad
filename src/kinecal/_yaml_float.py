"""The numbers YAML 1.2 reads in exponent notation and YAML 1.1 (PyYAML) reads as
strings: an exponent without a dot or without a sign (``1e-3``, ``2E5``, ``1.5e3``).
kinecal's YAML reader takes them as numbers, and its writers quote a string of this form
(``'12e5'``) so that it reads back as a string. Apart from :mod:`kinecal._yaml`, which
imports PyYAML, so that the plain writer needs no PyYAML."""

from __future__ import annotations

import re

__all__ = ["EXPONENT_FLOAT", "FIRST_CHARS"]

EXPONENT_FLOAT = re.compile(
    r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"
)
FIRST_CHARS = list("-+0123456789.")
