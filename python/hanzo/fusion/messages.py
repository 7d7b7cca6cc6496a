"""The sensor messages of hanzo-fusion (docs/messages.md) as dataclasses holding numpy arrays.

Times are integer nanoseconds since the Unix epoch (exact; `time_s` gives seconds), units SI,
every vector in the sensor's own frame. Arrays are converted on construction (to the dtype
named per field) and their shapes checked: a wrong shape raises ValueError naming the field.
Values (NaN, a non-unit quaternion, an unknown encoding...) are checked where the message is
used: `Session.push`, `LogWriter.write` and the gRPC streams refuse them with the reason.

    from hanzo.fusion.messages import Imu
    imu = Imu(timestamp_ns=1_700_000_000_000_000_000, linear_acceleration=[0, 0, 9.81], angular_velocity=[0, 0, 0])
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional, Union

import numpy as np

__all__ = [
    "CameraIntrinsics", "Detection", "Detections", "Distortion", "Gnss", "Image", "Imu", "LogRecord", "Message", "PointCloud",
    "PoseEstimate", "Radar", "Range", "WheelOdometry", "FIX_TYPES", "IMAGE_ENCODINGS", "RANGE_RADIATION",
]

#: GNSS fix types, weakest first (GnssFixType of the spec).
FIX_TYPES = ("NO_FIX", "FIX_2D", "FIX_3D", "RTK_FLOAT", "RTK_FIXED")
#: What a rangefinder emits (sensor_msgs/Range's radiation_type).
RANGE_RADIATION = ("ultrasound", "infrared")
#: Image encodings and the numpy layout of their pixels: (dtype, channels).
IMAGE_ENCODINGS = {"mono8": (np.uint8, 1), "rgb8": (np.uint8, 3), "bgr8": (np.uint8, 3),
                   "depth16": (np.uint16, 1), "depth32f": (np.float32, 1)}


def _array(value, dtype, shape, name):
    """`value` as a C-contiguous array of `dtype` whose shape matches `shape` (None: any size)."""
    array = np.ascontiguousarray(value, dtype=dtype)
    if array.ndim != len(shape) or any(want is not None and want != got for want, got in zip(shape, array.shape)):
        wanted = " x ".join("N" if want is None else str(want) for want in shape)
        raise ValueError(f"{name}: expected an array of {wanted}, got shape {array.shape}")
    return array


def _optional_array(value, dtype, shape, name):
    return None if value is None else _array(value, dtype, shape, name)


def _per_point(value, dtype, count, name):
    if value is None:
        return None
    array = _array(value, dtype, (None,), name)
    if len(array) != count:
        raise ValueError(f"{name}: expected {count} values (one per point), got {len(array)}")
    return array


class _Stamped:
    timestamp_ns: int

    @property
    def time_s(self) -> float:
        """The timestamp in seconds since the epoch (float: about 0.2 us resolution today)."""
        return self.timestamp_ns * 1e-9


def _check_time(timestamp_ns):
    if isinstance(timestamp_ns, (bool, float)) or not isinstance(timestamp_ns, (int, np.integer)):
        raise ValueError(f"timestamp_ns: expected integer nanoseconds since the epoch, got {timestamp_ns!r}")
    return int(timestamp_ns)


@dataclass
class Imu(_Stamped):
    """Specific force (m/s^2) and turn rate (rad/s) in the IMU frame."""
    timestamp_ns: int
    linear_acceleration: np.ndarray
    angular_velocity: np.ndarray
    frame_id: str = ""
    acceleration_covariance: Optional[np.ndarray] = None   # 3 x 3, (m/s^2)^2
    gyroscope_covariance: Optional[np.ndarray] = None      # 3 x 3, (rad/s)^2
    orientation: Optional[np.ndarray] = None               # R_world_imu as (w, x, y, z), world ENU
    orientation_covariance: Optional[np.ndarray] = None    # 3 x 3 rad^2, with orientation only

    def __post_init__(self):
        self.timestamp_ns = _check_time(self.timestamp_ns)
        self.linear_acceleration = _array(self.linear_acceleration, np.float64, (3,), "linear_acceleration")
        self.angular_velocity = _array(self.angular_velocity, np.float64, (3,), "angular_velocity")
        self.acceleration_covariance = _optional_array(self.acceleration_covariance, np.float64, (3, 3), "acceleration_covariance")
        self.gyroscope_covariance = _optional_array(self.gyroscope_covariance, np.float64, (3, 3), "gyroscope_covariance")
        self.orientation = _optional_array(self.orientation, np.float64, (4,), "orientation")
        self.orientation_covariance = _optional_array(self.orientation_covariance, np.float64, (3, 3), "orientation_covariance")


@dataclass
class PointCloud(_Stamped):
    """A LiDAR sweep: N x 3 points (sensor frame, m) with optional per-point values."""
    timestamp_ns: int
    points: np.ndarray                                  # N x 3 float32
    frame_id: str = ""
    intensities: Optional[np.ndarray] = None            # N float32 in [0, 1]
    ring_ids: Optional[np.ndarray] = None               # N uint32
    point_timestamps_ns: Optional[np.ndarray] = None    # N int64, absolute (ns since the epoch)

    def __post_init__(self):
        self.timestamp_ns = _check_time(self.timestamp_ns)
        self.points = _array(self.points, np.float32, (None, 3), "points")
        count = len(self.points)
        self.intensities = _per_point(self.intensities, np.float32, count, "intensities")
        self.ring_ids = _per_point(self.ring_ids, np.uint32, count, "ring_ids")
        self.point_timestamps_ns = _per_point(self.point_timestamps_ns, np.int64, count, "point_timestamps_ns")

    @property
    def point_times_s(self) -> Optional[np.ndarray]:
        """Per-point times in seconds after `timestamp_ns` (None without per-point times)."""
        if self.point_timestamps_ns is None:
            return None
        return (self.point_timestamps_ns - self.timestamp_ns) * 1e-9


@dataclass
class CameraIntrinsics:
    """Pinhole intrinsics in pixels; width and height 0 when unknown."""
    fx: float
    fy: float
    cx: float
    cy: float
    width: int = 0
    height: int = 0


@dataclass
class Distortion:
    """'none', 'radtan' (k1, k2, p1, p2 [, k3]) or 'equidistant' (k1, k2, k3, k4)."""
    model: str = "none"
    coefficients: list = field(default_factory=list)


@dataclass
class Image(_Stamped):
    """Pixels as numpy: H x W (mono8 uint8, depth16 uint16 mm, depth32f float32 m) or H x W x 3 (rgb8, bgr8)."""
    timestamp_ns: int
    pixels: np.ndarray
    encoding: str = "mono8"
    frame_id: str = ""
    intrinsics: Optional[CameraIntrinsics] = None
    distortion: Optional[Distortion] = None

    def __post_init__(self):
        self.timestamp_ns = _check_time(self.timestamp_ns)
        if self.encoding not in IMAGE_ENCODINGS:
            raise ValueError(f"encoding: expected one of {', '.join(IMAGE_ENCODINGS)}, got '{self.encoding}'")
        dtype, channels = IMAGE_ENCODINGS[self.encoding]
        shape = (None, None) if channels == 1 else (None, None, channels)
        self.pixels = _array(self.pixels, dtype, shape, f"pixels ({self.encoding})")

    @property
    def width(self) -> int:
        return int(self.pixels.shape[1])

    @property
    def height(self) -> int:
        return int(self.pixels.shape[0])


@dataclass
class Gnss(_Stamped):
    """A WGS84 fix: degrees and metres above the ellipsoid; covariance 3 x 3 ENU m^2."""
    timestamp_ns: int
    latitude: float
    longitude: float
    altitude: float
    fix_type: str = "FIX_3D"
    position_covariance: Optional[np.ndarray] = None
    satellites_used: int = 0
    hdop: float = 0.0

    def __post_init__(self):
        self.timestamp_ns = _check_time(self.timestamp_ns)
        if self.fix_type not in FIX_TYPES:
            raise ValueError(f"fix_type: expected one of {', '.join(FIX_TYPES)}, got '{self.fix_type}'")
        self.position_covariance = _optional_array(self.position_covariance, np.float64, (3, 3), "position_covariance")


@dataclass
class WheelOdometry(_Stamped):
    """Cumulative left and right wheel distances (m) of a differential drive."""
    timestamp_ns: int
    left_distance: float
    right_distance: float
    wheel_separation: float
    wheel_radius: float = 0.0
    frame_id: str = ""


@dataclass
class Radar(_Stamped):
    """Radar targets: N x 5 float32 columns range (m), azimuth, elevation (rad), radial_velocity (m/s), rcs (dBsm)."""
    timestamp_ns: int
    targets: np.ndarray
    frame_id: str = ""

    def __post_init__(self):
        self.timestamp_ns = _check_time(self.timestamp_ns)
        self.targets = _array(np.reshape(self.targets, (-1, 5)) if np.size(self.targets) == 0 else self.targets,
                              np.float32, (None, 5), "targets")


@dataclass
class Range(_Stamped):
    """A single-beam rangefinder's reading (ultrasonic, infrared; sensor_msgs/Range): the distance (m) to the
    nearest object within a cone of full angle field_of_view (rad) about the sensor frame's +x axis; +inf nothing
    within max_range, -inf nearer than min_range."""
    timestamp_ns: int
    range: float
    min_range: float
    max_range: float
    field_of_view: float
    radiation: str = "ultrasound"
    variance: float = 0.0
    frame_id: str = ""

    def __post_init__(self):
        self.timestamp_ns = _check_time(self.timestamp_ns)
        if self.radiation not in RANGE_RADIATION:
            raise ValueError(f"radiation: expected one of {', '.join(RANGE_RADIATION)}, got '{self.radiation}'")


@dataclass
class Detection:
    """One object a detector found in a camera image (vision_msgs/Detection2D): its class, score in [0, 1], box
    (x_min, y_min, x_max, y_max) in pixels (integer coordinates at pixel centres), a tracker's id (-1: none) and an
    optional instance mask (uint8, rows x columns, non-zero on the object) stretched over the box."""
    class_name: str
    box: np.ndarray
    score: float = 1.0
    track_id: int = -1
    mask: Optional[np.ndarray] = None

    def __post_init__(self):
        self.box = _array(self.box, np.float32, (4,), "box")
        self.mask = _optional_array(self.mask, np.uint8, (None, None), "mask")


@dataclass
class Detections(_Stamped):
    """A vision pipeline's output for one camera image: pushed on the camera's sensor name with the image's timestamp
    and size, which is how the session matches it to that image (fusion.vision.dynamic_objects masks the moving ones
    out of the visual odometry). Optionally a dense segmentation: `segmentation` (uint8, image_height x image_width,
    a class id per pixel, 255 unlabelled) and its label table `segmentation_classes` (the name of each id)."""
    timestamp_ns: int
    image_width: int
    image_height: int
    detections: list = field(default_factory=list)
    frame_id: str = ""
    segmentation: Optional[np.ndarray] = None
    segmentation_classes: list = field(default_factory=list)

    def __post_init__(self):
        self.timestamp_ns = _check_time(self.timestamp_ns)
        self.segmentation = _optional_array(self.segmentation, np.uint8, (self.image_height, self.image_width), "segmentation")
        self.segmentation_classes = [str(name) for name in self.segmentation_classes]
        for index, detection in enumerate(self.detections):
            if not isinstance(detection, Detection):
                raise ValueError(f"detections[{index}]: expected a Detection, got {type(detection).__name__}")


@dataclass
class PoseEstimate(_Stamped):
    """A pose the engine emitted: T_world_body as position (m) and orientation (w, x, y, z)."""
    timestamp_ns: int
    position: np.ndarray
    orientation: np.ndarray
    velocity: np.ndarray
    covariance: Optional[np.ndarray] = None   # 6 x 6: position (world, m), orientation (body, rad)
    tracking_state: str = ""


Message = Union[Imu, PointCloud, Image, Gnss, WheelOdometry, Radar, Range, Detections]


@dataclass
class LogRecord:
    """One message of a sensor log: the topic it was written on and when."""
    topic: str
    log_time_ns: int
    message: Union[Message, PoseEstimate]
