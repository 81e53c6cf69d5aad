"""Joint names as aliases of parameter names (issue 33 point 3)."""

from kinecal.robot._param_names import (
    canonical_parameter_name,
    display_parameter_name,
)

NAMES = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint"]


def test_alias_to_canonical_and_back() -> None:
    assert (
        canonical_parameter_name("shoulder_lift_joint.theta_offset", NAMES)
        == "joint2.theta_offset"
    )
    assert canonical_parameter_name("joint2.theta_offset", NAMES) == (
        "joint2.theta_offset"
    )
    assert canonical_parameter_name("base.x", NAMES) == "base.x"
    assert canonical_parameter_name("nope_joint.d", NAMES) == "nope_joint.d"
    assert display_parameter_name("joint3.lambda", NAMES) == "elbow_joint.lambda"
    assert display_parameter_name("joint9.d", NAMES) == "joint9.d"
    assert display_parameter_name("base.x", NAMES) == "base.x"


def test_default_names_are_not_rewritten() -> None:
    names = ["joint1", "joint2"]
    assert display_parameter_name("joint2.d", names) == "joint2.d"
    assert canonical_parameter_name("joint2.d", names) == "joint2.d"
    # ambiguous (two joints share a name): left alone
    assert canonical_parameter_name("j.d", ["j", "j"]) == "j.d"
