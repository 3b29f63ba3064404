"""AprilTag 36h11 tracking of the human hand and the object, in the robot base frame.

A colour camera (the RealSense D435 colour node used as a plain UVC camera) looks at the table. Three tags
matter: a *table tag* fixed on the table at a known pose in the robot base frame (it gives the camera's
pose), the *hand tag* (worn on the demonstrator's hand) and the *object tag*.

Detection uses OpenCV's :class:`cv2.aruco.ArucoDetector` with ``DICT_APRILTAG_36h11`` and subpixel corner
refinement; the pose of each tag comes from ``cv2.solvePnP(..., flags=cv2.SOLVEPNP_IPPE_SQUARE)``.

Frames: the *tag frame* has its origin at the tag centre, x to the right of the printed tag, y up and z out
of the printed face (towards a camera that sees it). Poses are 4x4 homogeneous transforms named
``<to>_from_<from>``, e.g. ``camera_from_tag`` maps tag coordinates to camera coordinates. Lengths are in
metres. Quaternions are ``(w, x, y, z)`` as in MuJoCo.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from lfdt.poses import invert_pose, quaternion_from_matrix, rotation_about_axis
from lfdt.robot.calibration import CameraCalibration, load_calibration

DEFAULT_TAG_SIZE_M = 0.065
"""Edge of the black square of a tag (the part the detector measures), metres."""


@dataclass(frozen=True)
class TagDetection:
    """One detected tag: its id, image corners and pose in the camera frame."""

    id: int
    corners: np.ndarray
    """Image corners (4, 2) in pixels, in the order top-left, top-right, bottom-right, bottom-left."""
    rvec: np.ndarray
    """Rotation vector (3,) of ``camera_from_tag``."""
    tvec: np.ndarray
    """Translation (3,) of ``camera_from_tag`` in metres: the tag centre in the camera frame."""
    pose: np.ndarray
    """``camera_from_tag`` as a 4x4 homogeneous transform."""
    reprojection_error: float
    """RMS distance in pixels between the detected corners and the corners reprojected from the pose."""
    size_m: float
    """Tag edge used for the pose, metres."""

    @property
    def rotation(self) -> np.ndarray:
        """Rotation matrix (3, 3) of ``camera_from_tag``."""
        return self.pose[:3, :3]

    @property
    def center_px(self) -> np.ndarray:
        """Mean of the four image corners, pixels."""
        return self.corners.mean(axis=0)


def tag_object_points(size_m: float) -> np.ndarray:
    """The tag's corners (4, 3) in its own frame, in the order IPPE_SQUARE expects (TL, TR, BR, BL)."""
    h = size_m / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]], dtype=np.float64)


def make_pose(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """A 4x4 homogeneous transform from a 3x3 rotation (or a rotation vector) and a translation."""
    rotation = np.asarray(rotation, dtype=np.float64)
    if rotation.shape != (3, 3):
        rotation = cv2.Rodrigues(rotation.reshape(3, 1))[0]
    pose = np.eye(4)
    pose[:3, :3] = rotation
    pose[:3, 3] = np.asarray(translation, dtype=np.float64).reshape(3)
    return pose


def apriltag_dictionary() -> cv2.aruco.Dictionary:
    """OpenCV's AprilTag 36h11 dictionary."""
    return cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)


def default_detector_parameters() -> cv2.aruco.DetectorParameters:
    """Detector parameters: subpixel corner refinement, tight convergence."""
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    params.cornerRefinementWinSize = 5
    params.cornerRefinementMaxIterations = 50
    params.cornerRefinementMinAccuracy = 0.01
    return params


