"""Camera calibration (intrinsics and lens distortion) from chessboard or ChArUco views, stored as JSON.

The RealSense D435 colour node is used as a plain UVC camera, so its intrinsics come from our own
calibration: grab views of a printed board (:func:`collect_frames`), run :func:`calibrate_chessboard` (or
:func:`calibrate_charuco`), and keep the result with :func:`save_calibration` (JSON, never pickle).
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np

FORMAT_VERSION = 1


@dataclass(frozen=True)
class CameraCalibration:
    """Pinhole intrinsics with OpenCV distortion coefficients."""

    camera_matrix: np.ndarray
    """K (3x3): fx, fy, cx, cy in pixels."""
    dist_coeffs: np.ndarray
    """OpenCV distortion coefficients (k1, k2, p1, p2, k3, ...)."""
    image_size: tuple[int, int]
    """(width, height) in pixels of the images the calibration is valid for."""
    rms_px: float = float("nan")
    """RMS reprojection error of the calibration, pixels (NaN when not measured)."""
    n_views: int = 0
    """Number of views used by the calibration."""
    method: str = "manual"
    """How it was obtained: ``chessboard``, ``charuco`` or ``manual``."""

    @property
    def K(self) -> np.ndarray:
        """Alias of :attr:`camera_matrix`."""
        return self.camera_matrix

    @property
    def dist(self) -> np.ndarray:
        """Alias of :attr:`dist_coeffs`."""
        return self.dist_coeffs

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {
            "format_version": FORMAT_VERSION,
            "camera_matrix": np.asarray(self.camera_matrix, dtype=float).tolist(),
            "dist_coeffs": np.asarray(self.dist_coeffs, dtype=float).reshape(-1).tolist(),
            "image_size": [int(self.image_size[0]), int(self.image_size[1])],
            "rms_px": None if not np.isfinite(self.rms_px) else float(self.rms_px),
            "n_views": int(self.n_views),
            "method": str(self.method),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> CameraCalibration:
        """Inverse of :meth:`to_dict`. A missing key raises KeyError; a value of the wrong type, shape or range
        (a quoted number, a 2x2 matrix, fx <= 0, NaN) raises TypeError or ValueError naming the key."""
        if not isinstance(data, dict):
            raise TypeError(f"a calibration is a JSON object, not a {type(data).__name__}")
        version = data.get("format_version", FORMAT_VERSION)
        if not _is_int(version):
            raise TypeError(f"format_version: {version!r} is not an integer")
        if version > FORMAT_VERSION:
            raise ValueError(f"calibration format {version} is newer than this code ({FORMAT_VERSION})")
        k = _numbers(data["camera_matrix"], "camera_matrix").reshape(-1)
        if k.size != 9:
            raise ValueError(f"camera_matrix: {k.size} numbers, not 3x3")
        k = k.reshape(3, 3)
        if not (k[0, 0] > 0 and k[1, 1] > 0):
            raise ValueError("camera_matrix: fx and fy (the diagonal's first two numbers) must be > 0")
        size = data["image_size"]
        if not (isinstance(size, list) and len(size) == 2 and all(_is_int(v) and v > 0 for v in size)):
            raise ValueError(f"image_size: {size!r} is not [width, height] in pixels (two positive integers)")
        rms = data.get("rms_px")
        if rms is not None and not _is_number(rms):
            raise TypeError(f"rms_px: {rms!r} is not a number or null")
        n_views = data.get("n_views", 0)
        if not _is_int(n_views):
            raise TypeError(f"n_views: {n_views!r} is not an integer")
        method = data.get("method", "manual")
        if not isinstance(method, str):
            raise TypeError(f"method: {method!r} is not a string")
        return cls(camera_matrix=k, dist_coeffs=_numbers(data.get("dist_coeffs", []), "dist_coeffs").reshape(-1),
                   image_size=(int(size[0]), int(size[1])), rms_px=float("nan") if rms is None else float(rms),
                   n_views=int(n_views), method=method)


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _numbers(value: Any, key: str) -> np.ndarray:
    """A (nested) JSON list of finite numbers as a float array; a string, a boolean or NaN is refused (numpy would
    turn "1.5" and true into numbers)."""
    def flat(v: Any) -> list:
        if isinstance(v, list):
            return [x for item in v for x in flat(item)]
        if not _is_number(v):
            raise TypeError(f"{key}: {v!r} is not a number")
        return [v]

    if not isinstance(value, list):
        raise TypeError(f"{key}: {value!r} is not a list of numbers")
    numbers = flat(value)
    try:
        out = np.asarray(value, dtype=np.float64)
    except ValueError:
        raise ValueError(f"{key}: rows of different lengths") from None
    if not np.all(np.isfinite(out)) or out.size != len(numbers):
        raise ValueError(f"{key}: not a table of finite numbers")
    return out


def calibration_from_intrinsics(camera_matrix: np.ndarray | Sequence[float], image_size: tuple[int, int],
                                dist_coeffs: np.ndarray | Sequence[float] | None = None) -> CameraCalibration:
    """A :class:`CameraCalibration` from a known K (3x3 or 9 numbers row-major), e.g. a datasheet's."""
    k = np.asarray(camera_matrix, dtype=np.float64).reshape(3, 3)
    dist = np.zeros(5) if dist_coeffs is None else np.asarray(dist_coeffs, dtype=np.float64).reshape(-1)
    return CameraCalibration(camera_matrix=k, dist_coeffs=dist, image_size=(int(image_size[0]), int(image_size[1])))


