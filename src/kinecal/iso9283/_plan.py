"""The ISO 9283 test program: the cube placed in the workspace, joint angles by IK.

:func:`place_cube` finds the largest cube (edges parallel to the base frame) whose eight
corners and five test points the tool reaches at the test orientation; :func:`iso_plan`
turns a cube into the program of the pose test: P1 -> P5 -> P4 -> P3 -> P2 per cycle,
with the controller angles the nominal model's inverse kinematics gives (one IK branch:
P1's, the others started from it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinecal.errors import DataError
from kinecal.iso9283._cube import POINT_LABELS, VISIT_ORDER, IsoCube
from kinecal.models import CalibrationModel, ModelInputs, solve_ik
from kinecal.robot import RobotDescription
from kinecal.typing import ArrayLike, Float, Int, Pose, Rotation

__all__ = [
    "DEFAULT_CYCLES",
    "IsoPlan",
    "iso_plan",
    "nominal_model",
    "place_cube",
    "plan_iso9283",
]

DEFAULT_CYCLES = 30  # the standard's number of cycles for AP and RP
# Default test orientation: the tool's z axis down, its x axis along the base's x.
TOOL_DOWN = np.diag([1.0, -1.0, -1.0])
_SAMPLES = 4000  # random joint samples: seeds and the workspace's extent
_LENGTH = 0.3  # [m] weight of 1 rad of orientation when picking seeds
_TOL = 1e-7  # [m] a point counts as reached within this
# A searched cube keeps its near face this fraction of the reach in front of the J1
# axis (clear of the robot's own base and column).
_CLEAR = 0.25


@dataclass(frozen=True)
class IsoPlan:
    """The program of an ISO 9283 pose test (SI, robot base frame).

    Attributes
    ----------
    cube : IsoCube
    R_base_tool : (3, 3) test orientation of the tool in the robot base frame.
    q_points : (5, n) controller angles of P1..P5 [rad; m for prismatic joints].
    cycles : number of cycles.
    q_ctrl : (N, n) the program, N = 5 x cycles rows in the order of visits.
    point_index : (N,) int, the test point of each row (0 = P1 .. 4 = P5).
    cycle : (N,) int, the cycle of each row (1-based).
    """

    cube: IsoCube
    R_base_tool: Rotation
    q_points: Float
    cycles: int
    q_ctrl: Float
    point_index: Int
    cycle: Int

    @property
    def labels(self) -> tuple[str, ...]:
        """The test point of each row (P1 .. P5)."""
        return tuple(POINT_LABELS[i] for i in self.point_index)

    @property
    def p_command(self) -> Float:
        """(N, 3) command position of each row in the robot base frame [m]."""
        return self.cube.points[self.point_index]


def nominal_model(
    robot: RobotDescription,
    orientation: bool = True,
    T_flange_tool: Pose | None = None,
) -> tuple[CalibrationModel, Float]:
    """The robot's nominal kinematic model with the user frame on the robot base and
    the tool ``T_flange_tool`` (4, 4) [m] (default the robot file's): ``(model,
    params)``."""
    from kinecal.planning import Instrument, planning_model

    inst = Instrument("pose" if orientation else "tracker")
    return planning_model(robot, "kinematic", inst, None, T_flange_tool)


def joint_samples(robot: RobotDescription, n: int, seed: int) -> Float:
    """``n`` controller poses (n, joints) uniform within the joint limits (+-170 deg or
    +-0.5 m where a joint has none), seeded."""
    from kinecal.robot._gravity import finite_limits

    lim = finite_limits(robot)
    rng = np.random.default_rng(seed)
    return lim[:, 0] + rng.random((n, lim.shape[0])) * (lim[:, 1] - lim[:, 0])


def _samples(
    model: CalibrationModel, params: Float, seed: int
) -> tuple[Float, Float, Float]:
    """Random joint samples within the limits and their tool poses: (q, p, R)."""
    q = joint_samples(model.robot, _SAMPLES, seed)
    out = model.evaluate(params, ModelInputs.make(q), orientation=True)
    assert out.R_user_cam is not None
    return q, out.p_user, out.R_user_cam


def _distance(samples: tuple[Float, Float, Float], p: Float, R: Rotation) -> Float:
    """(M, S) distance of each sample's tool pose to each target at orientation ``R``:
    position [m] plus ``_LENGTH`` x angle [rad]."""
    _, p_s, R_s = samples
    d = np.linalg.norm(p[:, None, :] - p_s[None], axis=2)
    cos = (np.einsum("ij,sij->s", R, R_s) - 1.0) / 2.0  # cos of the angle to R
    return d + _LENGTH * np.arccos(np.clip(cos, -1.0, 1.0))[None, :]


def _seeds(samples: tuple[Float, Float, Float], p: Float, R: Rotation) -> Float:
    """The sample nearest to each target (position plus weighted orientation)."""
    return samples[0][np.argmin(_distance(samples, p, R), axis=1)]


def _reach(
    model: CalibrationModel, params: Float, p: Float, R: Rotation, q_seed: Float
) -> tuple[Float, np.ndarray]:
    """IK of targets ``p`` (M, 3) at orientation ``R``: (q (M, n), reached (M,))."""
    M = p.shape[0]
    ik = solve_ik(
        model,
        params,
        p,
        q_seed,
        R_target=np.broadcast_to(R, (M, 3, 3)),
        max_iter=60,
    )
    ok = ik.within_limits & (ik.position_error < _TOL) & (ik.rotation_error < 1e-6)
    return ik.q_ctrl, ok


def _centre_solutions(
    model: CalibrationModel,
    params: Float,
    centres: Float,
    R: Rotation,
    samples: tuple[Float, Float, Float],
) -> tuple[Float, np.ndarray]:
    """IK of each centre (K, 3) from its 16 nearest samples, keeping the solution
    nearest to the middle of the joint ranges: (q (K, n), reached (K,))."""
    K, S = centres.shape[0], 16
    near = np.argsort(_distance(samples, centres, R), axis=1)[:, :S]  # (K, S)
    q, ok = _reach(model, params, np.repeat(centres, S, 0), R, samples[0][near.ravel()])
    lim = model.robot.limits
    lim = np.where(np.isfinite(lim), lim, np.sign(lim) * np.pi)
    off = (q - lim.mean(axis=1)) / (lim[:, 1] - lim[:, 0])
    spread = np.where(ok, np.sum(off**2, axis=1), np.inf).reshape(K, S)
    best = np.argmin(spread, axis=1)
    pick = np.arange(K) * S + best
    return q[pick], ok[pick]


def _reach_from(
    model: CalibrationModel,
    params: Float,
    p: Float,
    R: Rotation,
    q_seed: Float,
    samples: tuple[Float, Float, Float],
) -> tuple[Float, np.ndarray]:
    """:func:`_reach` from ``q_seed``, the targets it misses again from their nearest
    samples."""
    q, ok = _reach(model, params, p, R, q_seed)
    retry = np.flatnonzero(~ok)
    if retry.size:
        q2, ok2 = _reach(model, params, p[retry], R, _seeds(samples, p[retry], R))
        q[retry[ok2]] = q2[ok2]
        ok[retry] = ok2
    return q, ok


def place_cube(
    model: CalibrationModel,
    params: Float,
    R_base_tool: Rotation,
    *,
    edge: float | None = None,
    centre: ArrayLike | None = None,
    plane: str = "C1-C2-C7-C8",
    seed: int = 0,
) -> IsoCube:
    """The test cube: the largest (edges parallel to the base frame) whose corners and
    test points the tool reaches at ``R_base_tool``, or the given size and centre.

    Parameters
    ----------
    model, params : the nominal model, user frame = robot base (:func:`nominal_model`).
    R_base_tool : (3, 3) test orientation.
    edge : edge length [m]; default the largest reachable (to 1 %).
    centre : (3,) cube centre [m, base frame]; default searched on a grid in the
        robot's x-z plane (in front of the robot, y = 0) over the reachable heights,
        the cube's near face at least a quarter of the reach in front of the base
        origin (clear of the robot's column).
    plane, seed : the test plane; the seed of the random IK seeds.

    Raises
    ------
    DataError
        No cube of the given size or at the given centre is reachable.
    """
    R = np.asarray(R_base_tool, np.float64)
    samples = _samples(model, params, seed)
    p_s = samples[1]
    reach = float(np.quantile(np.hypot(p_s[:, 0], p_s[:, 1]), 0.95))
    clear = -np.inf
    if centre is not None:
        centres = np.asarray(centre, np.float64).reshape(1, 3)
    else:
        clear = _CLEAR * reach
        z_lo, z_hi = np.quantile(p_s[:, 2], [0.2, 0.8])
        xs = np.linspace(_CLEAR + 0.05, 0.8, 6) * reach
        zs = np.linspace(z_lo, z_hi, 6)
        X, Z = np.meshgrid(xs, zs, indexing="ij")
        centres = np.column_stack([X.ravel(), np.zeros(X.size), Z.ravel()])

    q_c, ok_c = _centre_solutions(model, params, centres, R, samples)

    def feasible(sizes: Float) -> np.ndarray:
        """Which centres hold a reachable cube of their edge in ``sizes``."""
        cubes = [IsoCube(c, float(e), plane) for c, e in zip(centres, sizes)]
        pts = np.concatenate([np.vstack([c.corners, c.points]) for c in cubes])
        seed_q = np.repeat(q_c, 13, axis=0)
        _, ok = _reach_from(model, params, pts, R, seed_q, samples)
        front = centres[:, 0] - 0.5 * sizes >= clear
        return ok.reshape(len(cubes), 13).all(axis=1) & ok_c & front

    if edge is not None:
        ok = feasible(np.full(len(centres), edge))
        if not ok.any():
            where = "at the given centre" if centre is not None else "anywhere tried"
            raise DataError(
                f"an ISO cube of edge {edge * 1e3:.6g} mm is not reachable {where} at "
                "the test orientation (a corner or test point is out of reach or beyond "
                "the joint limits); expected a smaller --cube-mm, another --cube-centre "
                "or --orientation."
            )
        # the feasible centre nearest to the grid's middle
        mid = centres.mean(axis=0)
        best = np.flatnonzero(ok)[np.argmin(np.linalg.norm(centres[ok] - mid, axis=1))]
        return IsoCube(centres[best], edge, plane)
    lo = np.zeros(len(centres))
    hi = np.full(len(centres), reach)
    for _ in range(8):  # bisection on the edge, every centre at once
        mid_e = 0.5 * (lo + hi)
        ok = feasible(mid_e)
        lo = np.where(ok, mid_e, lo)
        hi = np.where(ok, hi, mid_e)
    if lo.max() <= 0:
        raise DataError(
            "no ISO cube is reachable at the test orientation; expected another "
            "--orientation or --cube-centre."
        )
    k = int(np.argmax(lo))
    return IsoCube(centres[k], float(lo[k]), plane)


def iso_plan(
    model: CalibrationModel,
    params: Float,
    cube: IsoCube,
    R_base_tool: Rotation,
    *,
    cycles: int = DEFAULT_CYCLES,
    seed: int = 0,
) -> IsoPlan:
    """The ISO 9283 pose-test program for ``cube`` at ``R_base_tool``.

    Controller angles of P1..P5 from the nominal model's inverse kinematics: P1 from the
    sampled seed nearest to it (the branch farthest from the joint limits among a few),
    P2..P5 started from P1's solution so that all five share its IK branch.

    Raises
    ------
    DataError
        A test point out of reach, or ``cycles`` below 2.
    """
    if int(cycles) != cycles or cycles < 2:
        raise DataError(
            f"cycles must be an integer of at least 2 (ISO 9283: 30); got {cycles!r}."
        )
    R = np.asarray(R_base_tool, np.float64)
    pts = cube.points
    samples = _samples(model, params, seed)
    q1, ok1 = _centre_solutions(model, params, pts[:1], R, samples)
    if not ok1[0]:
        raise DataError(
            "ISO point P1 (the cube's centre) is not reachable at the test orientation; "
            "expected another --cube-centre or --orientation."
        )
    q, ok = _reach_from(model, params, pts, R, np.repeat(q1, 5, 0), samples)
    if not ok.all():
        bad = [POINT_LABELS[i] for i in np.flatnonzero(~ok)]
        raise DataError(
            f"ISO point(s) {', '.join(bad)} not reachable at the test orientation "
            "within the joint limits; expected a smaller --cube-mm or another "
            "--cube-centre or --orientation."
        )
    order = np.array([POINT_LABELS.index(lab) for lab in VISIT_ORDER], np.intp)
    n = int(cycles)
    point_index = np.tile(order, n)
    cycle = np.repeat(np.arange(1, n + 1, dtype=np.intp), len(order))
    return IsoPlan(cube, R, q, n, q[point_index], point_index, cycle)


def plan_iso9283(
    robot: RobotDescription,
    *,
    edge: float | None = None,
    centre: ArrayLike | None = None,
    R_base_tool: Rotation | None = None,
    cycles: int = DEFAULT_CYCLES,
    plane: str = "C1-C2-C7-C8",
    seed: int = 0,
    T_flange_tool: Pose | None = None,
) -> IsoPlan:
    """The ISO 9283 pose test of ``robot`` (what ``kinecal plan --iso9283`` writes).

    Parameters
    ----------
    robot : the robot (its nominal kinematics, limits and tool).
    edge : cube edge [m]; default the largest reachable (:func:`place_cube`).
    centre : (3,) cube centre in the robot base frame [m]; default searched.
    R_base_tool : (3, 3) test orientation of the tool; default the tool's z axis
        down and its x axis along the base's x (``diag(1, -1, -1)``).
    cycles : cycles of the test (the standard: 30).
    plane : the diagonal test plane (:data:`~kinecal.iso9283.PLANES`).
    seed : seed of the random IK seeds (the result is reproducible).
    T_flange_tool : (4, 4) the tool (TCP, reflector) in the flange frame [m]; default
        the robot file's.
    """
    R = TOOL_DOWN if R_base_tool is None else np.asarray(R_base_tool, np.float64)
    if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9):
        raise ValueError("R_base_tool must be a (3, 3) rotation matrix.")
    model, params = nominal_model(robot, True, T_flange_tool)
    cube = place_cube(
        model, params, R, edge=edge, centre=centre, plane=plane, seed=seed
    )
    return iso_plan(model, params, cube, R, cycles=cycles, seed=seed)