def refine_corners_by_edges(gray: np.ndarray, corners: np.ndarray, camera_matrix: np.ndarray | None = None,
                            dist_coeffs: np.ndarray | None = None, max_shift_px: float = 1.5) -> np.ndarray | None:
    """Refine a tag's four outer corners by intersecting straight lines fitted to its four edges.

    Along each edge of the black square (away from the corners) the image is sampled across the edge, the
    dark-to-light step is located to a fraction of a pixel (centroid of the intensity gradient), and a line
    is fitted through those points (Huber loss); neighbouring lines are intersected. This averages dozens
    of edge points per side, so it is much less biased than refining each corner on its own (about 0.05 px
    against about 0.3 px on synthetic tags). With non-zero ``dist_coeffs`` the lines are fitted in
    undistorted pixel coordinates and the corners are distorted back. Returns the corners (4, 2) in image
    pixels, or None when an edge is too short or too weak, or a corner would move more than ``max_shift_px``
    (the caller then keeps the detector's corners).
    """
    c = np.asarray(corners, dtype=np.float64).reshape(4, 2)
    centre = c.mean(axis=0)
    img = np.asarray(gray, dtype=np.float32)
    distorted = (camera_matrix is not None and dist_coeffs is not None
                 and bool(np.any(np.asarray(dist_coeffs, dtype=np.float64) != 0)))
    lines = []
    for k in range(4):
        a, b = c[k], c[(k + 1) % 4]
        length = float(np.linalg.norm(b - a))
        if length < 12.0:
            return None
        d = (b - a) / length
        n = np.array([-d[1], d[0]])
        if np.dot(n, (a + b) / 2 - centre) < 0:
            n = -n  # outward, from the black border to the white quiet zone
        half = float(np.clip(0.4 * length / 8.0, 1.5, 4.0))  # stay inside the border cell (1/8 of the edge)
        t = np.linspace(0.12, 0.88, int(np.clip(length / 2, 8, 200))) * length
        s = np.arange(-half, half + 1e-9, 0.25)
        pts = a + t[:, None, None] * d + s[None, :, None] * n
        prof = cv2.remap(img, pts[..., 0].astype(np.float32), pts[..., 1].astype(np.float32), cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REPLICATE)
        g = np.diff(prof, axis=1)
        j = np.argmax(g, axis=1)
        idx = np.arange(g.shape[1])[None, :]
        w = np.where(np.abs(idx - j[:, None]) <= 6, np.maximum(g, 0.0), 0.0)  # +-1.5 px around the steepest step
        wsum = w.sum(axis=1)
        contrast = prof.max(axis=1) - prof.min(axis=1)
        ok = (j > 1) & (j < g.shape[1] - 2) & (contrast > 10) & (wsum > 0.5 * contrast)
        if ok.sum() < 6:
            return None
        centroid = (w * idx).sum(axis=1) / np.maximum(wsum, 1e-9)
        offset = s[0] + (centroid + 0.5) * 0.25  # gradient sample i sits between s[i] and s[i + 1]
        edge = (a + t[:, None] * d + offset[:, None] * n)[ok]
        if distorted:
            edge = cv2.undistortPoints(edge.reshape(-1, 1, 2), camera_matrix, dist_coeffs,
                                       P=camera_matrix).reshape(-1, 2)
        vx, vy, x0, y0 = cv2.fitLine(edge.astype(np.float32), cv2.DIST_HUBER, 0, 0.01, 0.01).reshape(4)
        lines.append((np.array([x0, y0], dtype=np.float64), np.array([vx, vy], dtype=np.float64)))
    out = np.empty((4, 2))
    for k in range(4):
        p1, v1 = lines[(k - 1) % 4]  # the edge ending at corner k
        p2, v2 = lines[k]  # the edge starting at corner k
        m = np.column_stack([v1, -v2])
        if abs(np.linalg.det(m)) < 1e-6:
            return None
        out[k] = p1 + np.linalg.solve(m, p2 - p1)[0] * v1
    if distorted:
        k_inv = np.linalg.inv(camera_matrix)
        rays = (k_inv @ np.column_stack([out, np.ones(4)]).T).T
        out = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), camera_matrix, dist_coeffs)[0].reshape(4, 2)
    if not np.all(np.isfinite(out)) or np.max(np.linalg.norm(out - c, axis=1)) > max_shift_px:
        return None
    return out


