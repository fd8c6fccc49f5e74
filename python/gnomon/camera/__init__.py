"""The camera: its models and poses (:mod:`~gnomon.camera.models`: OpenCV's and Tsai's, rays and
projections), calibration from chessboard photos and the camera file (:mod:`~gnomon.camera.calibration`),
Tsai's two-stage method (:mod:`~gnomon.camera.tsai`), and a reference plane's pose from what is printed
on it: 2×2 checkers or a chessboard (:mod:`~gnomon.camera.plane_pose`), ArUco markers or a ChArUco board
(:mod:`~gnomon.camera.aruco`).
"""

from gnomon.camera.aruco import plane_pose_from_aruco, plane_pose_from_charuco
from gnomon.camera.calibration import (
    camera_from_table,
    camera_to_table,
    detect_chessboard,
    load_camera_file,
    write_camera_file,
)
from gnomon.camera.models import CalibratedCamera, CameraModel, OpenCVCamera, Pose, TsaiCamera
from gnomon.camera.plane_pose import PlanePose, fit_plane_pose, plane_pose_from_chessboard, plane_pose_from_markers

__all__ = [
    "CalibratedCamera", "CameraModel", "OpenCVCamera", "PlanePose", "Pose", "TsaiCamera", "camera_from_table",
    "camera_to_table", "detect_chessboard", "fit_plane_pose", "load_camera_file", "plane_pose_from_aruco",
    "plane_pose_from_charuco", "plane_pose_from_chessboard", "plane_pose_from_markers", "write_camera_file",
]
