"""Audit 8: files of one session handed to the next command: compensate's CORRECTED.csv
given to evaluate as if it were measured (it printed an RMS of 3e-8 mm, the model
meeting its own targets, as the robot's accuracy)."""

from __future__ import annotations

from tests.cli_contract import failed_with, run_kinecal


def test_evaluate_refuses_a_compensate_output(data, tmp_path, capsys):
    out = tmp_path / "corrected.csv"
    res = run_kinecal(
        capsys, "compensate", data["targets"], "--model", data["model"], "--out", out
    )
    assert res.code == 0, str(res)
    res = run_kinecal(capsys, "evaluate", out, "--model", data["model"], "--json")
    failed_with(res, f"{out}: columns j1_deg_program.., err_mm, status", "compensate")
    # the corrected joints measured: positions pasted into the file are evaluated
    lines = out.read_text().splitlines()
    head = lines[0].split(",")
    k = head.index("x_mm")
    shifted = [lines[0]]
    for r in lines[1:]:
        c = r.split(",")
        c[k] = f"{float(c[k]) + 0.02:.6f}"  # a robot 20 um off along x
        shifted.append(",".join(c))
    pasted = tmp_path / "measured_corrected.csv"
    pasted.write_text("\n".join(shifted) + "\n")
    res = run_kinecal(capsys, "evaluate", pasted, "--model", data["model"], "--json")
    assert res.code == 0, str(res)
    # the same rows as measured data (the program's joints and the measured points)
    lines = out.read_text().splitlines()
    head = lines[0].split(",")
    keep = [k for k, c in enumerate(head) if c in ("x_mm", "y_mm", "z_mm") or
            c.endswith("_deg_program")]  # fmt: skip
    meas = tmp_path / "measured.csv"
    rows = [",".join(r.split(",")[k] for k in keep) for r in lines]
    meas.write_text("\n".join(rows).replace("_program", "") + "\n")
    res = run_kinecal(capsys, "evaluate", meas, "--model", data["model"], "--json")
    assert res.code == 0, str(res)


def test_evaluate_of_the_calibration_residuals_warns(data, tmp_path, capsys):
    """residuals.csv beside the model (the calibration's own poses, with their errors)
    evaluated as new data: its figures were printed as held-out errors, unsaid."""
    import shutil

    d = tmp_path / "cal"
    d.mkdir()
    shutil.copy(data["model"], d / "model.yaml")
    lines = data["train"].read_text().splitlines()
    res_csv = d / "residuals.csv"
    rows = [f"{k + 2},{ln},0.1,0.01" for k, ln in enumerate(lines[1:])]
    res_csv.write_text(
        "\n".join([f"row,{lines[0]},err_before_mm,err_mm", *rows]) + "\n"
    )
    res = run_kinecal(
        capsys, "evaluate", res_csv, "--model", d / "model.yaml", "--json"
    )
    assert res.code == 0, str(res)
    assert f"{res_csv}: the residuals" in res.err and "training errors" in res.err
    # the same rows under another name, elsewhere: held-out for all kinecal knows
    other = tmp_path / "session2.csv"
    shutil.copy(data["test"], other)
    res = run_kinecal(capsys, "evaluate", other, "--model", d / "model.yaml", "--json")
    assert res.code == 0 and "training errors" not in res.err, str(res)