class AprilTagTracker:
    """Detects AprilTag 36h11 markers and estimates each one's pose in the camera frame."""

    def __init__(
        self,
        camera_matrix: np.ndarray,
        dist_coeffs: np.ndarray | Sequence[float] | None = None,
        tag_size_m: float = DEFAULT_TAG_SIZE_M,
        tag_sizes_m: Mapping[int, float] | None = None,
        parameters: cv2.aruco.DetectorParameters | None = None,
        ids: Sequence[int] | None = None,
        refine_edges: bool = True,
    ) -> None:
        """``camera_matrix`` K (3x3), ``dist_coeffs`` (None: no distortion), ``tag_size_m`` the default edge of
        the black square, ``tag_sizes_m`` per-id edges, ``parameters`` detector parameters (default: subpixel
        corner refinement), ``ids`` if given the only ids reported, ``refine_edges`` whether to refine the
        detector's corners further by edge-line fitting (:func:`refine_corners_by_edges`)."""
        self.camera_matrix = np.asarray(camera_matrix, dtype=np.float64).reshape(3, 3)
        self.dist_coeffs = (np.zeros(5) if dist_coeffs is None
                            else np.asarray(dist_coeffs, dtype=np.float64).reshape(-1))
        if tag_size_m <= 0:
            raise ValueError("tag_size_m must be positive")
        self.tag_size_m = float(tag_size_m)
        self.tag_sizes_m = {int(k): float(v) for k, v in (tag_sizes_m or {}).items()}
        self.ids = None if ids is None else frozenset(int(i) for i in ids)
        self.refine_edges = bool(refine_edges)
        self.parameters = parameters if parameters is not None else default_detector_parameters()
        self.dictionary = apriltag_dictionary()
        self._detector = cv2.aruco.ArucoDetector(self.dictionary, self.parameters)

    def size_of(self, tag_id: int) -> float:
        """Edge length in metres used for ``tag_id``."""
        return self.tag_sizes_m.get(int(tag_id), self.tag_size_m)

    def detect_corners(self, image: np.ndarray) -> list[tuple[int, np.ndarray]]:
        """Ids and image corners (4, 2) of the tags found in ``image`` (grayscale, BGR or BGRA).

        Corners come from the detector with subpixel refinement, then (``refine_edges``) from edge-line fitting
        where that succeeds.
        """
        gray = to_gray(image)
        corners, ids, _rejected = self._detector.detectMarkers(gray)
        if ids is None or len(ids) == 0:
            return []
        found = []
        for c, i in zip(corners, np.asarray(ids).reshape(-1)):
            tag_id = int(i)
            if self.ids is not None and tag_id not in self.ids:
                continue
            corners_px = np.asarray(c, dtype=np.float64).reshape(4, 2)
            if self.refine_edges:
                refined = refine_corners_by_edges(gray, corners_px, self.camera_matrix, self.dist_coeffs)
                if refined is not None:
                    corners_px = refined
            found.append((tag_id, corners_px))
        return found

    def estimate_pose(self, tag_id: int, corners: np.ndarray) -> TagDetection | None:
        """Pose of one tag from its four image corners (TL, TR, BR, BL); None if solvePnP fails."""
        size = self.size_of(tag_id)
        obj = tag_object_points(size)
        img = np.asarray(corners, dtype=np.float64).reshape(4, 2)
        ok, rvec, tvec = cv2.solvePnP(obj, img, self.camera_matrix, self.dist_coeffs,
                                      flags=cv2.SOLVEPNP_IPPE_SQUARE)
        if not ok:
            return None
        rvec = np.asarray(rvec, dtype=np.float64).reshape(3)
        tvec = np.asarray(tvec, dtype=np.float64).reshape(3)
        proj, _ = cv2.projectPoints(obj, rvec, tvec, self.camera_matrix, self.dist_coeffs)
        err = float(np.sqrt(np.mean(np.sum((proj.reshape(4, 2) - img) ** 2, axis=1))))
        return TagDetection(id=int(tag_id), corners=img, rvec=rvec, tvec=tvec, pose=make_pose(rvec, tvec),
                            reprojection_error=err, size_m=size)

    def detect(self, image: np.ndarray) -> list[TagDetection]:
        """All tags found in ``image`` with their poses in the camera frame, sorted by id."""
        out = []
        for tag_id, corners in self.detect_corners(image):
            det = self.estimate_pose(tag_id, corners)
            if det is not None:
                out.append(det)
        return sorted(out, key=lambda d: d.id)

    def detect_by_id(self, image: np.ndarray) -> dict[int, TagDetection]:
        """Like :meth:`detect`, keyed by id; if an id is seen twice the detection with more pixels wins."""
        out: dict[int, TagDetection] = {}
        for det in self.detect(image):
            prev = out.get(det.id)
            if prev is None or _area(det.corners) > _area(prev.corners):
                out[det.id] = det
        return out


def _area(corners: np.ndarray) -> float:
    return float(abs(cv2.contourArea(np.asarray(corners, dtype=np.float32).reshape(-1, 1, 2))))


