"""Candidate poses when the user has none: spread over the joint ranges, away from
singularities, visible to the instrument.

* Joint-space candidates (tracker, 6-D tracker): a Halton sequence with a random shift
  (Cranley-Patterson rotation) over the joint ranges, which covers them evenly. A pose is
  rejected when the wrist is near its singularity (``|J5|`` below a minimum), when the
  arm is near any singularity (inverse condition number of the geometric Jacobian, its
  translation rows divided by a characteristic length of the arm, below a minimum: the
  stretched elbow, the wrist over the shoulder), when the tool point is below a floor,
  and, for a laser tracker at a known station, when the reflector does not face the
  station within its acceptance cone (the angle between the tool z axis and the line to
  the station).
* Sensor candidates: views of each target from the sensor's working distance (115-135 mm
  for the paper's sensor) and from all around its upper half, as in the paper's
  experiment 1 (:func:`kinecal.simulation.sphere_poses`, inverse kinematics on the
  nominal model), filtered as above.

Collisions with the cell are not modelled: give candidates from the cell's own checks
(``kinecal plan --candidates``) where that matters.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from kinecal.models import CalibrationModel, ModelInputs
from kinecal.robot import RobotDescription
from kinecal.simulation import sphere_poses
from kinecal.typing import Float

__all__ = [
    "Candidates",
    "halton",
    "joint_candidates",
    "range_inside_limits",
    "sensor_candidates",
]

log = logging.getLogger(__name__)

_PRIMES = (2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37)


def range_inside_limits(
    robot: RobotDescription, j: int, lo: float, hi: float, item: str
) -> None:
    """ValueError for a joint range ``item`` (joint ``j``, 1-based; [lo, hi] in rad or
    m) more than 1 deg (1 mm) beyond the joint's limits: it was clipped silently."""
    f = 1e-3 if robot.joints[j - 1].kind == "prismatic" else np.pi / 180
    lim = robot.limits[j - 1] / f  # deg or mm
    if lo / f < lim[0] - 1.0 or hi / f > lim[1] + 1.0:
        unit = "mm" if f == 1e-3 else "deg"
        raise ValueError(
            f"{item!r} goes beyond J{j}'s limits [{lim[0]:.6g}, {lim[1]:.6g}] {unit} "
            f"of {robot.name}; expected a range inside them"
        )


@dataclass(frozen=True)
class Candidates:
    """Generated candidate poses and why others were rejected.

    Attributes
    ----------
    q_ctrl : (N, n) controller angles [rad].
    target_index : (N,) int or None, the target each sensor pose looks at.
    tried : poses drawn.
    rejected : number rejected per reason.
    """

    q_ctrl: Float
    target_index: np.ndarray | None
    tried: int
    rejected: dict[str, int] = field(default_factory=dict)


def halton(n: int, dim: int, rng: np.random.Generator) -> Float:
    """``n`` points of the ``dim``-dimensional Halton sequence in [0, 1), randomly shifted
    modulo 1 (Cranley-Patterson rotation), shape (n, dim)."""
    if not 1 <= dim <= len(_PRIMES):
        raise ValueError(f"dim must be between 1 and {len(_PRIMES)}; got {dim}.")
    idx = np.arange(1, n + 1)
    out = np.zeros((n, dim))
    for d in range(dim):
        b = _PRIMES[d]
        f = 1.0
        i = idx.copy()
        while np.any(i > 0):  # radical inverse, digit by digit (log_b n passes)
            f /= b
            out[:, d] += f * (i % b)
            i //= b
    return (out + rng.uniform(size=dim)) % 1.0


def _reach(model: CalibrationModel) -> float:
    """A characteristic length of the arm: half the sum of its DH lengths [m]."""
    ch = model.robot.dh_chain()
    return max(0.5 * float(np.sum(np.abs(ch.a)) + np.sum(np.abs(ch.d))), 0.1)


