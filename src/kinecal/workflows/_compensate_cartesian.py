"""The Cartesian targets of a program, compensated (issue 34; ``kinecal compensate``).

Each target is a tool pose in a user frame. The wanted flange pose in the robot base frame
is ``T_base_uframe · T_target · inv(T_flange_tool)``; the taught configuration is the
nominal joint solution with the target's flags (or, without flags, the one nearest the
program's earlier joints); the calibrated IK from there gives ``q*`` and the corrected
target is the nominal pose of ``q*`` in the same frames (:mod:`kinecal.compensation._cartesian`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from kinecal.errors import DataError
from kinecal.workflows._frames import (
    FAR_FRAME,
    FAR_TOOL,
    far_from_origin,
    how_far,
    unit_words,
)

# Why a move with an offset (RAPID Offs(p10, ..), FANUC Offset,PR[5]) is not solved
# itself: its target is corrected once.
_FOLLOWS = "follows its target"

# Frame id meaning the robot base (user frames) or the flange (tools), per format.
_BASE_IDS = {"fanuc-ls": "0", "krl": "0", "rapid": "wobj0", "urscript": ""}
_FLANGE_IDS = {"fanuc-ls": "0", "krl": "0", "rapid": "tool0", "urscript": ""}


@dataclass
class CartesianRun:
    """What the Cartesian part of a run found and did, per target."""

    points: list
    status: np.ndarray  # 'ok', 'unreachable', 'joint_limit', 'left'
    why: list[str]
    q_seed: np.ndarray  # (N, n) the taught configuration (NaN: none)
    q_new: np.ndarray  # (N, n) corrected joints (NaN: none)
    T_uf: np.ndarray
    T_tool: np.ndarray
    T_tcp: np.ndarray  # (N, 4, 4) the taught tool poses in the base frame
    edits: list = field(default_factory=list)
    notes: list = field(default_factory=list)  # (target index, message)
    res: object = None
    rows: np.ndarray = field(default_factory=lambda: np.zeros(0, np.intp))
    fmt: str = ""
    registers: dict = field(default_factory=dict)  # FANUC {n: Register} as given
    registers_new: dict = field(default_factory=dict)  # {n: Register} corrected
    follow_err: dict = field(default_factory=dict)  # {k: (err, rot)} of RAPID offsets


def _frames(
    prog: Any, pts: list[Any], uframes: dict[str, Any], utools: dict[str, Any]
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Per target: T_base_uframe, T_flange_tool (N, 4, 4) and why a frame is missing."""
    from kinecal.io._cartesian_programs import (
        point_pose,
        rapid_frames,
        urscript_features,
    )

    fmt = prog.format
    known_uf, known_tool = dict(uframes), dict(utools)
    if fmt == "urscript":  # --uframe NAME=... over the script's own value
        for name, frame in urscript_features(prog.text).items():
            known_uf.setdefault(name, frame)
    if fmt == "rapid":
        tools, wobjs = rapid_frames(prog.text)
        for name, frame in tools.items():
            known_tool.setdefault(name, frame)
        for name, frame in wobjs.items():
            known_uf.setdefault(name, frame)
    N = len(pts)
    T_uf, T_tool = np.tile(np.eye(4), (N, 1, 1)), np.tile(np.eye(4), (N, 1, 1))
    why = [pt.why_not for pt in pts]
    for k, pt in enumerate(pts):
        if fmt == "urscript" and pt.tool and not pt.tool.startswith("?"):
            try:
                vals = [float(v) for v in pt.tool[2:-1].split(",")]
            except ValueError:
                vals = []
            if len(vals) != 6 or not np.isfinite(vals).all():
                raise DataError(f"{prog.path}: line {pt.line} ({pt.name}): its tool "
                                f"{pt.tool} is no pose; expected set_tcp(p[x, y, z, "
                                "rx, ry, rz]) with 6 numbers (m, rad).")  # fmt: skip
            T_tool[k] = point_pose("urscript", tuple(vals))
        if fmt == "urscript":
            val: Any = known_uf.get(pt.frame)
            if isinstance(val, str):
                why[k] = why[k] or f"feature {pt.frame}: {val}"
            elif val is not None:
                T_uf[k] = val
            elif pt.frame:
                why[k] = why[k] or (
                    f"feature {pt.frame}: its pose is not assigned in the script (an "
                    f"installation feature?); give it with --uframe {pt.frame}=x,y,z,"
                    "rx,ry,rz (m, rad)"
                )
            continue
        for ident, base, known, out, what in (
            (pt.frame, _BASE_IDS[fmt], known_uf, T_uf, "user frame"),
            (pt.tool, _FLANGE_IDS[fmt], known_tool, T_tool, "tool"),
        ):
            val = known.get(ident)
            if isinstance(val, str):
                why[k] = why[k] or f"{what} {ident}: {val}"
            elif val is not None:
                out[k] = val
            elif ident != base:
                opt = "--uframe" if what == "user frame" else "--utool"
                why[k] = (
                    why[k]
                    or f"{what} {ident} not given ({opt} {ident}=... or --frames)"
                )
    return T_uf, T_tool, why


