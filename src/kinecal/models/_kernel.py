"""The compiled model kernel: :meth:`CalibrationModel.evaluate` in C, for every pose.

``kinecal.models._ckernel`` (``_ckernel.c``) computes what the numpy code
(:mod:`kinecal.models._numpy_forward`, :mod:`kinecal.models._numpy_jacobian`) computes:
forward kinematics of both chains, the compliance torques and deflections, every Jacobian
column including the torques' dependence on the geometry, for all-revolute arms of up to
16 joints with any of the model's terms: Hayati rows, Fourier transmission errors, payload
and link compliance (lumped and general), several user frames and markers, orientation.
It is built when the package is installed with a C compiler at hand; without one, or for
a model it does not cover (prismatic joints), the numpy code runs. Both give the same
numbers to rounding (tested). This module reads only the public
:class:`~kinecal.models.ModelDefinition` of a model: :func:`tables` packs what of it does
not change between calls (once per model), :func:`_pack` what depends on the parameters.

The environment variable ``KINECAL_KERNEL`` chooses: ``auto`` (default: C where it
applies), ``numpy`` (never C), ``c`` (C required: an error where it is not built).
:func:`kinecal.models.kernel_name` tells which code evaluates a model.

The kernel releases the interpreter lock; large batches are split over threads
(:func:`kinecal._cpu.set_kernel_threads`; one per CPU by default, one in kinecal's worker
processes). It evaluates 2 poses a vector, or 4 (AVX2) or 8 (AVX-512F) where the build
has those widths and the CPU runs them (``_ckernel.lanes()``, the widest by default):
the same numbers on every width.
"""

from __future__ import annotations

import importlib
import itertools
import os
import threading
import warnings
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from kinecal._cpu import DaemonPool, kernel_threads
from kinecal.errors import ConfigError, DataError
from kinecal.models._definition import ModelDefinition
from kinecal.models._inputs import ModelInputs
from kinecal.typing import Float

# The header fields of _ckernel.c, in its order: a build of other source (an editable
# install not rebuilt after a change) is not used.
_FIELDS = (
    *("n", "sets", "markers", "c", "P", "K", "n_products", "jacobian", "cam_rotation"),
    *(
        "load",
        "link",
        "shoulder",
        "elbow",
        "wrist",
        "n_bodies",
        "n_link",
        "n_ntm",
        "nb",
    ),
    *("ntm_start", "lam_start", "link_start", "i_row_idx", "i_cam_idx", "i_base_idx"),
    *("i_ntm_joints", "i_bodies", "i_products", "r_rows", "r_base", "r_cam", "r_lam"),
    *("r_link", "r_ntm", "r_xsign"),
)

_ckernel: Any
# Why the compiled kernel is not used (None: it is), for kernel_status().
_missing: str | None = None
try:
    _ckernel = importlib.import_module("kinecal.models._ckernel")
except ImportError as exc:  # built without a C compiler: the numpy code runs
    _ckernel = None
    _missing = f"the compiled kernel is not built ({exc})"
if _ckernel is not None and tuple(_ckernel.FIELDS) != _FIELDS:
    _missing = (
        "the compiled kernel is a build of other source (rebuild: pip install -e .)"
    )
    warnings.warn(
        f"kinecal's compiled model kernel ({_ckernel.__file__}) does not match this "
        "version of kinecal (rebuild it: pip install -e . or make); the numpy code runs.",
        RuntimeWarning,
        stacklevel=1,
    )
    _ckernel = None

__all__ = [
    "KernelTables",
    "active_tables",
    "compiled_kernel_available",
    "gram",
    "kernel_status",
    "tables",
]

_MODES = ("auto", "c", "numpy")
# Kinds of a link product's torque basis value (the link_T column it reads); see
# _ckernel.c: the x-hat and u-hat moments of the lumped model, a body's mass and one of
# its first moments.
_XHAT, _UHAT, _MASS, _MOMENT = range(4)