def _screen(
    model: CalibrationModel,
    params: Float,
    q: Float,
    *,
    min_j5: float,
    min_conditioning: float,
    floor_z: float | None,
    station: Float | None,
    cone: float,
    rejected: dict[str, int],
) -> np.ndarray:
    """Mask of acceptable poses; counts the rejections by reason."""
    ok = np.ones(q.shape[0], bool)

    def drop(reason: str, bad: np.ndarray) -> None:
        new = bad & ok
        rejected[reason] = rejected.get(reason, 0) + int(new.sum())
        ok[new] = False

    if model.n_joints >= 5 and min_j5 > 0:
        drop("wrist singularity (|J5| small)", np.abs(q[:, 4]) < min_j5)
    inputs = ModelInputs.make(q)
    if min_conditioning > 0:
        J = model.joint_jacobian(params, inputs)
        J[:, :3] /= _reach(model)
        s = np.linalg.svd(J, compute_uv=False)
        drop("near a singularity", s[:, -1] < min_conditioning * s[:, 0])
    if floor_z is not None or station is not None:
        out = model.evaluate(params, inputs, orientation=True)
        if floor_z is not None:
            R_b, t_b = model.base_frames(params)  # the model base in the user frame
            p_mb = (out.p_user - t_b[0]) @ R_b[0]
            T = model.T_robotbase_modelbase
            z_robot = p_mb @ T[2, :3] + T[2, 3]
            drop("below the floor", z_robot < floor_z)
        if station is not None:
            assert out.R_user_cam is not None
            u = np.asarray(station, float) - out.p_user
            u /= np.linalg.norm(u, axis=1, keepdims=True)
            cos = np.einsum("ni,ni->n", out.R_user_cam[:, :, 2], u)
            drop("reflector not facing the station", cos < np.cos(cone))
    return ok


def joint_candidates(
    model: CalibrationModel,
    params: Float,
    n: int,
    *,
    ranges: Float | None = None,
    seed: int = 0,
    min_j5: float = np.radians(10.0),
    min_conditioning: float = 0.05,
    floor_z: float | None = None,
    station: Float | None = None,
    cone: float = np.radians(30.0),
    margin: float = np.radians(2.0),
    max_tries: int = 50,
) -> Candidates:
    """Up to ``n`` acceptable poses spread evenly over the joint ranges.

    Parameters
    ----------
    model, params : the planning model at nominal kinematics (user frame set).
    n : number of candidates wanted.
    ranges : (n_joints, 2) [rad]; default the joint limits less ``margin``. Ranges outside
        the limits are clipped to them.
    seed : random shift of the sequence.
    min_j5 : smallest ``|J5|`` [rad] (wrist singularity at J5 = 0 on a 6-axis arm).
    min_conditioning : smallest inverse condition number of the geometric Jacobian
        (translation rows divided by half the arm's summed DH lengths).
    floor_z : lowest tool point, z in the robot base frame [m]; None: no check.
    station : (3,) tracker position in the user frame [m]; None: no line-of-sight check.
    cone : acceptance half-angle of the reflector about the tool z axis [rad].
    max_tries : draw at most ``max_tries * n`` poses.
    """
    if n < 1:
        raise ValueError(f"the number of candidates must be positive; got {n}.")
    lim = model.robot.limits.copy()
    # A joint without limits (a URDF 'continuous' joint): one turn, every angle once
    # (a slide without limits: +-0.5 m).
    wide = np.where(model.robot.prismatic, 0.5, np.pi)
    lim = np.where(np.isfinite(lim), lim, np.sign(lim) * wide[:, None])
    lim[:, 0] += margin
    lim[:, 1] -= margin
    if ranges is not None:
        r = np.asarray(ranges, float)
        if r.shape != lim.shape or np.any(r[:, 0] > r[:, 1]):
            raise ValueError(
                f"ranges must have shape {lim.shape} with low <= high; got {r.shape}."
            )
        lim = np.column_stack(
            [np.maximum(lim[:, 0], r[:, 0]), np.minimum(lim[:, 1], r[:, 1])]
        )
        if np.any(lim[:, 0] > lim[:, 1]):
            j = int(np.flatnonzero(lim[:, 0] > lim[:, 1])[0]) + 1
            raise ValueError(f"the range of joint {j} lies outside its limits.")
    rng = np.random.default_rng(seed)
    nj = model.n_joints
    u_all = halton(max_tries * n, nj, rng)
    got: list[Float] = []
    rejected: dict[str, int] = {}
    count = tried = 0
    batch = max(2 * n, 256)
    while count < n and tried < u_all.shape[0]:
        u = u_all[tried : tried + batch]
        tried += u.shape[0]
        q = lim[:, 0] + u * (lim[:, 1] - lim[:, 0])
        ok = _screen(
            model,
            params,
            q,
            min_j5=min_j5,
            min_conditioning=min_conditioning,
            floor_z=floor_z,
            station=station,
            cone=cone,
            rejected=rejected,
        )
        got.append(q[ok])
        count += int(ok.sum())
    q_all = np.concatenate(got)[:n] if got else np.zeros((0, nj))
    log.info(
        "%d candidates from %d poses drawn; rejected %s",
        q_all.shape[0],
        tried,
        rejected,
    )
    return Candidates(q_all, None, tried, rejected)


