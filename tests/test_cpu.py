"""The CPU count and the compiled kernel's thread setting (kinecal._cpu)."""

from __future__ import annotations

import pytest

from kinecal._cpu import (
    _cgroup_cpu_quota,
    available_cpus,
    kernel_threads,
    set_kernel_threads,
)
from kinecal._parallel import _can_fork, parallel_map


def test_a_container_cpu_quota_caps_the_workers(tmp_path):
    f = tmp_path / "cpu.max"
    for text, want in (
        ("max 100000\n", None),
        ("200000 100000\n", 2),
        ("150000 100000\n", 2),
        ("50000 100000\n", 1),
        ("garbage", None),
    ):
        f.write_text(text)
        assert _cgroup_cpu_quota(f) == want, text
    assert _cgroup_cpu_quota(tmp_path / "missing") is None


def test_kernel_threads_are_one_per_cpu_unless_set():
    try:
        set_kernel_threads(None)
        assert kernel_threads() == available_cpus() >= 1
        set_kernel_threads(3)
        assert kernel_threads() == 3
        with pytest.raises(ValueError, match="count must be >= 1 or None; got 0"):
            set_kernel_threads(0)
        assert kernel_threads() == 3
    finally:
        set_kernel_threads(None)


def _worker_kernel_threads(_: int) -> int:
    return kernel_threads()


def test_worker_processes_run_the_kernel_on_one_thread():
    """Each worker already has a core: its model evaluations stay on one thread, whatever
    the parent set (a forked child would inherit it)."""
    if not _can_fork():
        pytest.skip("no forked worker processes on this platform")
    try:
        set_kernel_threads(5)
        assert parallel_map(_worker_kernel_threads, [0, 1], jobs=2) == [1, 1]
        assert kernel_threads() == 5
    finally:
        set_kernel_threads(None)
