"""The compiled model kernel against the numpy code, its threads, and its refusals.

The finite-difference checks of every Jacobian column run on both codes
(tests/models/test_kinematic_model.py, fixture ``kernel``); here the two are compared
entry by entry on every kind of model term.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from kinecal.errors import ConfigError, DataError
from kinecal.models import (
    CalibrationModel,
    ModelInputs,
    ModelSpec,
    kernel_name,
    set_kernel_threads,
)
from kinecal.robot import load_robot, robot_from_dict
from tests.conftest import require_compiled_kernel

FANUC = load_robot("fanuc-lrmate200id")


@pytest.fixture(autouse=True)
def _compiled() -> None:
    require_compiled_kernel()


def _inputs(robot, rng, n, sets=1, markers=1):
    lim = np.clip(robot.limits, -3.0, 3.0)
    return ModelInputs.make(
        rng.uniform(lim[:, 0], lim[:, 1], size=(n, robot.n_joints)),
        set_index=rng.integers(0, sets, n),
        marker_index=rng.integers(0, markers, n),
        p_cam=rng.normal(size=(n, 3)) * 0.1,
        load_scale=rng.uniform(0.5, 1.5, n),
    )


def _params(model, rng, lam, ntm=1e-3):
    """Random geometry; compliances ~lam, Fourier terms ~ntm, link moments ~0.3."""
    p = model.nominal + rng.normal(size=model.size) * model.layout.scales * 3
    for i, s in enumerate(model.layout.specs):
        if s.kind == "compliance":
            p[i] = rng.normal() * lam
        elif s.kind == "ntm":
            p[i] = rng.normal() * ntm
        elif s.kind in ("moment", "ratio"):
            p[i] = 0.3 + 0.1 * rng.normal()
    return p


def _evaluate(monkeypatch, code, model, p, inp, **kw):
    monkeypatch.setenv("KINECAL_KERNEL", code)
    assert kernel_name(model) == code
    return model.evaluate(p, inp, **kw)


def _assert_same(a, b, what):
    """Equal to rounding: every column within 1e-13 of the array's largest entry."""
    assert a.shape == b.shape, what
    scale = max(float(np.abs(b).max()), 1e-300)
    err = float(np.abs(a - b).max()) / scale
    assert err < 1e-13, f"{what}: {err:.1e}"


SPECS = {
    "full": ("fanuc-lrmate200id", ModelSpec.preset("full")),
    "full, position only": (
        "fanuc-lrmate200id",
        ModelSpec.preset("full", cam_rotation=False),
    ),
    "rfcm, Hayati, sets, markers": (
        "fanuc-lrmate200id",
        ModelSpec.preset("rfcm", hayati=(2,), sets=("a", "b"), markers=("m", "n")),
    ),
    "ntm": ("fanuc-lrmate200id", ModelSpec.preset("ntm", cam_rotation=False)),
    "paper + bodies, NTM on 1 2 3 5, 3 markers": (
        "fanuc-lrmate200id",
        ModelSpec(
            ntm_joints=(1, 2, 3, 5),
            ntm_order=3,
            load=True,
            link="paper",
            link_bodies=(2, 3, 5),
            markers=("a", "b", "c"),
        ),
    ),
    "general link model, 2 sets": (
        "fanuc-lrmate200id",
        ModelSpec(
            ntm_joints=(2,),
            ntm_offset=False,
            load=True,
            link="general",
            link_bodies=(2, 3, 6),
            sets=("a", "b"),
        ),
    ),
    "UR10 full, two Hayati rows": ("ur10", ModelSpec.preset("full", hayati=(2, 3))),
    "FR3 (7 joints) full, no link weight": (
        "franka-fr3",
        ModelSpec.preset("full", has_self_weight=False),
    ),
    "FR3 kinematic": ("franka-fr3", ModelSpec.preset("kinematic")),
}


