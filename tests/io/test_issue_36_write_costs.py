"""Issue 36: what ``kinecal calibrate`` writes costs no work done twice."""

from __future__ import annotations

import dataclasses

import numpy as np

from kinecal.io import _model_bounds, _model_file, load_model
from kinecal.io._model_file import save_model_as_read
from kinecal.simulation import LaserTracker, experiment2


def test_issue_36_model_yaml_dumps_its_robot_once(tmp_path, monkeypatch):
    """The robot section is dumped once for the file and its fingerprint, and the
    robot read back is dumped again only when the file's fingerprint does not match
    its section (it was dumped three times)."""
    from kinecal.identification import calibrate

    exp = experiment2(3, tracker=LaserTracker(5e-6, 0.0), n_side=3)
    cal = calibrate(exp.truth.robot, exp.train, "kinematic").calibrated
    cal = dataclasses.replace(cal, info={**cal.info, "source": "train.csv"})
    dumps: list[int] = []
    for mod in (_model_file, _model_bounds):
        f = mod.dump_robot
        monkeypatch.setattr(
            mod, "dump_robot", lambda r, f=f: dumps.append(1) or f(r), raising=True
        )
    path, read = save_model_as_read(tmp_path / "model.yaml", cal)
    assert len(dumps) == 1
    assert read is not None and np.array_equal(read.params, load_model(path).params)


def test_issue_36_sha256_is_hashlibs_with_or_without_openssl(tmp_path):
    """Small inputs are hashed by CPython's own SHA-256 (no OpenSSL load), large ones
    by hashlib's: the same digests."""
    import hashlib

    from kinecal.io._files import BUILTIN_SHA256_MAX, file_sha256, sha256

    rng = np.random.default_rng(0)
    for n in (0, 1, 63, 64, 1000, BUILTIN_SHA256_MAX + 1):
        data = rng.bytes(n)
        assert sha256(data).hexdigest() == hashlib.sha256(data).hexdigest()
        f = tmp_path / f"f{n}"
        f.write_bytes(data)
        assert file_sha256(f) == hashlib.sha256(data).hexdigest()


def test_issue_36_the_report_of_calibrate_hashes_nothing_again(tmp_path, monkeypatch):
    """calibrate draws report.html from the files it has just written: their hashes
    are not computed a second time for the check against its manifest."""
    import kinecal.io
    from kinecal.cli import main
    from kinecal.io import _files, measurements_to_csv

    exp = experiment2(3, tracker=LaserTracker(5e-6, 0.0), n_side=3)
    data = tmp_path / "train.csv"
    data.write_text(measurements_to_csv(exp.train, exp.truth.robot))
    hashed: list[str] = []
    f = _files.file_sha256
    spy = lambda p: hashed.append(p) or f(p)  # noqa: E731
    monkeypatch.setattr(_files, "file_sha256", spy)
    monkeypatch.setattr(kinecal.io, "file_sha256", spy)  # (once looked up, kept there)
    argv = ["calibrate", str(data), "--robot", "fanuc-lrmate200id", "--model"]
    assert main([*argv, "kinematic", "--cv", "off", "--out", str(tmp_path / "o")]) == 0
    names = sorted(str(p).rsplit("/", 1)[-1] for p in hashed)
    assert names == ["model.yaml", "report.json", "residuals.csv", "train.csv"]


def test_issue_36_strong_correlations_are_every_pair_over_095_as_before():
    """report.json's strong correlations, taken from the pairs at once (a loop over
    the ~950 pairs of a full model): the same pairs, values and order."""
    from kinecal.identification import calibrate
    from kinecal.report import calibration_summary

    exp = experiment2(3, tracker=LaserTracker(5e-6, 0.0), n_side=3)
    res = calibrate(exp.truth.robot, exp.train, "full")
    corr, names = res.correlation(), res.calibrated.model.layout.names
    free = np.flatnonzero(res.identifiability.free)
    want = []
    for i, a in enumerate(free):
        for b in free[i + 1 :]:
            if abs(corr[a, b]) > 0.95:
                want.append({"a": names[a], "b": names[b], "correlation": corr[a, b]})
    want.sort(key=lambda d: -abs(d["correlation"]))
    got = calibration_summary(res)["identifiability"]["strong_correlations"]
    assert got == want and len(want) >= 1