def save_calibration(path: str | Path, calib: CameraCalibration) -> Path:
    """Write ``calib`` as JSON at ``path`` (atomically: temporary file then rename); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(calib.to_dict(), f, indent=2)
            f.write("\n")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def load_calibration(path: str | Path) -> CameraCalibration:
    """Read a calibration written by :func:`save_calibration`."""
    with open(path) as f:
        return CameraCalibration.from_dict(json.load(f))


def _load_gray(image: np.ndarray | str | Path) -> np.ndarray:
    if isinstance(image, str | Path):
        img = cv2.imread(str(image), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise FileNotFoundError(f"cannot read image {image}")
        return img
    img = np.asarray(image)
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    if img.dtype != np.uint8:
        raise ValueError(f"expected 8-bit images, got {img.dtype}")
    return img


def chessboard_object_points(pattern: tuple[int, int], square_m: float) -> np.ndarray:
    """Inner-corner coordinates (cols*rows, 3) of a chessboard in its own plane (z = 0), metres, row-major."""
    cols, rows = pattern
    grid = np.zeros((rows * cols, 3), np.float32)
    grid[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square_m
    return grid


def find_chessboard(gray: np.ndarray, pattern: tuple[int, int]) -> np.ndarray | None:
    """Inner corners (N, 2) of a chessboard with ``pattern`` = (cols, rows) inner corners, or None.

    Uses the sector-based detector (``findChessboardCornersSB``, already sub-pixel) and falls back on the
    classic detector plus ``cornerSubPix``.
    """
    ok, corners = cv2.findChessboardCornersSB(gray, pattern, flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
    if ok and corners is not None:
        return corners.reshape(-1, 2).astype(np.float32)
    ok, corners = cv2.findChessboardCorners(
        gray, pattern, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not ok or corners is None:
        return None
    corners = cv2.cornerSubPix(gray, corners.astype(np.float32), (11, 11), (-1, -1),
                               (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3))
    return corners.reshape(-1, 2).astype(np.float32)


def _calibrate(object_points: list[np.ndarray], image_points: list[np.ndarray], size: tuple[int, int],
               flags: int, method: str) -> CameraCalibration:
    if len(object_points) < 3:
        raise ValueError(f"need at least 3 usable views, got {len(object_points)}")
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-9)
    rms, k, dist, _rvecs, _tvecs = cv2.calibrateCamera(
        [o.reshape(-1, 1, 3).astype(np.float32) for o in object_points],
        [i.reshape(-1, 1, 2).astype(np.float32) for i in image_points],
        size, None, None, flags=flags, criteria=criteria)
    return CameraCalibration(camera_matrix=np.asarray(k, dtype=np.float64),
                             dist_coeffs=np.asarray(dist, dtype=np.float64).reshape(-1), image_size=size,
                             rms_px=float(rms), n_views=len(object_points), method=method)


def _common_size(gray: np.ndarray, size: tuple[int, int] | None) -> tuple[int, int]:
    this = (int(gray.shape[1]), int(gray.shape[0]))
    if size is not None and size != this:
        raise ValueError(f"all images must have the same size: {size} vs {this}")
    return this


def calibrate_chessboard(images: Iterable[np.ndarray | str | Path], pattern: tuple[int, int], square_m: float,
                         flags: int = 0) -> CameraCalibration:
    """Calibrate from views of a chessboard with ``pattern`` = (cols, rows) *inner* corners of ``square_m``.

    ``images`` are arrays (grayscale or BGR) or file paths, all the same size; views where the board is not
    found are skipped (``n_views`` counts those used). ``flags`` go to ``cv2.calibrateCamera``.
    """
    if square_m <= 0:
        raise ValueError("square_m must be positive")
    obj = chessboard_object_points(pattern, square_m)
    object_points, image_points = [], []
    size = None
    for image in images:
        gray = _load_gray(image)
        size = _common_size(gray, size)
        corners = find_chessboard(gray, pattern)
        if corners is not None:
            object_points.append(obj)
            image_points.append(corners)
    if size is None:
        raise ValueError("no images given")
    return _calibrate(object_points, image_points, size, flags, "chessboard")


def make_charuco_board(squares: tuple[int, int], square_m: float, marker_m: float,
                       dictionary: int = cv2.aruco.DICT_APRILTAG_36h11) -> cv2.aruco.CharucoBoard:
    """A ChArUco board of ``squares`` = (cols, rows) squares (OpenCV's current, non-legacy layout)."""
    return cv2.aruco.CharucoBoard(squares, square_m, marker_m, cv2.aruco.getPredefinedDictionary(dictionary))


def calibrate_charuco(images: Iterable[np.ndarray | str | Path], board: cv2.aruco.CharucoBoard,
                      min_corners: int = 6, flags: int = 0) -> CameraCalibration:
    """Calibrate from views of a ChArUco ``board`` (see :func:`make_charuco_board`); partial views are fine.

    Views with fewer than ``min_corners`` interpolated chessboard corners are skipped.
    """
    detector = cv2.aruco.CharucoDetector(board)
    object_points, image_points = [], []
    size = None
    for image in images:
        gray = _load_gray(image)
        size = _common_size(gray, size)
        ch_corners, ch_ids, _mc, _mi = detector.detectBoard(gray)
        if ch_ids is None or len(ch_ids) < min_corners:
            continue
        obj, img = board.matchImagePoints(ch_corners, ch_ids)
        if obj is None or len(obj) < min_corners:
            continue
        object_points.append(np.asarray(obj, np.float32).reshape(-1, 3))
        image_points.append(np.asarray(img, np.float32).reshape(-1, 2))
    if size is None:
        raise ValueError("no images given")
    return _calibrate(object_points, image_points, size, flags, "charuco")


def collect_frames(source: cv2.VideoCapture, n: int, every_s: float, *,
                   pattern: tuple[int, int] | None = None, time_base: Literal["wall", "video"] = "wall",
                   clock: Callable[[], float] = time.monotonic, max_reads: int | None = None) -> list[np.ndarray]:
    """Grab up to ``n`` frames from an opened capture, at least ``every_s`` seconds apart.

    ``time_base="wall"`` spaces frames by ``clock`` (a live camera); ``"video"`` by the stream position
    (``CAP_PROP_POS_MSEC``, for a recorded file). With ``pattern`` = (cols, rows) only frames where a
    chessboard is found (quick check) are kept. Stops early at the end of the stream or after ``max_reads``
    reads; returns the kept frames (BGR, as read).
    """
    if n <= 0:
        return []
    frames: list[np.ndarray] = []
    last_t: float | None = None
    reads = 0
    while len(frames) < n and (max_reads is None or reads < max_reads):
        ok, frame = source.read()
        reads += 1
        if not ok or frame is None:
            break
        t = clock() if time_base == "wall" else float(source.get(cv2.CAP_PROP_POS_MSEC)) / 1000.0
        if last_t is not None and t - last_t < every_s:
            continue
        if pattern is not None and not cv2.checkChessboard(_load_gray(frame), pattern):
            continue
        frames.append(frame)
        last_t = t
    return frames