def _near_joints(
    prog: Any, pts: list[Any], robot: Any, q_joint: np.ndarray
) -> np.ndarray:
    """Per target without flags: the joints to start from (the UR waypoint's own, or the
    program's last joint target before it), NaN where none."""
    n = robot.n_joints
    starts = (
        np.array([p.spans[0][0] for p in prog.points]) if prog.points else np.zeros(0)
    )
    out = np.full((len(pts), n), np.nan)
    for k, pt in enumerate(pts):
        if pt.register == "joint" and len(pt.values) == n:
            out[k] = register_q(robot, pt.values)
            continue
        if len(pt.q_values) >= n:
            out[k] = pt.q_values[:n]
            continue
        before = np.flatnonzero(starts < pt.spans[0][0])
        if before.size:
            out[k] = q_joint[before[-1]]
    return out


def _seeds(
    cal: Any,
    fmt: str,
    pts: list[Any],
    F_want: np.ndarray,
    near: np.ndarray,
    why: list[str],
) -> np.ndarray:
    """The taught configuration of each target (N, n), NaN where it cannot be found."""
    from kinecal.compensation._cartesian import branch_solutions, nearest_solutions
    from kinecal.compensation._configs import config_accept

    N, n = len(pts), cal.model.n_joints
    seeds = np.full((N, n), np.nan)
    flagged = [k for k in range(N) if not why[k] and pts[k].config is not None]
    if flagged and n != 6:
        for k in flagged:
            why[k] = "configuration flags are read for 6-axis arms only"
        flagged = []
    if flagged:
        configs = [pts[k].config for k in flagged]
        q, found = branch_solutions(
            cal, F_want[flagged], config_accept(cal, fmt, configs)
        )
        seeds[flagged] = q
        for k, f in zip(flagged, found):
            if not f:
                why[k] = (
                    f"no nominal joint solution with its configuration {pts[k].config}"
                )
    free = [k for k in range(N) if not why[k] and pts[k].config is None]
    for k in free:
        if not np.isfinite(near[k]).all():
            why[k] = "no configuration and no earlier joint target to start from"
    free = [k for k in free if not why[k]]
    if free:
        q, found = nearest_solutions(cal, F_want[free], near[free])
        seeds[free] = q
        for k, f in zip(free, found):
            if not f:
                why[k] = "the nominal model does not reach it from the joints before it"
    return seeds


def _crossed_flags(cal: Any, run: CartesianRun, q_ctrl: np.ndarray) -> list[Any]:
    """New configuration flags (per target, None: kept) where the corrected joints
    cross a configuration boundary (next to J5 = 0 or the stretched arm): the
    controller must be told the branch the correction is on; noted for the screen."""
    from kinecal.compensation._configs import encode_config, same_config

    pts, rows = run.points, run.rows
    out: list = [None] * len(run.points)
    flagged = [i for i, k in enumerate(rows) if pts[k].config is not None]
    if not flagged:
        return out
    fmt = run.fmt
    same = same_config(
        cal, fmt, q_ctrl[flagged], [pts[rows[i]].config for i in flagged]
    )
    for i in np.asarray(flagged, int)[~same]:
        k = rows[i]
        new = encode_config(cal, fmt, q_ctrl[i][None])[0]
        if fmt == "krl":  # S bit 2 (A5) in the file's own sense, flipped with A5
            old = pts[k].config
            flip = (run.q_seed[k, 4] < 0) != (q_ctrl[i, 4] < 0)
            new = ((new[0] & 3) | ((old[0] & 4) ^ (4 if flip else 0)), new[1])
        out[k] = new
        if pts[k].register:
            note = (f"the correction crosses a configuration boundary: set the "
                    f"register's CONFIG to {new} (was {pts[k].config}) on the pendant "
                    "(PR[i,j]= keeps it)")  # fmt: skip
            run.notes.append((k, note))
            continue
        run.notes.append((k, f"configuration written as {new} (was {pts[k].config}): "
                             "the correction crosses a configuration boundary"))  # fmt: skip
    return out


def register_q(robot: Any, values: Any) -> np.ndarray:
    """A joint register's values (deg, mm for prismatic joints) [rad, m]."""
    v = np.asarray(values, np.float64)
    return np.where(robot.prismatic, v * 1e-3, np.radians(v))


