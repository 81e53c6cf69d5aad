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
    from kinecal.sensor._stripes import extract_stripes, extract_stripes_all

__all__ = [
    "INTRINSICS",
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
    "board_pose",
    "board_views",
    "calibrate_camera",
    "calibrate_planes",
    "calibrate_sensor",
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
    "simulate_calibration",
    "sphere_scene",
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
        "_camera": ("INTRINSICS", "Camera", "paper_camera"),
        "_joint": (
            "PlaneCalibration",
            "SensorCalibration",
            "calibrate_planes",
            "calibrate_sensor",
        ),
        "_planes": ("LightPlanes", "fit_plane", "intersect_planes", "rotary_planes"),
        "_render": (
            "ChessboardTarget",
            "PlaneSurface",
            "Scene",
            "SphereSurface",
            "StripeRenderer",
            "render_chessboard",
        ),
        "_sensor": ("ScanCloud", "Sensor", "paper_sensor"),
        "_simulate": (
            "CalibrationSession",
            "RenderedImages",
            "board_views",
            "simulate_calibration",
            "sphere_scene",
        ),
        "_sphere": ("SphereFit", "fit_sphere"),
        "_stripes": ("extract_stripes", "extract_stripes_all"),
    },
)
