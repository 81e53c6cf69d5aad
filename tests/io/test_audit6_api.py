"""Audit 6: the public workflow functions given what a script gets wrong (a name or a
path where an object is expected, a wrong shape, degrees for radians, a string for a
list): a ValueError naming the argument and what was expected, not an AttributeError,
IndexError or TypeError deep inside, and never a silently wrong result."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from kinecal import workflows as W
from kinecal.errors import ConfigError, DataError
from tests.cli_contract import make_point_data


@pytest.fixture(scope="module")
def pt(tmp_path_factory: pytest.TempPathFactory) -> dict:
    from kinecal.io import load_model, read_measurements
    from kinecal.robot import load_robot

    d = make_point_data(tmp_path_factory.mktemp("audit6_api"))
    robot = load_robot("fanuc-lrmate200id")
    return {
        **d,
        "robot": robot,
        "meas": read_measurements(d["train"], robot),
        "test_meas": read_measurements(d["test"], robot, check=False),
        "cal": load_model(d["model"]),
        "ur5e": load_robot("ur5e"),
    }


def _refused(call, *needles: str, kind: type = ConfigError) -> str:
    with pytest.raises(ValueError) as exc:
        call()
    assert isinstance(exc.value, kind), repr(exc.value)
    for n in needles:
        assert n in str(exc.value), str(exc.value)
    return str(exc.value)


def test_objects_given_as_names_or_paths(pt):
    """A robot name, a data path or a model path where the object is expected: an
    AttributeError ('str' object has no attribute 'n_joints', 'kind', 'model')."""
    _refused(
        lambda: W.calibrate_measurements("fanuc-lrmate200id", pt["meas"]),
        "robot: expected a RobotDescription", "load_robot",
    )  # fmt: skip
    _refused(
        lambda: W.calibrate_measurements(pt["robot"], str(pt["train"])),
        "meas: expected a Measurements", "read_measurements",
    )  # fmt: skip
    _refused(
        lambda: W.evaluate_measurements(str(pt["model"]), pt["test_meas"]),
        "cal: expected a CalibratedModel", "load_model",
    )  # fmt: skip
    _refused(lambda: W.evaluate_measurements(pt["cal"], str(pt["test"])), "meas:")
    _refused(lambda: W.compensate_targets(str(pt["model"]), pt["targets"]), "cal:")
    _refused(lambda: W.export_model(str(pt["model"])), "cal:")
    _refused(lambda: W.compensate_program(str(pt["model"]), "p.ls", "fanuc-ls"), "cal:")
    _refused(lambda: W.evaluate_iso_test(pt["cal"], None, "d.csv"), "meas:")
    _refused(lambda: W.forward_pose("fanuc-lrmate200id", [0] * 6), "source:")
    _refused(lambda: W.plan_setup("fanuc-lrmate200id"), "robot:")
    _refused(lambda: W.simulate_robot_twin("ur5e", n_train=10, n_test=5), "robot:")
    _refused(lambda: W.read_pose_file(str(pt["train"]), "ur5e", None), "robot:")
    _refused(
        lambda: W.compare_measurements(
            pt["robot"], pt["meas"], str(pt["test"]), ["kinematic"]
        ),
        "test: expected a Measurements",
    )


def test_calibrate_fold_arguments(pt):
    """groups of the wrong length: an IndexError in the folds; cv_folds '5': a
    TypeError; cv_folds 1 or 1000: refused only after the whole calibration ran, as
    'a fold's calibration failed'; options as a dict: an AttributeError."""
    run = W.calibrate_measurements
    r, m = pt["robot"], pt["meas"]
    _refused(
        lambda: run(r, m, model="kinematic", cv_folds=5, groups=np.array(["a", "b"])),
        "groups", f"one label per row of meas ({m.n})", "(2,)",
    )  # fmt: skip
    _refused(lambda: run(r, m, model="kinematic", cv_folds="5"), "cv_folds", "'5'")
    _refused(lambda: run(r, m, model="kinematic", cv_folds=1), "cv_folds", ">= 2")
    msg = _refused(
        lambda: run(r, m, model="kinematic", cv_folds=1000),
        "1000 folds",
        kind=DataError,
    )
    assert "a fold's calibration failed" not in msg
    _refused(lambda: run(r, m, model="kinematic", options={}), "options", "dict")