def compiled_kernel_available() -> bool:
    """Whether the compiled kernel was built with this installation."""
    return _ckernel is not None


def _build_note() -> str | None:
    """The reason the build left when it could not compile the kernel (setup.py), if
    any: e.g. no C compiler at install."""
    note = Path(__file__).with_name("_ckernel_build.txt")
    try:
        text = " ".join(note.read_text(encoding="utf-8").split())
    except OSError:
        return None
    return text[:300] or None


def kernel_status() -> tuple[str, str]:
    """The model code in use, ``'compiled kernel'`` or ``'numpy'``, and why (one line).

    ``KINECAL_KERNEL`` decides first; otherwise the compiled kernel runs where it was
    built with this installation (models with prismatic joints always run the numpy
    code). Used by ``kinecal --version``.
    """
    mode = os.environ.get("KINECAL_KERNEL", "auto").strip().lower() or "auto"
    if mode == "numpy":
        return "numpy", "KINECAL_KERNEL=numpy is set"
    if _ckernel is not None:
        where = Path(_ckernel.__file__).name
        return "compiled kernel", (
            f"built with this installation ({where}; numpy code for models with "
            "prismatic joints)"
        )
    note = _build_note()
    why = f"the build could not compile it: {note}" if note else _missing or ""
    return "numpy", f"{why}; install a C compiler and reinstall kinecal to build it"


_warned = False


