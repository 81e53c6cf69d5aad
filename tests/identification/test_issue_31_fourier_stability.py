"""Issue 31: Fourier transmission terms are chosen only when their coefficients are
reproducible across the region folds (a delete-one-region jackknife): on the shipped FR3
halves the order-2 terms won every region of session a and lost 9 % on session b."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from kinecal.identification import calibrate, evaluate, select_model
from kinecal.identification.selection._fourier import (
    fourier_terms,
    jackknife_z2,
    null_z2,
    same_physics,
)
from kinecal.identification.selection._select import Candidate, choose_candidate
from kinecal.io import read_measurements
from kinecal.models import ModelSpec
from kinecal.robot import load_robot
from tests.identification.test_issue_31_transfer import auto_calibration

REAL = Path(__file__).resolve().parents[1] / "data" / "real"


def test_default_on_the_fr3_session_b_after_calibrating_on_session_a():
    """Session a (60 poses) to session b (54, the board moved; user and tool frames
    refitted): the default within 5 % of the best fixed model. The order-2 terms of
    J1-J3 validated 4.5 % better than order 1 in session a's regions but their
    coefficients swing with the region left out (mean z^2 0.97 against 2 for noise):
    the rule without the test kept them, 1.088x the best fixed model (2.018 mm against
    the kinematic model's 1.855); order 1 gives 1.792."""
    robot = load_robot("franka-fr3")
    a = read_measurements(REAL / "fr3_session_a.csv", robot, check=False)
    b = read_measurements(REAL / "fr3_session_b_board_moved.csv", robot, check=False)
    refit = ("user", "tool")
    fixed = {
        m: evaluate(calibrate(robot, a, m).calibrated, b, refit=refit).metrics.rms_mm
        for m in ("kinematic", "ntm", "rfcm", "full")
    }
    res = auto_calibration(robot, a)
    got = evaluate(res.calibrated, b, refit=refit).metrics.rms_mm
    assert got <= 1.05 * min(fixed.values()), (res.model.spec.name, got, fixed)
    assert fixed["ntm"] > 1.05 * min(fixed.values())  # the case: order 2 loses
    # The table says why the better-validating order-2 terms were not chosen.
    notes = select_model(robot, a).warnings
    assert any(
        n.startswith("ntm, full: validated better") and "mean z^2 0.97" in n
        for n in notes
    ), notes


def _cand(label, spec, size, folds, fourier=None):
    f = np.asarray(folds, float)
    return Candidate(
        label,
        spec,
        1.0,
        size,
        float(np.sqrt(np.mean(f**2))),
        0.0,
        0.0,
        fold_rms_mm=tuple(f),
        fold_fourier=fourier or {},
    )


def _coefs(rng, names, mean, spread):
    return {n: tuple(mean + spread * rng.standard_normal(5)) for n in names}


@pytest.mark.parametrize("stable", [True, False])
def test_order_2_terms_whose_coefficients_swing_with_the_region_are_not_chosen(
    stable,
):
    """A table like session a's: order 2 predicts every region better than order 1
    (beyond 1.75 paired standard errors). With its extra coefficients reproducible
    across the folds it is chosen; swinging with the region left out (mean z^2 below
    the noise level 2), order 1 is."""
    rng = np.random.default_rng(0)
    kin = ModelSpec(name="kinematic")
    o1 = ModelSpec(ntm_joints=(1, 2, 3), ntm_order=1, name="ntm")
    o2 = ModelSpec(ntm_joints=(1, 2, 3), ntm_order=2, name="ntm")
    first = [f"joint{j}.{k}" for j in (1, 2, 3) for k in ("ka1", "kb1")]
    second = [f"joint{j}.{k}" for j in (1, 2, 3) for k in ("ka2", "kb2")]
    base = np.array([1.0, 1.7, 1.8, 2.3, 1.2])
    c1 = _coefs(rng, first, 1e-3, 1e-5)
    c2 = c1 | _coefs(rng, second, 1e-3 if stable else 0.0, 1e-5 if stable else 5e-4)
    table = [
        _cand("kinematic", kin, 34, base),
        _cand("ntm J1,2,3 order 1", o1, 40, 0.87 * base, c1),
        _cand("ntm", o2, 46, 0.83 * base * [1, 1.001, 0.999, 1, 1.002], c2),
    ]
    chosen = choose_candidate(table)
    assert chosen.label == ("ntm" if stable else "ntm J1,2,3 order 1")
    assert sum(c.chosen for c in table) == 1


def test_jackknife_z2_and_its_noise_level():
    """z = mean / sqrt((k - 1) / k sum (x - mean)^2); coefficients the folds held fixed
    are left out; for noise the mean of z^2 is (k - 1) / (k - 3) (Student's t, k - 1
    degrees of freedom): 2 for 5 folds, checked by simulation."""
    v = (1.0, 2.0, 3.0, 4.0, 5.0)
    se = np.sqrt(4 / 5 * 10.0)
    assert jackknife_z2({"a": v}, ["a"]) == pytest.approx((3.0 / se) ** 2)
    assert jackknife_z2({"a": v, "b": (0.5,) * 5}, ["a", "b"]) == jackknife_z2(
        {"a": v}, ["a"]
    )
    assert jackknife_z2({"b": (0.5,) * 5}, ["b"]) == np.inf
    assert null_z2(5) == 2.0 and null_z2(4) == 3.0 and null_z2(3) == 0.0
    # Five regions of noise; each fold's estimate leaves one region out.
    x = np.random.default_rng(1).standard_normal((200_000, 5))
    folds = (x.sum(axis=1, keepdims=True) - x) / 4
    m = folds.mean(axis=1)
    z2 = m**2 / (4 / 5 * np.sum((folds - m[:, None]) ** 2, axis=1))
    assert np.median(z2) == pytest.approx(0.549, abs=0.01)  # t(4)^2's median
    assert np.mean(np.minimum(z2, 1e3)) == pytest.approx(null_z2(5), rel=0.1)


def test_fourier_terms_and_the_physics_they_sit_on():
    full = ModelSpec(ntm_joints=(1, 2, 3), ntm_order=2, load=True, name="full")
    assert fourier_terms(full) == 6
    assert fourier_terms(ModelSpec(name="kinematic")) == 0
    assert same_physics(full, ModelSpec(load=True, name="load"))
    assert not same_physics(full, ModelSpec(ntm_joints=(1, 2, 3), name="ntm"))
