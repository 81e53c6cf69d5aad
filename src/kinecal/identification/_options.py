"""Settings of a calibration and the physical scales of the priors.

The priors are Gaussian, centred on the start value (nominal geometry, zero for the
transmission and compliance terms), with the standard deviations of :data:`PRIOR_SIGMA`
(theory.md, Eq. (T-6)).
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field, replace

import numpy as np

from kinecal._record import Record
from kinecal.identification._lm import LMOptions

__all__ = [
    "PRIOR_GROUPS",
    "PRIOR_SIGMA",
    "CalibrationOptions",
    "FitSettings",
    "IdentifySettings",
    "PriorSettings",
    "RejectSettings",
    "Tuning",
]

# Prior standard deviations (SI) by parameter group and kind: physical scales of the
# deviations from nominal (DH), of transmission errors (NTM) and of per-unit-weight
# compliance and link moments; the mean is the start value (nominal, or zero).
PRIOR_SIGMA: dict[tuple[str, str], float] = {
    ("joint", "length"): 1e-3,  # 1 mm
    ("joint", "angle"): np.radians(0.1),  # 0.1 deg
    ("ntm", "ntm"): 5e-4,  # rad
    ("load", "compliance"): 1e-3,  # rad/m, i.e. 1e-5 rad/(N m) for a 10 kg payload
    ("link", "moment"): 2.0,  # m: link first moment per unit payload weight
    ("link", "ratio"): 10.0,  # link mass per payload mass
}
# Which groups carry a prior for each value of CalibrationOptions.priors.
PRIOR_GROUPS: dict[str, tuple[str, ...]] = {
    "none": (),
    "compliance": ("load", "link"),
    "all": ("joint", "ntm", "load", "link"),
}
# Groups of the unified kinematic model (stage 1).
KINEMATIC_GROUPS = ("base", "joint", "cam")
# Initial LM damping for a start next to the optimum (a lifted start, or the result of a
# fit with other weights or priors): Madsen, Nielsen & Tingleff, "Methods for non-linear
# least squares problems" (2004), Sec. 3.2, advise 1e-6 when the start is believed good
# and 1e-3 otherwise (LMOptions' default, used from nominal kinematics).
MU0_WARM = 1e-6
# Stop an LM run once a step moves the estimate by about 1.4 % of its standard deviations
# (LMOptions.stol): further digits are far below the statistical uncertainty.
STOL = 1e-4
# The unconstrained stage-1 pre-fit only gives the noise and the scale of the geometry
# priors before the real stage 1 starts from it: stopping at steps of sqrt(2 x 1e-2), about
# 14 % of a standard deviation, is close enough. On a robot with large joint compliances,
# which the kinematic model cannot fit, the pre-fit otherwise crawls for 100 iterations.
STOL_PRE = 1e-2


@dataclass(frozen=True, eq=False, repr=False)
class Tuning(Record):
    """What the stages read beyond the command line's options (issue 32): each stage's
    settings (:class:`FitSettings`, :class:`IdentifySettings`, :class:`PriorSettings`,
    :class:`RejectSettings`) take theirs from here. Defaults are what ``kinecal
    calibrate`` runs.

    Attributes
    ----------
    f_scale_mm : float or None
        Where the robust loss bends (in mm of position error); default three times a
        robust estimate of the noise.
    max_iter : int
        Iterations of each Levenberg-Marquardt run.
    drop_tol, weak_tol : float
        Identifiability tolerances (see :func:`analyse_identifiability`).
    outlier_p : float
        A row is reported as an outlier when its error is this unlikely under the fitted
        noise (chi distribution of the row's components).
    variance_components : bool
        Without per-row sigmas in the data, estimate the noise from the residuals (for pose
        data separately for position and orientation) and weight by it, so priors and data
        are balanced.
    prior_sigma : dict, optional
        Per-parameter overrides ``{name: sigma (SI)}``; ``inf`` removes a prior.
    prior_scale : float
        Multiplies every prior sigma (``--model auto`` tries several when the priors are
        not adapted).
    adapt_priors : bool
        Empirical Bayes. Widen the joint-geometry priors when an unconstrained kinematic
        fit shows larger deviations from nominal than they allow (method of moments on
        the well-determined parameters; never narrowed; reported in the warnings), and
        scale the transmission, payload and link-weight priors by maximum evidence
        (0.01x to 3x, ``CalibrationResult.prior_factors``), so terms the data do not
        support are shrunk instead of fitted to noise.
    """

    f_scale_mm: float | None = None
    max_iter: int = 100
    drop_tol: float = 1e-6
    weak_tol: float = 1e-3
    outlier_p: float = 1e-5
    variance_components: bool = True
    prior_sigma: dict[str, float] | None = None
    prior_scale: float = 1.0
    adapt_priors: bool = True

    def __post_init__(self) -> None:
        if self.f_scale_mm is not None and not self.f_scale_mm > 0:
            raise ValueError(f"f_scale_mm must be positive; got {self.f_scale_mm!r}.")
        if not (isinstance(self.max_iter, numbers.Integral) and self.max_iter >= 1):
            raise ValueError(
                f"max_iter must be an integer >= 1; got {self.max_iter!r}."
            )
        for name in ("drop_tol", "weak_tol", "outlier_p"):
            v = getattr(self, name)
            if not 0 < v < 1:
                raise ValueError(f"{name} must be between 0 and 1; got {v!r}.")
        if not self.prior_scale > 0:
            raise ValueError(f"prior_scale must be positive; got {self.prior_scale!r}.")


@dataclass(frozen=True, eq=False, repr=False)
class CalibrationOptions(Record):
    """Settings of :func:`~kinecal.identification.calibrate`: what ``kinecal calibrate``
    maps from its command line, and the stages' :class:`Tuning` beyond it.

    Attributes
    ----------
    stage2 : {'direct', 'project', 'none'}
        How stage 2 fits the transmission terms: directly on the position residuals, by
        the paper's projection to joint space (Eq. 29), or not at all (``--stage2``).
    loss : {'linear', 'huber', 'soft_l1'}
        The data term's loss (``--loss``).
    priors : {'none', 'compliance', 'all'}
        Gaussian priors with physical scales (:data:`PRIOR_SIGMA`), making the estimate a
        maximum a posteriori one: 'all' (default) on the joint geometry, the transmission
        terms, the payload compliance and the link moments; 'compliance' on the payload
        and link-weight terms only (their product lambda* s is otherwise only weakly split);
        'none' is the paper's plain least squares (``--priors``).
    reject : {'auto', 'off'}
        Gross-error rejection (:class:`~kinecal.identification.RobustRejection`): rows far
        beyond the noise of the others, standing apart from them and not following the
        pose, are left out and the fit repeated ('auto'); 'off' only reports them
        (``--reject``).
    reject_z : float or None
        Reject every row whose error exceeds this many robust noise sigmas (whitened row
        norm over the robust per-component sigma), without the test that it stands
        apart; default: automatic (chi quantile of ``outlier_p``, standing apart)
        (``--reject-z``).
    tuning : Tuning
        What the stages read beyond these (iteration limits, tolerances, prior scales);
        :meth:`tuned` gives a copy with some of them changed.
    """

    stage2: str = "direct"
    loss: str = "linear"
    priors: str = "all"
    reject: str = "auto"
    reject_z: float | None = None
    tuning: Tuning = field(default_factory=Tuning)

    def __post_init__(self) -> None:
        if self.reject not in ("auto", "off"):
            raise ValueError(f"reject must be 'auto' or 'off'; got {self.reject!r}.")
        if self.reject_z is not None and not self.reject_z > 0:
            raise ValueError(f"reject_z must be positive; got {self.reject_z!r}.")
        if self.priors not in PRIOR_GROUPS:
            raise ValueError(
                f"priors must be 'none', 'compliance' or 'all'; got {self.priors!r}."
            )
        if self.stage2 not in ("direct", "project", "none"):
            raise ValueError(
                f"stage2 must be 'direct', 'project' or 'none'; got {self.stage2!r}."
            )
        if not isinstance(self.tuning, Tuning):
            raise TypeError(
                f"tuning must be a Tuning; got {type(self.tuning).__name__}."
            )
        LMOptions(loss=self.loss)  # validates the loss name

    def tuned(self, **changes: object) -> CalibrationOptions:
        """A copy with the :class:`Tuning` fields ``changes`` changed, e.g.
        ``options.tuned(max_iter=40, prior_scale=2.0)``."""
        return replace(self, tuning=replace(self.tuning, **changes))  # type: ignore[arg-type]


# The settings each stage owns (issue 32, point 3a): a stage is constructed with its own
# (``default_stages(options)`` makes them from the options); one constructed without
# (``Identify()``) reads them from the problem's options when it runs.


@dataclass(frozen=True, eq=False, repr=False)
class FitSettings(Record):
    """What the fitting stages read: the data term's loss, where a robust loss bends
    (mm; None: three times a robust noise estimate) and the iteration limit."""

    loss: str = "linear"
    f_scale_mm: float | None = None
    max_iter: int = 100

    @classmethod
    def of(cls, options: CalibrationOptions) -> FitSettings:
        t = options.tuning
        return cls(options.loss, t.f_scale_mm, t.max_iter)


@dataclass(frozen=True, eq=False, repr=False)
class IdentifySettings(Record):
    """The identifiability analysis' tolerances (:func:`analyse_identifiability`)."""

    drop_tol: float = 1e-6
    weak_tol: float = 1e-3

    @classmethod
    def of(cls, options: CalibrationOptions) -> IdentifySettings:
        return cls(options.tuning.drop_tol, options.tuning.weak_tol)


@dataclass(frozen=True, eq=False, repr=False)
class PriorSettings(Record):
    """Which groups carry priors, per-parameter overrides, a common scale and whether
    the data adapt them (see :class:`CalibrationOptions`)."""

    priors: str = "all"
    prior_sigma: dict[str, float] | None = None
    prior_scale: float = 1.0
    adapt_priors: bool = True

    @classmethod
    def of(cls, options: CalibrationOptions) -> PriorSettings:
        t = options.tuning
        return cls(options.priors, t.prior_sigma, t.prior_scale, t.adapt_priors)


@dataclass(frozen=True, eq=False, repr=False)
class RejectSettings(Record):
    """Gross-error rejection and outlier reporting (see :class:`CalibrationOptions`):
    the fit's loss names what a kept outlier met."""

    reject: str = "auto"
    reject_z: float | None = None
    outlier_p: float = 1e-5
    loss: str = "linear"

    @classmethod
    def of(cls, options: CalibrationOptions) -> RejectSettings:
        t = options.tuning
        return cls(options.reject, options.reject_z, t.outlier_p, options.loss)