def _target_poses(robot: Any, fmt: str, pts: list[Any], why: list[str]) -> np.ndarray:
    """Each target's pose in its frames (N, 4, 4) [m] (RAPID: at its offset); a joint
    register: the nominal flange pose of its joints (in the base frame, no tool)."""
    from kinecal.io._cartesian_programs import apply_offset, point_pose

    out = np.tile(np.eye(4), (len(pts), 1, 1))
    for k, p in enumerate(pts):
        if p.register == "joint":
            if len(p.values) != robot.n_joints:
                why[k] = why[k] or (
                    f"a joint register with {len(p.values)} joints; the robot has "
                    f"{robot.n_joints}"
                )
                continue
            out[k] = robot.fk_flange(register_q(robot, p.values)[None])[0]
        elif p.values:
            try:
                out[k] = apply_offset(point_pose(fmt, p.values), p.offset)
            except DataError as exc:
                raise DataError(f"line {p.line} ({p.name}): {exc}") from None
    return out


def _refuse_far(
    prog: Any, pts: list[Any], T: np.ndarray, T_uf: np.ndarray, T_tool: np.ndarray
) -> None:
    """A target, or a frame the program itself defines (RAPID wobj/tooldata, a
    URScript feature), beyond any robot's reach is in the wrong units or damaged."""
    for k, pt in enumerate(pts):
        for M, limit, what in (
            (T[k], FAR_FRAME, "the target"),
            (T_uf[k], FAR_FRAME, f"its user frame {pt.frame}"),
            (T_tool[k], FAR_TOOL, f"its tool {pt.tool}"),
        ):
            if far_from_origin(M, limit):
                raise DataError(
                    f"{prog.path}: line {pt.line} ({pt.name}): {what} lies "
                    f"{how_far(M)} from its origin; expected "
                    f"{unit_words(prog.format)} and at most {limit:g} m."
                )


def _corrected_registers(
    robot: Any, run: CartesianRun, T_new: np.ndarray, q_new: np.ndarray
) -> dict:
    """{n: Register} with the corrected values of the registers corrected."""
    from dataclasses import replace

    from kinecal.io._cartesian_programs import cartesian_numbers

    out = {}
    for k, pt in enumerate(run.points):
        if not pt.register or run.status[k] != "ok":
            continue
        found = re.fullmatch(r"PR\[\s*(?:GP1\s*:\s*)?(\d+).*", pt.name, re.S)
        assert found is not None  # a register with a value has a number
        n = int(found.group(1))
        if pt.register == "joint":
            deg = np.where(robot.prismatic, q_new[k] * 1e3, np.degrees(q_new[k]))
            vals = tuple(float(v) for v in deg)
        else:
            vals = tuple(
                float(v) for v in cartesian_numbers("fanuc-ls", T_new[k], pt.values)
            )
        out[n] = replace(run.registers[n], values=vals)
    return out


def cartesian_run(
    cal: Any,
    prog: Any,
    q_joint: np.ndarray,
    uframes: dict[str, Any],
    utools: dict[str, Any],
    scale: float | None,
    tol_mm: float,
    decimals: int | None,
    registers: dict | None = None,
) -> CartesianRun:
    """Correct the Cartesian targets of ``prog``; joint targets ``q_joint`` (N_j, n)
    [rad] give the starting joints of targets without flags; ``registers``: FANUC
    position register values ({n: Register}) the program's ``PR[n]`` moves use."""
    from kinecal.compensation._cartesian import compensate_poses
    from kinecal.geometry import transform_inv
    from kinecal.io._cartesian_programs import (
        cartesian_edits,
        read_cartesian,
        remove_offset,
    )

    fmt, robot = prog.format, cal.model.robot
    try:
        pts = read_cartesian(prog.text, fmt, registers)
    except DataError as exc:
        raise DataError(f"{prog.path}: {exc}") from None
    N, n = len(pts), robot.n_joints
    try:  # frames the program defines and the targets' numbers: no pose is refused
        T_uf, T_tool, why = _frames(prog, pts, uframes, utools)
        for k, p in enumerate(pts):  # checked after the robtarget is corrected
            why[k] = why[k] or (_FOLLOWS if p.follows else "")
        T_target = _target_poses(robot, fmt, pts, why).reshape(N, 4, 4)
    except DataError as exc:
        text = str(exc)
        raise DataError(text if text.startswith(str(prog.path)) else f"{prog.path}: "
                        f"{text}") from None  # fmt: skip
    _refuse_far(prog, pts, T_target, T_uf, T_tool)
    T_tcp = T_uf @ T_target
    F_want = T_tcp @ transform_inv(T_tool) if N else T_tcp
    near = _near_joints(prog, pts, robot, q_joint)
    seeds = _seeds(cal, fmt, pts, F_want, near, why)
    status = np.array(["left"] * N, dtype=object)
    q_new = np.full((N, n), np.nan)
    rows = np.array([k for k in range(N) if not why[k]], np.intp)
    run = CartesianRun(pts, status, why, seeds, q_new, T_uf, T_tool, T_tcp, rows=rows)
    run.fmt, run.registers = fmt, dict(registers or {})
    if rows.size == 0:
        return run
    ls = None if scale is None else np.full(rows.size, scale)
    pc = compensate_poses(
        cal, F_want[rows], seeds[rows], T_flange_tool=T_tool[rows], load_scale=ls,
        tol=tol_mm * 1e-3,
    )  # fmt: skip
    run.res = pc.result
    status[rows] = pc.result.status
    q_new[rows] = pc.result.q_ctrl
    new_configs = _crossed_flags(cal, run, pc.result.q_ctrl)
    ok = rows[status[rows] == "ok"]
    T_new = np.full((N, 4, 4), np.nan)
    T_corr = np.full((N, 4, 4), np.nan)
    T_corr[rows] = pc.T_corrected
    T_new[ok] = transform_inv(T_uf[ok]) @ T_corr[ok] @ T_tool[ok]
    for k in ok:  # a robtarget corrected for its offset: the robtarget written
        T_new[k] = remove_offset(T_new[k], pts[k].offset)
    run.edits = cartesian_edits(
        prog.text, fmt, pts, T_new, q_new, decimals=decimals, configs=new_configs
    )
    run.status = status
    run.registers_new = _corrected_registers(robot, run, T_new, q_new)
    return run