def test_evaluate_refit_given_as_a_string(pt):
    """refit='user' was iterated letter by letter ("got 'u'"); 'user,tool' is what
    the command line takes."""
    a = W.evaluate_measurements(pt["cal"], pt["test_meas"], refit="user,tool")
    b = W.evaluate_measurements(pt["cal"], pt["test_meas"], refit=("user", "tool"))
    assert a.refit == b.refit == ("user", "tool")
    assert a.evaluation.metrics.rms_mm == pytest.approx(b.evaluation.metrics.rms_mm)
    _refused(
        lambda: W.evaluate_measurements(pt["cal"], pt["test_meas"], refit="users"),
        "refit", "some of user, tool, marker", "'users'",
    )  # fmt: skip


@pytest.mark.parametrize(
    ("joints", "needles"),
    [
        ("10 20 30 40 50 60", ("joints", "got str")),  # was '17 joint values'
        (np.zeros((2, 6)), ("joints", "(2, 6)")),  # was '2 joint values'
        (None, ("joints", "got NoneType.")),  # was a TypeError (no len())
    ],
)
def test_forward_pose_joints_of_the_wrong_shape(pt, joints, needles):
    _refused(lambda: W.forward_pose(pt["robot"], joints), *needles)


def test_simulate_twin_arguments(pt):
    """q_train of the wrong shape: a numpy concatenation error; in degrees: simulated as
    90 rad; nan: 'sigma must be positive'; n_test 0: named n_train; an unknown or a
    misspelt extra: ignored, unsaid."""
    ur = pt["ur5e"]
    sim = W.simulate_robot_twin
    _refused(lambda: sim(ur, q_train=np.zeros((10, 5)), n_test=5), "(N, 6)", "(10, 5)")
    _refused(lambda: sim(ur, q_train=np.zeros(6), n_test=5), "q_train", "(6,)")
    _refused(
        lambda: sim(ur, q_train=np.full((10, 6), 90.0), n_test=5),
        "q_train[0, 0]", "90 rad", "radians",
    )  # fmt: skip
    _refused(lambda: sim(ur, q_train=np.full((3, 6), np.nan), n_test=5), "finite")
    _refused(lambda: sim(ur, n_train=10, n_test=0), "n_test", ">= 1")
    _refused(lambda: sim(ur, n_train=10, n_test=5, extras=("harmonic",)), "'harmonic'")
    a = sim(ur, n_train=10, n_test=5, extras="harmonics,wrist")
    b = sim(ur, n_train=10, n_test=5, extras=("harmonics", "wrist"))
    assert np.array_equal(a.experiment.train.p, b.experiment.train.p)


def test_export_and_compensate_arguments(pt):
    """fmt 'sdf' and names 'x' were written as a URDF with kinecal's names; a payload
    given as text: a TypeError in a comparison."""
    _refused(lambda: W.export_model(pt["cal"], "sdf"), "fmt", "urdf, yaml-dh")
    _refused(lambda: W.export_model(pt["cal"], names="x"), "names", "kinecal, robot")
    _refused(
        lambda: W.compensate_targets(pt["cal"], pt["targets"], payload_kg="3"),
        "--payload-kg", "a number", kind=DataError,
    )  # fmt: skip
    _refused(lambda: W.compensate_targets(pt["cal"], np.zeros((3, 9))), "targets")


