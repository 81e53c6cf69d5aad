"""The 3D rotary laser sensor (Sec. 2.2, 5.1): camera, light planes, stripes, spheres.

Each name loads its module on first use (:mod:`kinecal._lazy`): fitting a sphere does not
import the stripe extractor's SciPy filters, nor the calibration's OpenCV.
"""

from typing import TYPE_CHECKING

from kinecal import _lazy

if TYPE_CHECKING:
    from kinecal.sensor._calibrate import (
        CameraCalibration,
        board_pose,
        calibrate_camera,
        find_corners,
    )
    from kinecal.sensor._camera import INTRINSICS, Camera, paper_camera
    from kinecal.sensor._joint import (
        PlaneCalibration,
        SensorCalibration,
        calibrate_planes,
        calibrate_sensor,
    )
    from kinecal.sensor._planes import (
        LightPlanes,
        fit_plane,
        intersect_planes,
        rotary_planes,
    )
    from kinecal.sensor._png import decode_grey_png
    from kinecal.sensor._render import (
        ChessboardTarget,
        PlaneSurface,
        Scene,
        SphereSurface,
        StripeRenderer,
        render_chessboard,
    )
    from kinecal.sensor._sensor import ScanCloud, Sensor, paper_sensor
    from kinecal.sensor._simulate import (
        CalibrationSession,
        RenderedImages,
        board_views,
        simulate_calibration,
        sphere_scene,
    )
    from kinecal.sensor._sphere import SphereFit, fit_sphere
    from kinecal.sensor._stripe_images import (
        StripeScore,
        StripeSpec,
        score_centres,
        sphere_stripe_truth,
        synthetic_stripe,
    )
    from kinecal.sensor._stripes import (
        BORDER,
        FIT_FAILED,
        NEIGHBOUR,
        SATURATED,
        STRIPE_COLUMNS,
        extract_stripes,
        extract_stripes_all,
    )

__all__ = [
    "BORDER",
    "FIT_FAILED",
    "INTRINSICS",
    "NEIGHBOUR",
    "SATURATED",
    "STRIPE_COLUMNS",
    "CalibrationSession",
    "Camera",
    "CameraCalibration",
    "ChessboardTarget",
    "LightPlanes",
    "PlaneCalibration",
    "PlaneSurface",
    "RenderedImages",
    "ScanCloud",
    "Scene",
    "Sensor",
    "SensorCalibration",
    "SphereFit",
    "SphereSurface",
    "StripeRenderer",
    "StripeScore",
    "StripeSpec",
    "board_pose",
    "board_views",
    "calibrate_camera",
    "calibrate_planes",
    "calibrate_sensor",
    "decode_grey_png",
    "extract_stripes",
    "extract_stripes_all",
    "find_corners",
    "fit_plane",
    "fit_sphere",
    "intersect_planes",
    "paper_camera",
    "paper_sensor",
    "render_chessboard",
    "rotary_planes",
    "score_centres",
    "simulate_calibration",
    "sphere_scene",
    "sphere_stripe_truth",
    "synthetic_stripe",
]

__getattr__, __dir__ = _lazy.exports(
    __name__,
    {
        "_calibrate": (
            "CameraCalibration",
            "board_pose",
            "calibrate_camera",
            "find_corners",
        ),
        "_camera": (
            "INTRINSICS",
            "Camera",
            "paper_camera",
        ),
        "_joint": (
            "PlaneCalibration",
            "SensorCalibration",
            "calibrate_planes",
            "calibrate_sensor",
        ),
        "_planes": (
            "LightPlanes",
            "fit_plane",
            "intersect_planes",
            "rotary_planes",
        ),
        "_png": ("decode_grey_png",),
        "_render": (
            "ChessboardTarget",
            "PlaneSurface",
            "Scene",
            "SphereSurface",
            "StripeRenderer",
            "render_chessboard",
        ),
        "_sensor": (
            "ScanCloud",
            "Sensor",
            "paper_sensor",
        ),
        "_simulate": (
            "CalibrationSession",
            "RenderedImages",
            "board_views",
            "simulate_calibration",
            "sphere_scene",
        ),
        "_sphere": (
            "SphereFit",
            "fit_sphere",
        ),
        "_stripe_images": (
            "StripeScore",
            "StripeSpec",
            "score_centres",
            "sphere_stripe_truth",
            "synthetic_stripe",
        ),
        "_stripes": (
            "BORDER",
            "FIT_FAILED",
            "NEIGHBOUR",
            "SATURATED",
            "STRIPE_COLUMNS",
            "extract_stripes",
            "extract_stripes_all",
        ),
    },
)
