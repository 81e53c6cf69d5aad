"""The allocator setting the CLI applies (see kinecal._memory)."""

from __future__ import annotations

import platform
import sys

from kinecal import keep_freed_memory


def test_keep_freed_memory_applies_once_on_glibc():
    first = keep_freed_memory()
    assert keep_freed_memory() is first  # idempotent
    if sys.platform.startswith("linux") and platform.libc_ver()[0] == "glibc":
        assert first
