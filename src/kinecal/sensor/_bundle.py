"""One bundle adjustment of the camera, the board poses and the light planes.

Unknowns: the intrinsics (Eq. 1-2; any of them may be held fixed), the pose ``T_cam_board``
of every board view (right-hand side perturbed on the left: ``R <- exp(dw) R``, ``t <- t +
dt``) and the light planes seen at two or more target poses (``n <- normalise(n + B d)``,
``b <- b + db``, ``B`` two unit vectors across ``n``). Residuals, both in pixels:

* board corners: projection of the corner minus its detected position (Eq. 1-2);
* stripe centres on the target: the ray of the undistorted centre meets the target plane
  of its view in ``X``; the residual is the signed distance ``s = n·X + b`` of ``X`` from
  its light plane (Eq. 3), divided by ``|ds/du|`` at the start (the distance that one
  pixel along the row makes), so it is the centre's error along the row in pixels.

Each group is weighted by its own standard deviation, estimated from its residuals and
its redundancy (variance components: ``s_g² = RSS_g / (n_g - tr(N⁻¹ N_g))``, iterated to a
fixed point), and the covariance of the parameters is ``N⁻¹`` of the weighted normal
matrix ``N = Jᵀ W J``: standard deviations from the residuals, in the units of each
parameter, whatever units the board is given in. The solver is Levenberg-Marquardt on the
normal equations, assembled block by block (every residual touches the intrinsics, one
pose and at most one plane).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kinecal._blas import one_blas_thread
from kinecal.errors import DataError
from kinecal.geometry import skew, so3_exp
from kinecal.sensor._camera import INTRINSICS, Camera
from kinecal.typing import Float

__all__ = ["BundleResult", "Stripes", "bundle_adjust"]


@dataclass(frozen=True)
class Stripes:
    """Stripe centres on the target: pixel ``uv`` (S, 2), board view ``view`` (S,) and
    light plane ``plane`` (S,) of each."""

    uv: Float
    view: np.ndarray
    plane: np.ndarray


@dataclass
class _State:
    camera: Camera
    R: Float  # (V, 3, 3) R_cam_board
    t: Float  # (V, 3) [m]
    n: Float  # (M, 3) light-plane normals
    b: Float  # (M,) [m]


@dataclass(frozen=True)
class BundleResult:
    """Result of :func:`bundle_adjust` (lengths in metres, pixels for image errors)."""

    camera: Camera
    T_cam_board: Float  # (V, 4, 4)
    n: Float  # (M, 3) light planes (the ones not adjusted as given)
    b: Float  # (M,) [m]
    free: tuple[str, ...]  # intrinsics estimated
    std: dict[str, float]  # standard deviation of each intrinsic (0 where fixed)
    covariance: (
        Float  # (P, P) of [free intrinsics, poses (6 each), adjusted planes (3)]
    )
    sigma_corner_px: float  # a-posteriori standard deviation of a corner coordinate
    sigma_stripe_px: float  # ... of a stripe centre along its row
    corner_residuals_px: Float  # (V, N, 2)
    stripe_residuals_m: Float  # (S,) signed distance of the stripe point from its plane
    plane_std_m: (
        Float  # (M,) std of each adjusted plane's position at its points' centroid
    )
    stripes: Stripes | None  # the stripes used, in the order of stripe_residuals_m
    iterations: int
    details: dict[str, object] = field(default_factory=dict)

    @property
    def rms_px(self) -> float:
        """RMS re-projection error of the corners (both coordinates)."""
        return float(np.sqrt(np.mean(self.corner_residuals_px**2)))


def _poses(R: Float, t: Float) -> Float:
    T = np.zeros((R.shape[0], 4, 4))
    T[:, :3, :3] = R
    T[:, :3, 3] = t
    T[:, 3, 3] = 1.0
    return T


def _across(n: Float) -> Float:
    """Two unit vectors (M, 3, 2) across each unit normal (M, 3)."""
    ref = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(n, ref)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return np.stack([e1, np.cross(n, e1)], axis=2)


class _Problem:
    """Residuals, Jacobian blocks and the normal equations of one adjustment."""

    def __init__(
        self,
        corners: Float,
        obj: Float,
        stripes: Stripes | None,
        free: np.ndarray,
        adjust: np.ndarray,
    ) -> None:
        self.corners, self.obj = corners, obj
        self.V = corners.shape[0]
        self.free = free  # (9,) bool
        self.nc = int(free.sum())
        self.adjust = adjust  # (M,) bool: planes estimated
        self.plane_col = np.full(adjust.size, -1)
        self.plane_col[adjust] = self.nc + 6 * self.V + 3 * np.arange(int(adjust.sum()))
        self.size = self.nc + 6 * self.V + 3 * int(adjust.sum())
        self.stripes = None
        if stripes is not None and stripes.uv.shape[0]:
            keep = adjust[stripes.plane]
            order = np.lexsort((stripes.plane[keep], stripes.view[keep]))
            self.stripes = Stripes(
                stripes.uv[keep][order],
                stripes.view[keep][order],
                stripes.plane[keep][order],
            )
            key = self.stripes.view * adjust.size + self.stripes.plane
            self.seg = np.flatnonzero(np.r_[True, key[1:] != key[:-1], True])
        self.w_px: Float | None = None  # |ds/du| per stripe point [m/px]

    # -- residuals ---------------------------------------------------------------------
    def corner_residuals(self, st: _State) -> Float:
        X = np.einsum("vij,nj->vni", st.R, self.obj) + st.t[:, None, :]
        return st.camera.project(X) - self.corners  # Eq. (1)-(2); (V, N, 2) [px]

    def stripe_distances(self, st: _State) -> Float:
        sp = self.stripes
        if sp is None:
            return np.zeros(0)
        xy = st.camera.normalised(sp.uv)
        r = np.concatenate([xy, np.ones_like(xy[:, :1])], axis=1)
        m = st.R[sp.view, :, 2]
        d = np.einsum("ij,ij->i", m, st.t[sp.view])
        X = r * (d / np.einsum("ij,ij->i", m, r))[:, None]
        return np.einsum("ij,ij->i", X, st.n[sp.plane]) + st.b[sp.plane]  # Eq. (3)

    def cost(self, st: _State, sig: tuple[float, float]) -> float:
        rc = self.corner_residuals(st) / sig[0]
        c = float(np.sum(rc**2))
        if self.stripes is not None:
            assert self.w_px is not None
            rs = self.stripe_distances(st) / (self.w_px * sig[1])
            c += float(rs @ rs)
        return c

    # -- normal equations ----------------------------------------------------------------
    def normal(
        self, st: _State, sig: tuple[float, float]
    ) -> tuple[Float, Float, Float, Float, float]:
        """Weighted ``N = JᵀWJ``, ``g = JᵀWr``, the corner and stripe parts of N and the
        cost, at ``st``."""
        P, nc, V = self.size, self.nc, self.V
        A = np.zeros((P, P))
        A_s = np.zeros((P, P))
        g = np.zeros(P)
        cam = st.camera
        # Corners: rows (u, v) of every corner of every view.
        RP = np.einsum("vij,nj->vni", st.R, self.obj)
        uv, J_uv_X, J_uv_c = cam.project_jacobian(RP + st.t[:, None, :])
        rc = (uv - self.corners) / sig[0]
        J_pose = np.concatenate([J_uv_X @ -skew(RP), J_uv_X], axis=-1)
        J = np.concatenate([J_uv_c[..., self.free], J_pose], axis=-1) / sig[0]
        J = J.reshape(V, -1, nc + 6)
        r = rc.reshape(V, -1)
        G = np.einsum("vri,vrj->vij", J, J)
        h = np.einsum("vri,vr->vi", J, r)
        for v in range(V):
            cols = np.r_[np.arange(nc), nc + 6 * v + np.arange(6)]
            A[np.ix_(cols, cols)] += G[v]
            g[cols] += h[v]
        cost = float(np.sum(rc**2))
        if self.stripes is not None:
            Js, rs = self._stripe_rows(st, sig[1])
            cost += float(rs @ rs)
            sp = self.stripes
            for a, b in zip(self.seg[:-1], self.seg[1:]):
                v, i = int(sp.view[a]), int(sp.plane[a])
                cols = np.r_[
                    np.arange(nc),
                    nc + 6 * v + np.arange(6),
                    self.plane_col[i] + np.arange(3),
                ]
                Jb = Js[a:b]
                A_s[np.ix_(cols, cols)] += Jb.T @ Jb
                g[cols] += Jb.T @ rs[a:b]
            A += A_s
        return A, g, A - A_s, A_s, cost

    def _stripe_rows(self, st: _State, sig: float) -> tuple[Float, Float]:
        """Weighted Jacobian rows (S, nc + 6 + 3) and residuals (S,) of the stripes."""
        sp = self.stripes
        assert sp is not None
        cam = st.camera
        xy, J_xy_c, J_xy_uv = cam.normalised_jacobian(sp.uv)
        r = np.concatenate([xy, np.ones_like(xy[:, :1])], axis=1)
        R, t = st.R[sp.view], st.t[sp.view]
        m = R[:, :, 2]
        d = np.einsum("ij,ij->i", m, t)
        den = np.einsum("ij,ij->i", m, r)
        X = r * (d / den)[:, None]
        n = st.n[sp.plane]
        nX = np.einsum("ij,ij->i", n, X)
        s = nX + st.b[sp.plane]  # Eq. (3)
        nr = nX * den / d  # n·r
        ds_dr = (d[:, None] * n - nX[:, None] * m) / den[:, None]
        ds_dxy = ds_dr[:, :2]
        if self.w_px is None:
            self.w_px = np.abs(np.einsum("ij,ij->i", ds_dxy, J_xy_uv[:, :, 0]))
        J_c = np.einsum("ij,ijk->ik", ds_dxy, J_xy_c)[:, self.free]
        J_w = (nr / den)[:, None] * np.cross(m, t) - (nX / den)[:, None] * np.cross(
            m, r
        )
        J_t = (nr / den)[:, None] * m
        J_n = np.einsum("ij,ijk->ik", X, _across(st.n)[sp.plane])
        scale = 1.0 / (self.w_px * sig)
        J = np.concatenate([J_c, J_w, J_t, J_n, np.ones((s.size, 1))], axis=1)
        J *= scale[:, None]
        return J, s * scale

    def dense(self, st: _State, sig: tuple[float, float]) -> tuple[Float, Float]:
        """The weighted Jacobian (R, P) and residuals (R,) as dense arrays (small
        problems: for tests): corner rows view by view, then the stripe rows."""
        nc, V = self.nc, self.V
        RP = np.einsum("vij,nj->vni", st.R, self.obj)
        uv, J_uv_X, J_uv_c = st.camera.project_jacobian(RP + st.t[:, None, :])
        J_pose = np.concatenate([J_uv_X @ -skew(RP), J_uv_X], axis=-1)
        rows = []
        for v in range(V):
            Jv = np.zeros((2 * self.obj.shape[0], self.size))
            Jv[:, :nc] = J_uv_c[v][..., self.free].reshape(-1, nc)
            Jv[:, nc + 6 * v : nc + 6 * v + 6] = J_pose[v].reshape(-1, 6)
            rows.append(Jv / sig[0])
        r = [((uv - self.corners) / sig[0]).ravel()]
        if self.stripes is not None:
            Js, rs = self._stripe_rows(st, sig[1])
            sp = self.stripes
            Jd = np.zeros((rs.size, self.size))
            k = np.arange(rs.size)[:, None]
            Jd[k, np.arange(nc)] = Js[:, :nc]
            Jd[k, nc + 6 * sp.view[:, None] + np.arange(6)] = Js[:, nc : nc + 6]
            Jd[k, self.plane_col[sp.plane][:, None] + np.arange(3)] = Js[:, nc + 6 :]
            rows.append(Jd)
            r.append(rs)
        return np.concatenate(rows), np.concatenate(r)

    def step(self, st: _State, dx: Float) -> _State:
        nc, V = self.nc, self.V
        c = st.camera.intrinsics()
        c[self.free] += dx[:nc]
        dp = dx[nc : nc + 6 * V].reshape(V, 6)
        R = so3_exp(dp[:, :3]) @ st.R
        t = st.t + dp[:, 3:]
        n, b = st.n.copy(), st.b.copy()
        idx = np.flatnonzero(self.adjust)
        if idx.size:
            dl = dx[nc + 6 * V :].reshape(-1, 3)
            nn = n[idx] + np.einsum("ijk,ik->ij", _across(n[idx]), dl[:, :2])
            n[idx] = nn / np.linalg.norm(nn, axis=1, keepdims=True)
            b[idx] += dl[:, 2]
        return _State(st.camera.with_intrinsics(c), R, t, n, b)


def _solve(
    pb: _Problem, st: _State, sig: tuple[float, float], max_iter: int
) -> tuple[_State, int, bool]:
    """Levenberg-Marquardt (Marquardt's diagonal scaling) from ``st``; ends when the
    Gauss-Newton step would lower the weighted cost by under 1e-6 (a step of 1e-3 of the
    parameters' standard deviations)."""
    mu = 1e-4
    A, g, _, _, cost = pb.normal(st, sig)
    for it in range(1, max_iter + 1):
        D = np.diag(np.diag(A))
        while True:
            try:
                dx: Float | None = np.asarray(-np.linalg.solve(A + mu * D, g), float)
            except np.linalg.LinAlgError:
                dx = None
            if dx is not None:
                new = pb.step(st, dx)
                c_new = pb.cost(new, sig)
                if c_new <= cost:
                    break
            mu *= 10.0
            if mu > 1e10:
                return st, it, False
        decrement = float(-g @ dx)
        st = new
        mu = max(mu / 10.0, 1e-10)
        A, g, _, _, cost = pb.normal(st, sig)
        if decrement < 1e-6:
            return st, it, True
    return st, max_iter, False


def bundle_adjust(
    camera: Camera,
    T_cam_board: Float,
    corners: Float,
    object_points: Float,
    *,
    stripes: Stripes | None = None,
    planes: tuple[Float, Float] | None = None,
    adjust_planes: np.ndarray | None = None,
    fixed: tuple[str, ...] = (),
    max_iter: int = 100,
) -> BundleResult:
    """Adjust the intrinsics (but ``fixed``), the board poses and the light planes.

    Parameters
    ----------
    camera
        Starting intrinsics.
    T_cam_board : (V, 4, 4)
        Starting pose of the board in the camera frame for every view [m].
    corners : (V, N, 2)
        Detected corners [px] of every view, in the order of ``object_points`` (N, 3) [m,
        board frame].
    stripes, planes, adjust_planes
        Stripe centres on the board (of views ``stripes.view``), the starting light
        planes ``(n (M, 3), b (M,) [m])`` and which of them to estimate (default: those
        with stripes on two or more views).
    fixed
        Names of intrinsics (:data:`~kinecal.sensor.INTRINSICS`) held at their value.

    The dense algebra runs with one BLAS thread.
    """
    with one_blas_thread():
        return _bundle_adjust(
            camera,
            T_cam_board,
            corners,
            object_points,
            stripes=stripes,
            planes=planes,
            adjust_planes=adjust_planes,
            fixed=fixed,
            max_iter=max_iter,
        )


def _bundle_adjust(
    camera: Camera,
    T_cam_board: Float,
    corners: Float,
    object_points: Float,
    *,
    stripes: Stripes | None,
    planes: tuple[Float, Float] | None,
    adjust_planes: np.ndarray | None,
    fixed: tuple[str, ...],
    max_iter: int,
) -> BundleResult:
    corners = np.asarray(corners, float)
    obj = np.asarray(object_points, float)
    T = np.asarray(T_cam_board, float)
    V = corners.shape[0]
    if corners.ndim != 3 or corners.shape[2] != 2 or corners.shape[1] != obj.shape[0]:
        raise DataError(
            f"bundle_adjust: corners must be (V, {obj.shape[0]}, 2), got {corners.shape}"
        )
    if T.shape != (V, 4, 4):
        raise DataError(
            f"bundle_adjust: T_cam_board must be ({V}, 4, 4), got {T.shape}"
        )
    unknown = set(fixed) - set(INTRINSICS)
    if unknown:
        raise DataError(
            f"bundle_adjust: unknown intrinsics {sorted(unknown)}; names are {INTRINSICS}"
        )
    free = np.array([k not in fixed for k in INTRINSICS])
    n0, b0 = (np.zeros((0, 3)), np.zeros(0)) if planes is None else planes
    n0, b0 = np.array(n0, float), np.array(b0, float)
    if adjust_planes is None:
        adjust_planes = np.zeros(n0.shape[0], bool)
        if stripes is not None:
            for i in range(n0.shape[0]):
                adjust_planes[i] = np.unique(stripes.view[stripes.plane == i]).size >= 2
    adjust = np.asarray(adjust_planes, bool)
    pb = _Problem(corners, obj, stripes, free, adjust)
    st = _State(camera, T[:, :3, :3].copy(), T[:, :3, 3].copy(), n0, b0)
    sig = (0.05, 0.1)  # starting guesses [px]; replaced by the estimates below
    iters = 0
    converged = False
    for _ in range(6):  # variance components to a fixed point
        st, it, converged = _solve(pb, st, sig, max_iter)
        iters += it
        A, _, A_c, A_s, _ = pb.normal(st, sig)
        Ainv = np.linalg.inv(A)
        rc = pb.corner_residuals(st)
        red_c = rc.size - float(np.sum(Ainv * A_c))
        new_c = max(float(np.sqrt(np.sum(rc**2) / max(red_c, 1.0))), 1e-6)
        new_s = sig[1]
        if pb.stripes is not None:
            assert pb.w_px is not None
            rs = pb.stripe_distances(st) / pb.w_px
            red_s = rs.size - float(np.sum(Ainv * A_s))
            new_s = max(float(np.sqrt(np.sum(rs**2) / max(red_s, 1.0))), 1e-6)
        done = abs(new_c / sig[0] - 1) < 1e-2 and abs(new_s / sig[1] - 1) < 1e-2
        sig = (new_c, new_s)
        if done:
            break
    A, *_ = pb.normal(st, sig)
    cov = np.linalg.inv(A)
    # What each fixed intrinsic would give if it were estimated as well, at this
    # solution: its standard deviation and variance inflation factor (its variance
    # with the others estimated over its variance with the others known).
    if_free = _if_free(pb, st, sig, stripes)
    std = dict.fromkeys(INTRINSICS, 0.0)
    for k, name in enumerate(np.array(INTRINSICS)[free]):
        std[str(name)] = float(np.sqrt(cov[k, k]))
    # Std of each plane's position (signed distance) at the centroid of its points.
    plane_std = _plane_std(pb, st, cov)
    return BundleResult(
        camera=st.camera,
        T_cam_board=_poses(st.R, st.t),
        n=st.n,
        b=st.b,
        free=tuple(str(k) for k in np.array(INTRINSICS)[free]),
        std=std,
        covariance=np.asarray(cov, np.float64),
        sigma_corner_px=sig[0],
        sigma_stripe_px=sig[1],
        corner_residuals_px=pb.corner_residuals(st),
        stripe_residuals_m=pb.stripe_distances(st),
        plane_std_m=plane_std,
        stripes=pb.stripes,
        iterations=iters,
        details={"converged": converged, "normal_matrix": A, "if_free": if_free},
    )


def _if_free(
    pb: _Problem, st: _State, sig: tuple[float, float], stripes: Stripes | None
) -> dict[str, dict[str, float]]:
    """Per fixed intrinsic: its std and variance inflation factor were it estimated
    (``stripes``: as given to the adjustment)."""
    if_free: dict[str, dict[str, float]] = {}
    free, adjust = pb.free, pb.adjust
    if not free.all():
        full = _Problem(pb.corners, pb.obj, stripes, np.ones(9, bool), adjust)
        full.w_px = pb.w_px  # the same weights (the same stripe order)
        A_full = full.normal(st, sig)[0]
        try:
            inv_full = np.linalg.inv(A_full)
        except np.linalg.LinAlgError:
            inv_full = np.full_like(A_full, np.inf)
        for kk in np.flatnonzero(~free):
            var = float(inv_full[kk, kk])
            if_free[INTRINSICS[kk]] = {
                "std": float(np.sqrt(var)) if var >= 0 else float("inf"),
                "vif": var * float(A_full[kk, kk]),
            }
    return if_free


def _plane_std(pb: _Problem, st: _State, cov: np.ndarray) -> Float:
    """Std of each adjusted plane's position at the centroid of its points (NaN else)."""
    adjust = pb.adjust
    plane_std = np.full(adjust.size, np.nan)
    if pb.stripes is not None:
        sp = pb.stripes
        xy = st.camera.normalised(sp.uv)
        r = np.concatenate([xy, np.ones_like(xy[:, :1])], axis=1)
        m = st.R[sp.view, :, 2]
        d = np.einsum("ij,ij->i", m, st.t[sp.view])
        X = r * (d / np.einsum("ij,ij->i", m, r))[:, None]
        B = _across(st.n)
        for ip in np.flatnonzero(adjust):
            c0 = int(pb.plane_col[ip])
            j = np.r_[np.mean(X[sp.plane == ip], axis=0) @ B[ip], 1.0]
            plane_std[ip] = float(np.sqrt(j @ cov[c0 : c0 + 3, c0 : c0 + 3] @ j))
    return plane_std
