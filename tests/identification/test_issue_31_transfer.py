"""Issue 31: the default (``--model auto``) judged where a calibration is used: a twin
calibrated in one region of the workspace and scored in another after the tracker moved
and the tool was re-mounted, and the shipped real sets with the selection run inside
every fold (nested cross-validation)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from kinecal.geometry import euler_zyx_to_matrix
from kinecal.identification import (
    CalibrationOptions,
    calibrate,
    cross_validate,
    evaluate,
    make_folds,
    pose_features,
    select_model,
)
from kinecal.identification.selection._select import Candidate, choose_candidate
from kinecal.io import read_measurements
from kinecal.models import ModelSpec
from kinecal.robot import load_robot
from kinecal.simulation import LaserTracker, experiment2, robot_experiment, robot_truth

ROOT = Path(__file__).resolve().parents[2]
REAL = ROOT / "tests" / "data" / "real"


def auto_calibration(robot, train):
    """The default's calibration (``--model auto``) of ``train``."""
    sel = select_model(robot, train)
    opts = CalibrationOptions().tuned(prior_scale=sel.prior_scale)
    return sel.calibration(opts) or calibrate(robot, train, sel.spec, opts)


def _region_shift(seed: int):
    """150 training poses from one end of the workspace, 800 test poses from the other,
    seen by a moved tracker (10 um noise); the truth has self-weight compliance and
    transmission errors (the paper's full model)."""
    e = experiment2(seed, tracker=LaserTracker(10e-6, 5e-6))
    return (e.truth.robot, *new_region(e.truth.robot, e.test, seed))


def new_region(robot, pool, seed: int):
    """(train, test) of ``pool``: 150 poses from one end of the workspace (along the
    direction the poses' joint-frame positions spread most), 800 from the other, the
    test ones seen by a tracker moved 25 deg and 0.4 m."""
    f = pose_features(pool.q_ctrl, robot)
    c = f - f.mean(axis=0)
    along = c @ np.linalg.svd(c, full_matrices=False)[2][0]
    lo, hi = np.quantile(along, [0.4, 0.6])
    rng = np.random.default_rng(seed)
    train = pool.subset(np.sort(rng.choice(np.flatnonzero(along < lo), 150, False)))
    test = pool.subset(np.sort(rng.choice(np.flatnonzero(along > hi), 800, False)))
    R = euler_zyx_to_matrix(np.radians([25.0, 1.0, -2.0]))
    return train, replace(test, p=test.p @ R.T + [0.2, -0.3, 0.05])


def robot_new_region(name: str, seed: int, **truth):
    """(robot, train, test): a twin of a built-in robot (``robot_truth(**truth)``)
    measured in one region and scored in another after the tracker moved."""
    robot = load_robot(name)
    e = robot_experiment(
        robot_truth(robot, seed=seed, **truth), seed, n_train=10, n_test=3000,
        tracker=LaserTracker(10e-6, 0.0),
    )  # fmt: skip
    return (robot, *new_region(robot, e.test, seed))


@pytest.mark.parametrize(
    "seed", [0, 1, *(pytest.param(s, marks=pytest.mark.slow) for s in (2, 3, 4, 5))]
)
def test_default_transfers_to_another_region_and_set_up(seed):
    """The default (auto) within 1.1x of the best fixed model's error on the other
    region with user and tool frames refitted."""
    robot, train, test = _region_shift(seed)
    refit = ("user", "tool")
    fixed = {
        m: evaluate(calibrate(robot, train, m).calibrated, test, refit=refit)
        for m in ("kinematic", "ntm", "rfcm", "full")
    }
    best = min(v.metrics.rms_mm for v in fixed.values())
    got = evaluate(
        auto_calibration(robot, train).calibrated, test, refit=refit
    ).metrics.rms_mm
    assert got <= 1.1 * best, (got, {k: v.metrics.rms_mm for k, v in fixed.items()})


def _gravity_shift(name: str, seed: int):
    """A twin of a built-in robot whose truth has gravity compliance (its self-weight
    layout or link masses, a payload) and geometric errors but no transmission errors,
    as the real UR10 of issue 31 behaved: 150 training poses from one end of the
    workspace, 800 test poses from the other seen by a moved tracker."""
    return robot_new_region(name, seed, ntm_amplitude=0.0)


@pytest.mark.parametrize(
    ("name", "seed"),
    [
        ("ur10e", 0),
        ("franka-fr3", 0),
        *(
            pytest.param(n, s, marks=pytest.mark.slow)
            for n in ("ur10e", "franka-fr3", "fanuc-lrmate200id")
            for s in (1, 2)
        ),
    ],
)
def test_gravity_is_chosen_over_fourier_terms_where_the_truth_has_no_transmission(
    name, seed
):
    """The real UR10 of issue 31: the self-weight model transferred to new sessions,
    the Fourier transmission terms did not. On twins of that kind (UR10e with its lumped
    layout, FR3 with the general link model, the FANUC) the default (auto) is within
    1.05x of the best fixed model on the other region with the frames refitted (1.00x on
    the nine of these in development; the full model's Fourier terms 1.01-1.02x, the
    transmission-only model 2-30x)."""
    robot, train, test = _gravity_shift(name, seed)
    refit = ("user", "tool")
    models = ["kinematic", "ntm", "full"] + (["rfcm"] if robot.self_weight else [])
    fixed = {
        m: evaluate(calibrate(robot, train, m).calibrated, test, refit=refit)
        for m in models
    }
    best = min(v.metrics.rms_mm for v in fixed.values())
    got = evaluate(
        auto_calibration(robot, train).calibrated, test, refit=refit
    ).metrics.rms_mm
    assert got <= 1.05 * best, (got, {k: v.metrics.rms_mm for k, v in fixed.items()})