def _warn_not_built() -> None:
    """Warn, once per installation (a marker in the user's cache folder) or else once
    per process, that the numpy code runs because the kernel was not built."""
    global _warned
    chosen = os.environ.get("KINECAL_KERNEL", "").strip().lower()
    if _warned or _ckernel is not None or chosen == "numpy":
        return
    _warned = True
    from kinecal._version import __version__

    cache = Path(os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"))
    tag = zlib.crc32(str(Path(__file__).resolve().parent).encode())
    marker = cache / "kinecal" / f"kernel-not-built-{__version__}-{tag:08x}"
    home = cache.is_absolute()  # without a home folder: a warning in every process
    if home and marker.exists():
        return
    _, why = kernel_status()
    warnings.warn(
        f"kinecal runs its numpy model code, 2-4x slower than the compiled kernel: {why} "
        "(this warning is shown once; KINECAL_KERNEL=numpy silences it).",
        UserWarning,
        stacklevel=3,
    )
    if home:
        try:
            marker.parent.mkdir(parents=True, exist_ok=True)
            marker.touch()
        except OSError:
            pass


def _mode() -> str:
    mode = os.environ.get("KINECAL_KERNEL", "auto").strip().lower() or "auto"
    if mode not in _MODES:
        raise ConfigError(
            f"KINECAL_KERNEL must be one of {', '.join(_MODES)}; got {mode!r}."
        )
    if mode == "c" and _ckernel is None:
        raise ConfigError(
            "KINECAL_KERNEL=c, but the compiled kernel is not built (install kinecal "
            "with a C compiler at hand, e.g. gcc, then reinstall)."
        )
    return mode


@dataclass(frozen=True)
class KernelTables:
    """What of the kernel's tables depends on the model's terms only: the header and the
    integer tables (``ints``; the per-call fields c, K and jacobian are set by
    :func:`_pack`), and where the parameters go in the real tables."""

    ints: np.ndarray
    n_products: int
    lam_idx: np.ndarray
    link: slice
    ntm: slice
    x_sign: float
    # The real tables of the last parameters packed: a solver evaluates the Jacobian at
    # the point it evaluated the residuals at just before (half of its evaluations).
    # (Models that share these tables, with other reference rotations, have their own
    # definition: it is part of the key.)
    last: list[tuple[ModelDefinition, bytes, np.ndarray]] = field(
        default_factory=list, compare=False
    )


def tables(defn: ModelDefinition) -> KernelTables | None:
    """The model's tables, or None where the kernel is not built or does not apply
    (computed once per model)."""
    if _ckernel is None:
        _warn_not_built()
        return None
    if defn.prismatic.any():
        return None
    spec = defn.spec
    n, S, M = defn.n_joints, len(spec.sets), len(spec.markers)
    n_link = len(defn.link_names)
    n_lump = defn.n_lumped  # the lumped moments come first
    prods = []
    for j, kcol in defn.products:
        if kcol < n_lump:
            prods.append((j, kcol, _XHAT if kcol == 0 else _UHAT, 0, 0))
        else:
            b, k = divmod(kcol - n_lump, 4)
            frame = spec.link_bodies[b]
            prods.append((j, kcol, _MASS if k == 0 else _MOMENT, frame, max(k - 1, 0)))
    if (
        n > _ckernel.MAX_JOINTS
        or len(prods) > _ckernel.MAX_PRODUCTS
        or n_link > _ckernel.MAX_LINK
    ):
        return None
    cam_idx = -np.ones((M, 6), np.int64)
    cam_idx[:, : defn.cam_idx.shape[1]] = defn.cam_idx
    sw = defn.self_weight
    nb = len(defn.ntm_terms)
    int_tables = {
        "i_row_idx": np.asarray(defn.row_idx, np.int64),
        "i_cam_idx": cam_idx,
        "i_base_idx": np.asarray(defn.base_idx, np.int64),
        "i_ntm_joints": np.array([j - 1 for j in spec.ntm_joints], np.int64),
        "i_bodies": np.array(spec.link_bodies, np.int64),
        "i_products": np.array(prods, np.int64).reshape(-1, 5),
    }
    # Sizes of the real tables, in the order _pack writes them.
    real_sizes = {
        "r_rows": 8 * n,
        "r_base": 24 * S,
        "r_cam": 21 * M,
        "r_lam": n,
        "r_link": n_link,
        "r_ntm": len(spec.ntm_joints) * nb,
        "r_xsign": 1,
    }
    header = {
        "n": n,
        "sets": S,
        "markers": M,
        "c": 0,
        "K": 0,
        "jacobian": 0,
        "P": defn.size,
        "n_products": len(prods),
        "cam_rotation": int(spec.cam_rotation),
        "load": int(spec.load),
        "link": {"paper": 1, "rfcm": 2}.get(spec.link, 0),
        "shoulder": sw.shoulder if n_lump and sw else 0,
        "elbow": sw.elbow if n_lump and sw else 0,
        "wrist": sw.wrist_frame if n_lump and sw else 0,
        "n_bodies": len(spec.link_bodies),
        "n_link": n_link,
        "n_ntm": len(spec.ntm_joints),
        "nb": nb,
        "ntm_start": defn.ntm_start,
        "lam_start": defn.load_start,
        "link_start": defn.link_start,
    }
    offset = len(_FIELDS)
    for name, table in int_tables.items():
        header[name] = offset
        offset += table.size
    offset = 0
    for name, size in real_sizes.items():
        header[name] = offset
        offset += size
    head = np.array([header[f] for f in _FIELDS], np.int64)
    return KernelTables(
        ints=np.concatenate([head, *(t.ravel() for t in int_tables.values())]),
        n_products=len(prods),
        lam_idx=defn.lam_idx,
        link=defn.link_slice,
        ntm=defn.ntm_slice,
        x_sign=defn.x_sign,
    )


def active_tables(
    defn: ModelDefinition, static: KernelTables | None
) -> KernelTables | None:
    """``static`` (the model's :func:`tables`) where the compiled kernel evaluates the
    model of ``defn`` now (``KINECAL_KERNEL``), else None."""
    if _mode() == "numpy":
        return None
    if static is None and _mode() == "c":
        raise ConfigError(
            f"KINECAL_KERNEL=c, but the compiled kernel does not cover this model of "
            f"{defn.robot.name} (prismatic joints, more than {_ckernel.MAX_JOINTS} "
            f"joints or more than {_ckernel.MAX_PRODUCTS} link terms)."
        )
    return static


def _pack(
    static: KernelTables,
    defn: ModelDefinition,
    p: Float,
    c: int,
    K: int,
    jacobian: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """The header with the integer tables, and the real tables, for parameters ``p``."""
    ints = static.ints.copy()
    for name, value in (("c", c), ("K", K), ("jacobian", int(jacobian))):
        ints[_FIELDS.index(name)] = value
    key = np.asarray(p, np.float64).tobytes()
    last = static.last[:1]  # (another thread may replace it meanwhile)
    if last and last[0][0] is defn and last[0][1] == key:
        return ints, last[0][2]
    reals = _reals(static, defn, p)
    reals.setflags(write=False)
    static.last[:] = [(defn, key, reals)]
    return ints, reals


def _reals(static: KernelTables, defn: ModelDefinition, p: Float) -> np.ndarray:
    """The kernel's real tables for parameters ``p``."""

    rows = defn.rows(p)  # (n, 5): offset, d, a, alpha, beta (Eq. 10)
    row_table = np.column_stack(
        [
            np.cos(rows[:, 0]),
            np.sin(rows[:, 0]),
            rows[:, 1],
            rows[:, 2],
            np.cos(rows[:, 3]),
            np.sin(rows[:, 3]),
            np.cos(rows[:, 4]),
            np.sin(rows[:, 4]),
        ]
    )
    S, M = len(defn.spec.sets), len(defn.spec.markers)
    R_b, t_b = defn.base_frames(p)  # Eq. (8)
    base = np.concatenate(
        [
            R_b.reshape(-1, 9),
            t_b,
            R_b @ defn.g_hat,
            defn.base_axes(p).transpose(0, 2, 1).reshape(S, 9),
        ],
        axis=1,
    )
    R_c, t_c = defn.cam_frames(p)  # Eq. (9)
    if defn.spec.cam_rotation:
        axes_c = defn.cam_axes(p).transpose(0, 2, 1).reshape(M, 9)
    else:
        axes_c = np.zeros((M, 9))
    cam = np.concatenate([R_c.reshape(-1, 9), t_c, axes_c], axis=1)
    reals = (  # in the order of tables()' real_sizes
        row_table,
        base,
        cam,
        p[static.lam_idx] if defn.spec.load else np.zeros(defn.n_joints),
        p[static.link],
        p[static.ntm],
        np.array([static.x_sign]),
    )
    return np.concatenate([np.ravel(t) for t in reals])


# Threads of one evaluation: up to kinecal._cpu.kernel_threads() (one per CPU, 1 in worker
# processes) for large batches. Below about 1500 poses a thread costs more than it saves
# (2-core VM, full model: 2000 poses 0.9 ms on one thread and on two; 6855 poses 4-5 ms on
# one, 2.5-3 ms on two).
_MIN_POSES_PER_THREAD = 1500
_pool: Any = None
_pool_size = 0
_pool_lock = threading.Lock()


def _thread_count(N: int) -> int:
    return max(1, min(kernel_threads(), N // _MIN_POSES_PER_THREAD))


def _executor(count: int) -> Any:
    """A pool of at least ``count`` threads (kept for the next evaluation)."""
    global _pool, _pool_size
    with _pool_lock:
        if _pool is None or _pool_size < count:
            if _pool is not None:
                _pool.shutdown()
            _pool = DaemonPool(count)
            _pool_size = count
        return _pool


def _reset_after_fork() -> None:  # a forked child has none of the parent's threads
    global _pool, _pool_size, _pool_lock
    _pool, _pool_size = None, 0
    _pool_lock = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_reset_after_fork)


def evaluate(
    static: KernelTables,
    defn: ModelDefinition,
    p: Float,
    inputs: ModelInputs,
    *,
    orientation: bool,
    jacobian: bool,
    products: bool,
    alloc: Callable[[tuple[int, ...]], Float],
) -> tuple[Float, Float | None, Float | None, Float]:
    """``(p_user (N, 3), R_user_cam (N, 3, 3) or None, J (P', c, N) or None,
    theta (n, N))`` of :meth:`CalibrationModel.evaluate` by the compiled kernel."""
    c = 6 if orientation else 3
    K = static.n_products if (jacobian and products) else 0
    ints, reals = _pack(static, defn, p, c, K, jacobian)
    theta_c, cos_c, sin_c = defn.coupled(inputs)
    basis = defn.ntm_bases(inputs)  # (n_ntm, nb, N), kept with the inputs
    N, n = inputs.q_ctrl.shape
    p_user = np.empty((N, 3))
    R_uc = np.empty((N, 3, 3)) if orientation else np.empty(0)
    theta = np.empty((n, N))
    J = alloc((defn.size + K, c, N)) if jacobian else np.empty(0)
    args = (
        ints,
        reals,
        theta_c,
        cos_c,
        sin_c,
        basis,
        np.ascontiguousarray(inputs.set_index, np.int64),
        np.ascontiguousarray(inputs.marker_index, np.int64),
        np.ascontiguousarray(inputs.p_cam, np.float64),
        np.ascontiguousarray(inputs.load_scale, np.float64),
        p_user,
        R_uc,
        theta,
        J,
    )
    count = _thread_count(N)
    try:
        if count == 1:
            _ckernel.evaluate(*args, 0, N)
        else:  # whole blocks of lanes per thread; the first part on this thread
            lanes = _ckernel.lanes()  # the vector width in use
            bounds = [N * i // count // lanes * lanes for i in range(count)] + [N]
            pool = _executor(count - 1)
            futures = [
                pool.submit(_ckernel.evaluate, *args, a, b)
                for a, b in itertools.pairwise(bounds[1:])
            ]
            _ckernel.evaluate(*args, bounds[0], bounds[1])
            for f in futures:
                f.result()
    except IndexError as exc:  # a set or marker index out of range
        raise DataError(str(exc)) from None
    return (
        p_user,
        R_uc if orientation else None,
        J if jacobian else None,
        theta,
    )


def gram(
    J: Float, r: Float, lo: int, hi: int, row_weights: Float | None
) -> Float | None:
    """The products of the normal equations of the columns ``lo:hi`` of a held Jacobian
    by the compiled kernel (``_ckernel.gram``), or None where it does not serve: not
    built, a CPU without AVX, ``KINECAL_KERNEL=numpy``, or a ``J`` (N, c, P') that is not
    a whole parameter-major array (the model's own memory for point data).

    Returns ``G`` (k + 1, k + 1), k = hi - lo, its upper triangle filled: ``G[:k, :k]``
    the upper triangle of ``Xᵀ X`` and ``G[:k, k]`` ``Xᵀ r``, X the columns with the
    rows of pose i multiplied by ``row_weights[i]``, as r. The same numbers as the BLAS
    products to rounding (other sums), at 0.76-0.85x their time (2000 poses x 50
    parameters, one core).
    """
    if _ckernel is None or not getattr(_ckernel, "GRAM", 0) or _mode() == "numpy":
        return None
    Jt = J.transpose(2, 1, 0)  # (P', c, N)
    if Jt.dtype != np.float64 or not Jt.flags.c_contiguous or hi <= lo:
        return None
    c = Jt.shape[1]
    w = np.empty(0) if row_weights is None else row_weights
    out = np.zeros((hi - lo + 1, hi - lo + 1))
    _ckernel.gram(
        Jt,
        np.ascontiguousarray(r, np.float64),
        np.ascontiguousarray(w, np.float64),
        out,
        c,
        lo,
        hi,
    )
    return out