def to_gray(image: np.ndarray) -> np.ndarray:
    """8-bit grayscale view of a grayscale, BGR or BGRA image."""
    img = np.asarray(image)
    if img.dtype != np.uint8:
        raise ValueError(f"expected an 8-bit image, got {img.dtype}")
    if img.ndim == 2:
        return img
    if img.ndim == 3 and img.shape[2] == 1:
        return img[:, :, 0]
    if img.ndim == 3 and img.shape[2] == 3:
        return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    if img.ndim == 3 and img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY)
    raise ValueError(f"unsupported image shape {img.shape}")


def base_from_camera(table_detection: TagDetection | np.ndarray, table_tag_in_base: np.ndarray) -> np.ndarray:
    """``base_from_camera`` (4x4) from the table tag seen by the camera and its known pose in the base frame.

    ``table_detection`` is the table tag's detection (or its ``camera_from_tag`` 4x4); ``table_tag_in_base`` is
    ``base_from_tag`` of the same tag.
    """
    camera_from_tag = table_detection.pose if isinstance(table_detection, TagDetection) else table_detection
    return np.asarray(table_tag_in_base, dtype=np.float64) @ invert_pose(np.asarray(camera_from_tag))


def detection_in_base(detection: TagDetection, base_from_cam: np.ndarray) -> np.ndarray:
    """The detected tag's pose in the robot base frame (``base_from_tag``, 4x4)."""
    return np.asarray(base_from_cam, dtype=np.float64) @ detection.pose


@dataclass(frozen=True)
class ObjectPose:
    """The object tag's pose in the robot base frame."""

    position: np.ndarray
    """(x, y, z) metres."""
    quaternion: np.ndarray
    """``(w, x, y, z)`` of ``base_from_tag``."""
    yaw: float
    """Rotation about the base z axis, radians (twist of ``base_from_tag`` about z)."""
    pose: np.ndarray
    """``base_from_tag`` 4x4."""


@dataclass(frozen=True)
class TrackedFrame:
    """What the tracker saw in one frame, in the robot base frame (metres, radians)."""

    timestamp: float
    """When the frame was read, by the tracker's clock (default ``time.monotonic()``), seconds."""
    frame_index: int
    """0-based index of the frame in the source."""
    hand_position: np.ndarray | None
    """Hand tag centre (x, y, z) in the base frame; None when not seen."""
    object_pose: ObjectPose | None
    """Object tag pose in the base frame; None when not seen."""
    lost: bool
    """True when the hand or the object (or the base transform) is missing in this frame."""
    table_seen: bool
    """True when the table tag was seen in this frame (otherwise the last camera pose is reused)."""
    video_time_s: float | None = None
    """Position in the source as reported by OpenCV (useful for video replays), seconds."""
    detections: tuple[TagDetection, ...] = ()
    """All detections of the frame, camera frame."""

    @property
    def object_position(self) -> np.ndarray | None:
        """Object tag position (x, y, z) in the base frame, or None."""
        return None if self.object_pose is None else self.object_pose.position

    @property
    def object_yaw(self) -> float | None:
        """Object yaw about the base z axis (radians), or None."""
        return None if self.object_pose is None else self.object_pose.yaw


def open_capture(source: int | str | Path, api_preference: int | None = None,
                 frame_size: tuple[int, int] | None = None) -> cv2.VideoCapture:
    """A :class:`cv2.VideoCapture` on a camera index (V4L2 backend on Linux) or a video file path.

    For a camera, ``frame_size`` (width, height) is requested from the driver.
    """
    if isinstance(source, int | np.integer):
        if api_preference is None:
            api_preference = cv2.CAP_V4L2 if sys.platform.startswith("linux") else cv2.CAP_ANY
        cap = cv2.VideoCapture(int(source), api_preference)
        if cap.isOpened() and frame_size is not None:
            cap.set(cv2.CAP_PROP_FRAME_WIDTH, int(frame_size[0]))
            cap.set(cv2.CAP_PROP_FRAME_HEIGHT, int(frame_size[1]))
    else:
        path = Path(source)
        if not path.exists():
            raise FileNotFoundError(path)
        cap = cv2.VideoCapture(str(path), cv2.CAP_ANY if api_preference is None else api_preference)
    if not cap.isOpened():
        raise RuntimeError(f"could not open video source {source!r}")
    return cap


