"""Issue 33: default joint-compliance priors from the link masses: a joint is expected to
yield at most PRIOR_DEFLECTION under the largest gravity torque it carries, so its prior
on lambda* (per unit reference weight) is that angle over that torque. Checked against
a torque worked out by hand, and used by the calibration's and the planner's priors."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.identification import CalibrationOptions
from kinecal.identification._options import PRIOR_SIGMA
from kinecal.identification._priors import build_prior
from kinecal.models import CalibrationModel, ModelSpec
from kinecal.planning import prior_sigma
from kinecal.robot import (
    MAX_COMPLIANCE,
    PRIOR_DEFLECTION,
    compliance_priors,
    load_robot,
    robot_from_dict,
)


def _arm(**extra):
    """A vertical J1 and a horizontal J2 with a 0.5 m link: body 2 (4 kg) at its
    middle, the tool (1 kg reference payload) at its end."""
    doc = {
        "name": "two-link",
        "convention": "dh",
        "units": {"length": "mm", "angle": "deg"},
        "joints": [
            {"theta_offset": 0, "d": 300, "a": 0, "alpha": 90, "limits": [-170, 170]},
            {"theta_offset": 0, "d": 0, "a": 500, "alpha": 0, "limits": [-170, 170]},
        ],
        "payload_kg": 1.0,
        "link_masses": [{"frame": 2, "mass_kg": 4.0, "com": [-250, 0, 0]}],
    }
    return robot_from_dict({**doc, **extra})


def test_prior_is_the_deflection_over_the_largest_torque():
    # tau_2 = (4 kg x 0.25 m + 1 kg x 0.5 m) cos(theta_2) per kg of payload weight:
    # 1.5 m at the horizontal; J1 is vertical and carries none.
    pri = compliance_priors(_arm())
    assert set(pri) == {2}
    assert pri[2] == pytest.approx(PRIOR_DEFLECTION / 1.5, rel=1e-3)
    # A heavier reference payload: the same physical compliance is a larger lambda*.
    pri5 = compliance_priors(_arm(payload_kg=5.0))
    assert pri5[2] == pytest.approx(PRIOR_DEFLECTION / ((4 * 0.25 + 5 * 0.5) / 5), 1e-3)


def test_prior_bounds_and_exceptions():
    # A 1 mm link: J2 carries almost no torque, its prior is the bound.
    light = _arm(
        joints=[
            {"theta_offset": 0, "d": 300, "a": 0, "alpha": 90},
            {"theta_offset": 0, "d": 0, "a": 0.001, "alpha": 0},
        ],
        link_masses=[{"frame": 2, "mass_kg": 4.0, "com": [0, 0, 0]}],
    )
    assert compliance_priors(light)[2] == pytest.approx(MAX_COMPLIANCE * 9.80665)
    # A file that states the compliance prior keeps it for every joint; no masses: none.
    stated = _arm(priors={"load_compliance": 2e-3})
    assert compliance_priors(stated) == {}
    assert compliance_priors(load_robot("fanuc-lrmate200id")) == {}


def test_calibration_and_planning_use_it():
    robot = _arm()
    model = CalibrationModel(robot, ModelSpec(load=True, name="load"))
    L = model.layout
    sigma = build_prior(model, model.nominal, CalibrationOptions()).sigma
    expected = compliance_priors(robot)[2]
    assert sigma[L.index("joint2.lambda")] == pytest.approx(expected)
    generic = PRIOR_SIGMA[("load", "compliance")]
    assert sigma[L.index("joint1.lambda")] == pytest.approx(generic)
    planned = prior_sigma(model, "all")
    np.testing.assert_allclose(planned, sigma)
    # The FANUC's (lumped layout, no masses) are the general ones.
    fanuc = CalibrationModel(load_robot("fanuc-lrmate200id"), ModelSpec.preset("full"))
    s = build_prior(fanuc, fanuc.nominal, CalibrationOptions()).sigma
    lam = [i for i, p in enumerate(fanuc.layout.specs) if p.group == "load"]
    assert np.allclose(s[lam], generic)