def _nested(robot, meas, k):
    """Pooled held-out RMS of the default with the selection inside every fold."""
    num = den = 0.0
    for t in make_folds(meas, k).test:
        mask = np.zeros(meas.n, bool)
        mask[t] = True
        res = auto_calibration(robot, meas.subset(~mask))
        m = evaluate(res.calibrated, meas.subset(mask)).metrics
        num, den = num + m.rms_mm**2 * m.n, den + m.n
    return float(np.sqrt(num / den))


REAL_SETS = {
    "ur10e": ("ur10_mocap.csv", "ur10e"),
    "fr3": ("fr3_session_a.csv", "franka-fr3"),
    "tiago": (
        "tiago_mocap.csv",
        str(ROOT / "examples" / "data" / "tiago_figaroh_qualisys" / "tiago.yaml"),
    ),
}


@pytest.mark.parametrize(
    "name",
    ["ur10e", *(pytest.param(n, marks=pytest.mark.slow) for n in ("fr3", "tiago"))],
)
def test_default_on_the_shipped_real_sets_five_fold(name):
    """5-fold, the selection inside every fold: the default no worse than the kinematic
    model and within 2 % of the better of the kinematic and the full model (TIAGo: 4.276
    mm, the kinematic model's, 4.332 with the rule on fold differences in mm; UR10e equal
    to kinematic; FR3 1.202 against kinematic 1.247, full 1.178: 3 % on FR3, see
    :data:`_IN_SESSION`)."""
    f, rb = REAL_SETS[name]
    robot = load_robot(rb)
    meas = read_measurements(REAL / f, robot, check=False)
    got = _nested(robot, meas, 5)
    kin = cross_validate(robot, meas, "kinematic", k=5).rms_mm
    full = cross_validate(robot, meas, "full", k=5).rms_mm
    assert got <= 1.001 * kin, (got, kin)
    assert got <= _IN_SESSION.get(name, 1.02) * min(kin, full), (got, kin, full)


# In session a of FR3 the order-2 transmission terms of J1-J3 predict new poses better
# (the full model 1.178 mm 5-fold, 1.153 leave-one-out) but lose 9 % on session b; their
# coefficients are not reproducible across session a's regions and the default keeps
# order 1 (Eq. (T-12) of docs/theory.md): 1.202 and 1.185 mm here (1.184 and 1.166 with
# the order-2 terms), still 4-6 % better than the kinematic model. The in-session figure
# is what the issue says overstates a model; session b is the check
# (test_issue_31_fourier_stability.py).
_IN_SESSION = {"fr3": 1.03}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(REAL_SETS))
def test_default_on_the_shipped_real_sets_leave_one_out(name):
    """Leave one pose out (the selection inside every fold): no worse than the kinematic
    model (to 0.1 %) and within 2 % of the better of kinematic and full (TIAGo 4.186
    against kinematic 4.186 mm, 4.217 with the rule on fold differences in mm; FR3
    1.185 against full 1.153, 3 %: :data:`_IN_SESSION`; UR10e equal to kinematic)."""
    f, rb = REAL_SETS[name]
    robot = load_robot(rb)
    meas = read_measurements(REAL / f, robot, check=False)
    k = int(make_folds(meas, 2).test[0].size + make_folds(meas, 2).test[1].size)
    poses = len({tuple(np.round(q, 9)) for q in meas.q_ctrl})
    assert k == meas.n
    got = _nested(robot, meas, poses)
    kin = cross_validate(robot, meas, "kinematic", k=poses).rms_mm
    full = cross_validate(robot, meas, "full", k=poses).rms_mm
    assert got <= 1.001 * kin, (got, kin)
    assert got <= _IN_SESSION.get(name, 1.02) * min(kin, full), (got, kin, full)


def _table(folds: dict[str, list[float]]) -> list[Candidate]:
    sizes = {"kinematic": 41, "ntm": 56, "full": 64}
    return [
        Candidate(
            label,
            ModelSpec(name=label),
            1.0,
            sizes[label],
            float(np.sqrt(np.mean(np.square(f)))),
            0.0,
            0.0,
            fold_rms_mm=tuple(f),
        )
        for label, f in folds.items()
    ]


def test_rule_weighs_every_region_alike():
    """The selection table of one TIAGo fold (5 region folds, mm): the full model's gain
    over the kinematic model is 1.9 paired standard errors in mm, most of it from the
    hardest region (9.49 -> 7.78 mm), 1.7 in log ratios; the rule (1.75 standard
    errors) keeps the kinematic model, which predicted the held-out poses better (4.78
    against 5.00-5.02 mm). A gain that holds in every region is taken."""
    folds = {
        "kinematic": [3.5021, 6.2506, 9.4949, 2.8378, 3.3083],
        "ntm": [3.4550, 5.9556, 8.0048, 2.6339, 3.3494],
        "full": [3.4538, 5.8929, 7.7811, 2.6866, 3.3510],
    }
    kin, full = np.array(folds["kinematic"]), np.array(folds["full"])

    def se(d):
        return d.std(ddof=1) / np.sqrt(d.size)

    rms = [float(np.sqrt(np.mean(x**2))) for x in (kin, full)]
    ratio = np.log(kin / full)
    assert (rms[0] - rms[1]) / se(kin - full) > 1.75  # in mm it would not be kept
    assert ratio.mean() / se(ratio) < 1.75
    assert choose_candidate(_table(folds)).label == "kinematic"
    better = {"kinematic": folds["kinematic"]}
    better["full"] = [0.9 * x for x in folds["kinematic"]]
    assert choose_candidate(_table(better)).label == "full"
