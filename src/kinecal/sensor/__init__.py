"""The 3D rotary laser sensor (Sec. 2.2, 5.1): camera, light planes, stripes, spheres."""

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