@pytest.mark.parametrize("case", list(SPECS))
@pytest.mark.parametrize("orientation", [False, True])
def test_the_compiled_kernel_equals_the_numpy_code(case, orientation, rng, monkeypatch):
    """Every output, with the product columns, on an odd number of poses (a partial last
    block of lanes); with small errors (series for the shifted angles) and with errors
    beyond the series' 0.01 rad (the library's cos and sin); and with every compliance
    zero, where the kernel skips the torques' geometry terms (issue 26: the kinematic
    stages of a calibration), though not the compliance columns themselves."""
    name, spec = SPECS[case]
    robot = load_robot(name)
    model = CalibrationModel(robot, spec)
    inp = _inputs(robot, rng, 53, len(spec.sets), len(spec.markers))
    for lam, ntm in ((0.0, 1e-3), (1e-3, 1e-3), (0.2, 0.05)):
        p = _params(model, rng, lam, ntm)
        kw = dict(orientation=orientation, jacobian=True, products=True)
        c = _evaluate(monkeypatch, "c", model, p, inp, **kw)
        ref = _evaluate(monkeypatch, "numpy", model, p, inp, **kw)
        for field in ("p_user", "R_user_cam", "J_p", "J_w", "theta"):
            a, b = getattr(c, field), getattr(ref, field)
            assert (a is None) == (b is None), field
            if a is not None:
                _assert_same(a, b, f"{field} (lambda ~ {lam})")
        if lam > 0.1 and (spec.load or spec.ntm_joints):  # beyond the series' range
            assert np.abs(c.theta - inp.q_ctrl @ robot.coupling.T).max() > 0.01
        plain = _evaluate(monkeypatch, "c", model, p, inp, orientation=orientation)
        np.testing.assert_array_equal(plain.p_user, c.p_user)
        assert plain.J_p is None and plain.J_w is None and plain.forward is None


def test_threads_give_the_same_numbers_to_the_last_digit(rng):
    """Any split of the poses over threads gives the result of one thread: the poses are
    independent, and a partial block of lanes is computed alike wherever it falls."""
    model = CalibrationModel(
        FANUC, ModelSpec.preset("full", sets=("a", "b"), markers=("m", "n"))
    )
    inp = _inputs(FANUC, rng, 4599, 2, 2)  # 3 threads from 4500 poses
    p = _params(model, rng, 1e-3)
    outs = []
    try:
        for threads in (1, 2, 3):
            set_kernel_threads(threads)
            outs.append(model.evaluate(p, inp, orientation=True, jacobian=True))
    finally:
        set_kernel_threads(None)
    for out in outs[1:]:
        for field in ("p_user", "R_user_cam", "J_p", "J_w", "theta"):
            np.testing.assert_array_equal(getattr(out, field), getattr(outs[0], field))
    with pytest.raises(ValueError, match="count must be >= 1"):
        set_kernel_threads(0)


def test_a_set_or_marker_index_out_of_range_is_a_data_error(rng):
    model = CalibrationModel(FANUC, ModelSpec.preset("full", sets=("a", "b")))
    inp = _inputs(FANUC, rng, 10, 2)
    bad = ModelInputs.make(inp.q_ctrl, set_index=np.r_[np.zeros(9, int), 2])
    with pytest.raises(DataError, match=r"pose 9: set index 2 .* 2 sets and 1 markers"):
        model.evaluate(model.nominal, bad, jacobian=True)
    bad = ModelInputs.make(inp.q_ctrl, marker_index=np.r_[-1, np.zeros(9, int)])
    with pytest.raises(DataError, match=r"pose 0: .* marker index -1"):
        model.evaluate(model.nominal, bad)


def test_which_code_evaluates_a_model(monkeypatch):
    """The kernel where it applies; numpy for a prismatic joint or when asked; errors
    for a bad choice or a kernel asked for where it does not apply."""
    slide = robot_from_dict(
        {
            "name": "slide-3",
            "convention": "dh",
            "units": {"length": "mm", "angle": "deg"},
            "joints": [
                {"theta_offset": 0, "d": 300, "a": 50, "alpha": 90},
                {"theta_offset": 0, "d": 0, "a": 0, "alpha": 0, "type": "prismatic"},
                {"theta_offset": 0, "d": 80, "a": 0, "alpha": 0},
            ],
            "self_weight": None,
        }
    )
    full = CalibrationModel(FANUC, ModelSpec.preset("full"))
    prismatic = CalibrationModel(slide, ModelSpec.preset("kinematic"))
    assert kernel_name(full) == "c"
    assert kernel_name(prismatic) == "numpy"
    monkeypatch.setenv("KINECAL_KERNEL", "numpy")
    assert kernel_name(full) == "numpy"
    monkeypatch.setenv("KINECAL_KERNEL", "c")
    with pytest.raises(ConfigError, match="does not cover this model of slide-3"):
        kernel_name(prismatic)
    monkeypatch.setenv("KINECAL_KERNEL", "fortran")
    with pytest.raises(ConfigError, match="KINECAL_KERNEL must be one of auto, c"):
        full.evaluate(full.nominal, ModelInputs.make(np.zeros((2, 6))))


