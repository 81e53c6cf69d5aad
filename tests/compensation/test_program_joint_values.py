"""A program joint target far beyond the robot's limits is bad input (issue 35's class of
silent wrong results, found in this session's audit of `compensate`)."""

from __future__ import annotations


def test_a_program_joint_far_beyond_the_limits_is_refused(tmp_path):
    """A joint target a turn or more beyond the limits (1e9 deg) is no joint value: it
    was wrapped and 'corrected' into another pose with exit 0; now refused, naming the
    file, line and joint in the file's units. Nearer the limits it is solved and
    reported as 'joint_limit' (exit 4)."""
    import pytest

    from kinecal.errors import DataError
    from kinecal.io import load_model, save_model
    from kinecal.simulation import experiment2
    from kinecal.workflows import compensate_program

    e = experiment2(3)
    from kinecal.identification import calibrate

    cal = load_model(
        save_model(
            tmp_path / "m.yaml",
            calibrate(e.truth.robot, e.train, "kinematic").calibrated,
        )
    )
    ls = tmp_path / "p.ls"
    ls.write_text(
        "/PROG X\n/MN\n   1:J P[1] 100% FINE ;\n/POS\nP[1]{\n   GP1:\n\tUF : 0, UT : 0,\n"
        "\tJ1= 1e9 deg, J2= 0 deg, J3= 0 deg,\n\tJ4= 0 deg, J5= -30 deg, J6= 0 deg\n};\n/END\n"
    )
    with pytest.raises(
        DataError, match=r"p.ls: line 8 \(P\[1\]\): J1 = 1e\+09 deg is not"
    ):
        compensate_program(cal, ls, "fanuc-ls")
    ur = tmp_path / "p.script"
    ur.write_text("def a():\n  movej([0, -1.2, 20.0, 0, 1.0, 0])\nend\n")
    with pytest.raises(DataError, match=r"line 2 \(movej\): J3 = 20 rad is not"):
        compensate_program(cal, ur, "urscript")