def sensor_candidates(
    model: CalibrationModel,
    params: Float,
    targets: Float,
    n: int,
    *,
    seed: int = 0,
    standoff: tuple[float, float] = (0.115, 0.135),
    min_elevation: float = np.radians(25.0),
    ranges: Float | None = None,
    min_j5: float = np.radians(10.0),
    min_conditioning: float = 0.05,
    floor_z: float | None = None,
) -> Candidates:
    """Up to ``n`` views of the targets (about ``n / K`` each) from the working distance.

    Parameters
    ----------
    model, params : the planning model (cam frame = the sensor's optical frame, z along
        the optical axis) at nominal kinematics, user frame set.
    targets : (K, 3) target centres in the user frame [m].
    standoff : range of sensor-to-target distances along the optical axis [m].
    min_elevation : lowest view direction above the robot base's horizontal [rad].
    ranges, min_j5, min_conditioning, floor_z : as :func:`joint_candidates`.
    """
    tg = np.asarray(targets, float)
    if n < tg.shape[0]:
        raise ValueError(
            f"need at least one candidate per target ({tg.shape[0]}); got {n}."
        )
    rng = np.random.default_rng(seed)
    per = int(np.ceil(n / tg.shape[0]))
    planned = sphere_poses(
        model,
        params,
        tg,
        rng,
        per_sphere=per,
        standoff=standoff,
        min_elevation_deg=float(np.degrees(min_elevation)),
    )
    q, ti = planned.q_ctrl, planned.label
    rejected: dict[str, int] = {
        "no inverse kinematics solution": planned.n_requested - q.shape[0]
    }
    ok = np.ones(q.shape[0], bool)
    if ranges is not None:
        r = np.asarray(ranges, float)
        inside = np.all((q >= r[:, 0]) & (q <= r[:, 1]), axis=1)
        rejected["outside the joint ranges"] = int((~inside).sum())
        ok &= inside
    ok[ok] = _screen(
        model,
        params,
        q[ok],
        min_j5=min_j5,
        min_conditioning=min_conditioning,
        floor_z=floor_z,
        station=None,
        cone=np.pi,
        rejected=rejected,
    )
    q, ti = q[ok], ti[ok]
    # at most n, the targets taking turns (a pose of each, then the next of each, ...)
    turn = np.zeros(ti.size, np.intp)
    for k in range(tg.shape[0]):
        turn[ti == k] = np.arange(int(np.sum(ti == k)))
    keep = np.sort(np.lexsort((ti, turn))[:n])
    return Candidates(q[keep], ti[keep], planned.n_requested, rejected)