def test_inconsistent_tables_are_refused_not_read(rng):
    """The kernel checks the tables and arrays it is given before it reads them."""
    from kinecal.models import _kernel

    model = CalibrationModel(FANUC, ModelSpec.preset("full"))
    inp = _inputs(FANUC, rng, 8)
    static = _kernel.tables(model.definition)
    ints, reals = _kernel._pack(static, model.definition, model.nominal, 3, 0, True)
    th, cq, sq = model.definition.coupled(inp)
    basis = model.definition.ntm_bases(inp)
    out = [
        np.empty((8, 3)),
        np.empty(0),
        np.empty((6, 8)),
        np.empty((model.size, 3, 8)),
    ]
    args = [ints, reals, th, cq, sq, basis, inp.set_index, inp.marker_index]
    args += [inp.p_cam, inp.load_scale, *out]
    _kernel._ckernel.evaluate(*args, 0, 8)  # as given: fine
    ok = model.evaluate(model.nominal, inp, jacobian=True)
    np.testing.assert_array_equal(out[3], ok.J_p.transpose(2, 1, 0))

    def refused(i, value, match, k=(0, 8)):
        bad = list(args)
        bad[i] = value
        with pytest.raises(ValueError, match=match):
            _kernel._ckernel.evaluate(*bad, *k)

    refused(0, ints[:10], "inconsistent tables")
    refused(1, reals[:5], "inconsistent tables")
    wrong = ints.copy()
    wrong[ints[_kernel._ckernel.FIELDS.index("i_row_idx")]] = model.size  # column P
    refused(0, wrong, "inconsistent tables")
    refused(2, th[:, :4].copy(), "theta_c has 192 bytes; expected 384")
    refused(13, np.empty((model.size, 3, 7)), "J has")
    refused(2, th, "bad pose range", k=(0, 9))
    with pytest.raises(TypeError):  # a read-only array cannot take an output
        _kernel._ckernel.evaluate(*args[:10], th, *args[11:], 0, 8)


def test_forked_workers_evaluate_after_the_parent_used_threads():
    """A forked child has none of its parent's threads: the kernel's thread pool starts
    afresh there (a pool inherited from the parent would wait forever)."""
    code = textwrap.dedent(
        """
        import numpy as np
        from kinecal._parallel import parallel_map
        from kinecal.models import CalibrationModel, ModelInputs, ModelSpec
        from kinecal.models import set_kernel_threads
        from kinecal.robot import load_robot

        model = CalibrationModel(load_robot("fanuc-lrmate200id"), ModelSpec.preset("full"))
        q = np.random.default_rng(0).uniform(-1, 1, size=(4000, 6))
        inp = ModelInputs.make(q)
        set_kernel_threads(2)
        ref = model.evaluate(model.nominal, inp, jacobian=True).J_p

        def work(seed):
            set_kernel_threads(2)  # the workers set 1; a child that asks for more
            return model.evaluate(model.nominal, inp, jacobian=True).J_p

        for J in parallel_map(work, [0, 1], jobs=2):
            assert np.array_equal(J, ref)
        print("ok")
        """
    )
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300
    )
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr


def test_a_kernel_built_from_other_source_is_not_used():
    """A stale build (an editable install not rebuilt after a change of _ckernel.c) whose
    tables differ is set aside with a warning, and the numpy code runs."""
    code = textwrap.dedent(
        """
        import sys, types, warnings
        stale = types.ModuleType("kinecal.models._ckernel")
        stale.FIELDS, stale.__file__ = ("n", "sets"), "stale.so"
        sys.modules["kinecal.models._ckernel"] = stale
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            from kinecal.models import compiled_kernel_available
        print(compiled_kernel_available(), caught[0].message)
        """
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(
        "False kinecal's compiled model kernel (stale.so) does not"
    )


def test_the_packed_tables_of_one_point_serve_only_their_own_model(rng, monkeypatch):
    """The kernel keeps the real tables of the last point packed. A copy of the model
    with other reference rotations shares the kernel's tables: at the same parameters it
    must not get the first model's frames, and a point changed in place is packed anew."""
    monkeypatch.setenv("KINECAL_KERNEL", "c")
    from kinecal.geometry import euler_zyx_to_matrix

    cm = CalibrationModel(FANUC, ModelSpec.preset("full"))
    other = cm.with_references(euler_zyx_to_matrix(np.array([[0.3, 0.2, -0.1]])))
    inp = _inputs(FANUC, rng, 50)
    p = cm.nominal.copy()
    a = cm.evaluate(p, inp).p_user.copy()
    b = other.evaluate(p, inp).p_user.copy()  # same p, same tables: another model
    assert np.abs(a - b).max() > 1e-3
    p[cm.layout.index("base.x")] += 0.01  # the same array, changed in place
    c = cm.evaluate(p, inp).p_user
    np.testing.assert_allclose(c - a, np.tile([0.01, 0.0, 0.0], (50, 1)), atol=1e-12)
    monkeypatch.setenv("KINECAL_KERNEL", "numpy")
    np.testing.assert_allclose(other.evaluate(cm.nominal, inp).p_user, b, atol=1e-12)