def written_errors(
    cal: Any, run: CartesianRun, text: str, fmt: str, scale: float | None
) -> tuple[np.ndarray, np.ndarray]:
    """How far the calibrated robot's tool is from each taught pose when the controller's
    nominal model interprets the written program: (position [m], rotation [rad]) (N,),
    NaN for targets not corrected."""
    from kinecal.compensation._cartesian import (
        branch_solutions,
        calibrated_flange,
        nearest_solutions,
    )
    from kinecal.compensation._configs import config_accept
    from kinecal.geometry import so3_log, transform_inv
    from kinecal.io._cartesian_programs import read_cartesian

    pts = read_cartesian(text, fmt, {**run.registers, **run.registers_new})
    N = len(pts)
    err_p, err_r = np.full(N, np.nan), np.full(N, np.nan)
    ok = run.status == "ok"
    base_ok = {p.name for k, p in enumerate(pts) if ok[k] and not p.follows}
    done = np.flatnonzero(
        ok | np.array([p.follows in base_ok and not p.why_not for p in pts], bool)
    )
    if done.size == 0:
        return err_p, err_r
    T = _target_poses(cal.model.robot, fmt, [pts[k] for k in done], [""] * done.size)
    F = run.T_uf[done] @ T @ transform_inv(run.T_tool[done])
    flags: list[Any] = [pts[k].config for k in done]
    if all(c is not None for c in flags):
        q, found = branch_solutions(cal, F, config_accept(cal, fmt, flags))
    else:  # a controller without flags starts from the joints it is at
        q, found = nearest_solutions(cal, F, run.q_new[done])
    run.q_new[done] = np.where(np.isnan(run.q_new[done]), q, run.q_new[done])
    ls = None if scale is None else np.full(done.size, scale)
    got = calibrated_flange(cal, np.nan_to_num(q), ls) @ run.T_tool[done]
    want = run.T_tcp[done]
    ep = np.linalg.norm(got[:, :3, 3] - want[:, :3, 3], axis=1)
    er = np.linalg.norm(
        so3_log(np.swapaxes(want[:, :3, :3], 1, 2) @ got[:, :3, :3]), axis=1
    )
    err_p[done] = np.where(found, ep, np.inf)
    err_r[done] = np.where(found, er, np.inf)
    return err_p, err_r


def settle_follows(
    run: CartesianRun, err: np.ndarray, rot: np.ndarray, tol_mm: float
) -> None:
    """The status of moves with an offset that follow their target's correction (RAPID
    ``Offs(p10, ..)`` / ``RelTool(p10, ..)``, FANUC ``L P[4] .. Offset,PR[5]``): 'ok'
    where the calibrated robot reaches the taught pose within ``tol_mm`` there, else
    left with how far it stays (one target cannot be exact at two poses); ``err`` and
    ``rot`` from :func:`written_errors`."""
    for k, p in enumerate(run.points):
        if not p.follows or run.why[k] != _FOLLOWS:
            continue
        run.q_seed[k] = run.q_new[k]
        if not np.isfinite(err[k]):
            run.why[k] = f"its target {p.follows} is not corrected"
        elif err[k] * 1e3 <= tol_mm:
            run.status[k] = "ok"
            run.follow_err[k] = (err[k], rot[k])
        else:
            run.why[k] = (
                f"follows {p.follows}'s correction, {err[k] * 1e3:.4f} mm from the "
                "taught pose here (one target cannot be exact at both; a target of its "
                "own would be)"
            )
            run.notes.append((k, run.why[k]))