class Tracker:
    """Reads frames from a camera or a video file and reports the hand and the object in the robot base frame.

    The camera's pose comes from the table tag (its ``base_from_tag`` is ``table_tag_in_base``); when the table
    tag is hidden in a frame, the last camera pose is reused (the camera is fixed). Frames must have the
    calibration's image size (a camera is asked for it when opened).
    """

    def __init__(
        self,
        source: int | str | Path | cv2.VideoCapture,
        calibration: CameraCalibration | str | Path,
        table_tag_id: int,
        table_tag_in_base: np.ndarray,
        hand_tag_id: int,
        object_tag_id: int,
        tag_size_m: float = DEFAULT_TAG_SIZE_M,
        tag_sizes_m: Mapping[int, float] | None = None,
        api_preference: int | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        """``source`` camera index, video path or an opened capture; ``calibration`` a
        :class:`CameraCalibration` or the path of its JSON file; tag ids and the table tag's 4x4 pose in the
        base frame; tag sizes as in :class:`AprilTagTracker`; ``api_preference`` the OpenCV backend (default:
        V4L2 for a camera on Linux); ``clock`` gives the timestamps."""
        if len({table_tag_id, hand_tag_id, object_tag_id}) != 3:
            raise ValueError("table, hand and object tags must have different ids")
        self.calibration = (calibration if isinstance(calibration, CameraCalibration)
                            else load_calibration(calibration))
        self.table_tag_id = int(table_tag_id)
        self.hand_tag_id = int(hand_tag_id)
        self.object_tag_id = int(object_tag_id)
        self.table_tag_in_base = np.asarray(table_tag_in_base, dtype=np.float64).reshape(4, 4)
        self.detector = AprilTagTracker(self.calibration.camera_matrix, self.calibration.dist_coeffs,
                                        tag_size_m=tag_size_m, tag_sizes_m=tag_sizes_m,
                                        ids=(self.table_tag_id, self.hand_tag_id, self.object_tag_id))
        self.capture = (source if isinstance(source, cv2.VideoCapture)
                        else open_capture(source, api_preference, self.calibration.image_size))
        self.clock = clock
        self.camera_in_base: np.ndarray | None = None
        """Latest ``base_from_camera`` (4x4) estimated from the table tag; None until it is first seen."""
        self.frame_index = -1
        self._ended = False

    def process(self, image: np.ndarray, timestamp: float, frame_index: int,
                video_time_s: float | None = None) -> TrackedFrame:
        """Track one already-read image (used by :meth:`read`; handy for tests and offline replays)."""
        size = (int(image.shape[1]), int(image.shape[0]))
        if size != tuple(self.calibration.image_size):
            raise ValueError(f"frame size {size} differs from the calibration's {tuple(self.calibration.image_size)}")
        dets = self.detector.detect_by_id(image)
        table = dets.get(self.table_tag_id)
        if table is not None:
            self.camera_in_base = base_from_camera(table, self.table_tag_in_base)
        hand_pos = None
        obj_pose = None
        if self.camera_in_base is not None:
            hand = dets.get(self.hand_tag_id)
            if hand is not None:
                hand_pos = detection_in_base(hand, self.camera_in_base)[:3, 3].copy()
            obj = dets.get(self.object_tag_id)
            if obj is not None:
                pose = detection_in_base(obj, self.camera_in_base)
                obj_pose = ObjectPose(position=pose[:3, 3].copy(), quaternion=quaternion_from_matrix(pose[:3, :3]),
                                      yaw=rotation_about_axis(pose[:3, :3], (0.0, 0.0, 1.0)), pose=pose)
        return TrackedFrame(timestamp=timestamp, frame_index=frame_index, hand_position=hand_pos,
                            object_pose=obj_pose, lost=hand_pos is None or obj_pose is None,
                            table_seen=table is not None, video_time_s=video_time_s,
                            detections=tuple(dets[k] for k in sorted(dets)))

    def read(self) -> TrackedFrame | None:
        """Read and track the next frame; None at the end of a video file or when the camera stops."""
        if self._ended:
            return None
        ok, frame = self.capture.read()
        if not ok or frame is None:
            self._ended = True
            return None
        timestamp = self.clock()
        self.frame_index += 1
        pos_ms = self.capture.get(cv2.CAP_PROP_POS_MSEC)
        video_time = float(pos_ms) / 1000.0 if pos_ms is not None and pos_ms >= 0 else None
        return self.process(frame, timestamp, self.frame_index, video_time)

    def __iter__(self) -> Iterator[TrackedFrame]:
        """Iterate over :meth:`read` until it returns None."""
        while (frame := self.read()) is not None:
            yield frame

    def close(self) -> None:
        """Release the capture."""
        self.capture.release()

    def __enter__(self) -> Tracker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