def test_compare_models_given_as_one_string(pt):
    """models='kinematic' was read letter by letter ('k, i, n, e, ...')."""
    msg = _refused(
        lambda: W.compare_measurements(pt["robot"], pt["meas"], pt["test_meas"], "ntmx"),
        "models", "'ntmx'",
    )  # fmt: skip
    assert "n, t, m" not in msg
    assert Path(pt["model"]).exists()


def test_plan_functions_arguments(pt):
    """ranges in degrees: clipped to the limits (the whole range planned, unsaid);
    measured poses in degrees: planned from as radians; n '100': a TypeError; a model
    name for the setup or an array for the candidates: an AttributeError."""
    setup = W.plan_setup(pt["robot"], "kinematic")
    _refused(
        lambda: W.plan_candidates(setup, n=50, ranges=np.array([[-90.0, 90.0]] * 6)),
        "ranges[0] (J1)", "[-90, 90] rad", "radians",
    )  # fmt: skip
    _refused(lambda: W.plan_candidates(setup, n=50, ranges=np.zeros((5, 2))), "(5, 2)")
    _refused(lambda: W.plan_candidates(setup, n="100"), "n:", "'100'")
    _refused(
        lambda: W.plan_candidates("kinematic", n=10), "setup: expected a PlanSetup"
    )
    cand = W.plan_candidates(setup, n=200)
    _refused(lambda: W.plan_measurements(setup, cand.q, 5), "candidates: expected")
    seq = W.plan_setup(pt["robot"], pt["cal"])
    deg = np.degrees(pt["meas"].q_ctrl)
    _refused(
        lambda: W.plan_measurements(seq, cand, 5, measured=deg, random_draws=1),
        "measured[", "radians",
    )  # fmt: skip
    run = W.plan_measurements(seq, cand, 5, measured=pt["meas"].q_ctrl, random_draws=1)
    assert run is not None
    _refused(lambda: W.iso_test_program("fanuc-lrmate200id"), "robot:")


@pytest.mark.parametrize(
    ("centre", "every", "needle"),
    [((0.0, 0.0, 140.0), 1000, "every:"), ((0.0, 0.0, -140.0), 1, "center_mm:")],
)
def test_render_scan_of_a_sphere_it_cannot_see(tmp_path, centre, every, needle):
    """render_scan of a sphere behind the camera (or lit only by skipped planes): 120
    empty images written (the command line checked; the workflow did not)."""
    _refused(lambda: W.render_scan(tmp_path, centre, 15.0, every=every), needle)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize(
    ("key", "needles"),
    [
        ("cam_rotation", ("model: missing key 'cam_rotation'",)),  # was: 'got None'
        ("ntm_joints", ("unknown parameter 'joint1.k0'", "has no ntm_joints")),
        ("load", ("enable load", "has no load: defaults taken")),
        ("link", ("unknown parameter 'link.s1'", "has no link")),
    ],
)
def test_model_file_of_another_layout_names_the_absent_key(pt, tmp_path, key, needles):
    """A model.yaml whose model section lacks a term (another kinecal's layout, a hand
    edit) took its default and failed on a parameter ('unknown parameter joint1.k0'),
    or said 'got None', without naming the key that was absent."""
    from kinecal import _yaml as yaml
    from kinecal.io import load_model

    doc = yaml.load(pt["model"].read_text())
    doc["model"].pop(key)
    f = tmp_path / "old.yaml"
    f.write_text(yaml.dump(doc, sort_keys=False))
    msg = _refused(lambda: load_model(f), "old.yaml", *needles)
    assert "None" not in msg


def test_calibrate_measurements_refuses_another_robots_fit(pt):
    """LR Mate data calibrated as a UR5e from Python: a result with success True, 28 mm
    RMS and J2 138 deg off its nominal (the command refused it only when writing
    model.yaml, after its cross-validation had run)."""
    _refused(
        lambda: W.calibrate_measurements(pt["ur5e"], pt["meas"], model="kinematic"),
        "fit ends with", "ur5e", kind=DataError,
    )  # fmt: skip
