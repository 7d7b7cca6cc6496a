"""gRPC client of a hanzo-fusion server's FusionService (proto/hanzo/fusion/v1/service.proto):
sensor messages of hanzo.fusion.messages streamed into a session, poses streamed back.

Needs grpcio and protobuf (Debian: python3-grpcio, python3-protobuf); the generated stubs ship in
the package (hanzo.fusion.v1). Sessions are made over REST (hanzo.fusion.client.FusionClient).

    from hanzo.fusion.streaming import SensorStreams
    with SensorStreams("localhost:8084", session_id, token="...") as streams:
        streams.send("imu", Imu(timestamp_ns, acceleration, turn_rate))   # one stream per sensor, opened on first use
        streams.send_log("sensors.mcap", {"/sensors/lidar": "lidar"}, rate=1.0)   # a log's topics, paced
    print(len(streams.poses), "poses came back")         # PoseEstimate dataclasses

A failed stream (unknown session, missing or wrong token, a message the server refuses) raises
StreamError from send() or close() with the gRPC status and the server's message.
"""

from __future__ import annotations

import collections
import queue
import threading
import time
from typing import Dict, Iterator, List, Optional

import grpc  # type: ignore[import]
import numpy as np

from hanzo.fusion import messages
from hanzo.fusion.log import read_log
from hanzo.fusion.v1 import estimates_pb2, sensors_pb2, service_pb2, service_pb2_grpc

__all__ = ["SensorStreams", "StreamError", "subscribe_poses", "to_proto", "pose_from_proto"]


class StreamError(Exception):
    """A gRPC stream ended with an error: `code` (grpc.StatusCode) and the server's `details`."""

    def __init__(self, sensor: str, code, details: str):
        super().__init__(f"{sensor}: {code.name if code else 'UNKNOWN'}: {details}")
        self.sensor = sensor
        self.code = code
        self.details = details


def _matrix(target, matrix):
    if matrix is not None:
        target.data.extend(float(v) for v in matrix.reshape(-1))


def _packed_field(number: int, payload: bytes) -> bytes:
    """A packed repeated field (wire type 2) of fixed-width little-endian values, as protobuf encodes it."""
    header, length = bytearray([(number << 3) | 2]), len(payload)
    while True:
        byte, length = length & 0x7F, length >> 7
        header.append(byte | (0x80 if length else 0))
        if not length:
            return bytes(header) + payload


def to_proto(message: messages.Message):
    """The hanzo.fusion.v1 protobuf message of a hanzo.fusion.messages dataclass."""
    if isinstance(message, messages.Imu):
        out = sensors_pb2.ImuMessage(timestamp_ns=message.timestamp_ns, frame_id=message.frame_id)
        out.linear_acceleration.x, out.linear_acceleration.y, out.linear_acceleration.z = map(float, message.linear_acceleration)
        out.angular_velocity.x, out.angular_velocity.y, out.angular_velocity.z = map(float, message.angular_velocity)
        _matrix(out.acceleration_covariance, message.acceleration_covariance)
        _matrix(out.gyroscope_covariance, message.gyroscope_covariance)
        if message.orientation is not None:
            out.orientation.w, out.orientation.x, out.orientation.y, out.orientation.z = map(float, message.orientation)
            _matrix(out.orientation_covariance, message.orientation_covariance)
        return out
    if isinstance(message, messages.PointCloud):
        out = sensors_pb2.PointCloudMessage(timestamp_ns=message.timestamp_ns, frame_id=message.frame_id)
        # Arrays go in as their packed encodings (fields 7, 4 and 8 of PointCloudMessage): a
        # 100k-point sweep in a millisecond instead of a Python float at a time.
        encoded = _packed_field(7, message.points.astype("<f4").tobytes())
        if message.intensities is not None:
            encoded += _packed_field(4, message.intensities.astype("<f4").tobytes())
        if message.point_timestamps_ns is not None:
            encoded += _packed_field(8, (message.point_timestamps_ns - message.timestamp_ns).astype("<i4").tobytes())
        out.MergeFromString(encoded)
        if message.ring_ids is not None:
            out.ring_ids.extend(message.ring_ids.tolist())
        return out
    if isinstance(message, messages.Image):
        out = sensors_pb2.ImageMessage(timestamp_ns=message.timestamp_ns, frame_id=message.frame_id, width=message.width,
                                       height=message.height, encoding=message.encoding, data=message.pixels.tobytes())
        if message.intrinsics is not None:
            i = message.intrinsics
            out.intrinsics.CopyFrom(sensors_pb2.CameraIntrinsics(fx=i.fx, fy=i.fy, cx=i.cx, cy=i.cy, width=i.width, height=i.height))
        if message.distortion is not None:
            model = "MODEL_" + message.distortion.model.upper()
            out.distortion.CopyFrom(sensors_pb2.DistortionModel(model=model, coefficients=message.distortion.coefficients))
        return out
    if isinstance(message, messages.Gnss):
        out = sensors_pb2.GnssMessage(timestamp_ns=message.timestamp_ns, latitude=message.latitude, longitude=message.longitude,
                                      altitude=message.altitude, fix_type=sensors_pb2.GnssFixType.Value(message.fix_type),
                                      satellites_used=message.satellites_used, hdop=message.hdop)
        _matrix(out.position_covariance, message.position_covariance)
        return out
    if isinstance(message, messages.WheelOdometry):
        return sensors_pb2.WheelOdometryMessage(timestamp_ns=message.timestamp_ns, frame_id=message.frame_id,
                                                left_distance=message.left_distance, right_distance=message.right_distance,
                                                wheel_separation=message.wheel_separation, wheel_radius=message.wheel_radius)
    if isinstance(message, messages.Radar):
        out = sensors_pb2.RadarMessage(timestamp_ns=message.timestamp_ns, frame_id=message.frame_id)
        for target in message.targets:
            out.targets.add(range=target[0], azimuth=target[1], elevation=target[2], radial_velocity=target[3], rcs=target[4])
        return out
    if isinstance(message, messages.Range):
        return sensors_pb2.RangeMessage(timestamp_ns=message.timestamp_ns, frame_id=message.frame_id,
                                        radiation_type=messages.RANGE_RADIATION.index(message.radiation),
                                        field_of_view=message.field_of_view, min_range=message.min_range,
                                        max_range=message.max_range, range=message.range, variance=message.variance)
    if isinstance(message, messages.Detections):
        out = sensors_pb2.DetectionsMessage(timestamp_ns=message.timestamp_ns, frame_id=message.frame_id,
                                            image_width=message.image_width, image_height=message.image_height)
        for detection in message.detections:
            box = [float(v) for v in detection.box]
            item = out.detections.add(class_name=detection.class_name, score=detection.score, x_min=box[0], y_min=box[1],
                                      x_max=box[2], y_max=box[3], track_id=detection.track_id)
            if detection.mask is not None:
                item.mask_height, item.mask_width = detection.mask.shape
                item.mask = detection.mask.tobytes()
        if message.segmentation is not None:
            out.segmentation = message.segmentation.tobytes()
            out.segmentation_classes.extend(message.segmentation_classes)
        return out
    raise TypeError(f"expected a sensor message of hanzo.fusion.messages, got {type(message).__name__}")


def pose_from_proto(pose: estimates_pb2.PoseEstimate) -> messages.PoseEstimate:
    """A PoseEstimate dataclass from the server's protobuf message."""
    covariance = None
    if len(pose.pose_covariance.data) == 36:
        covariance = np.array(pose.pose_covariance.data).reshape(6, 6)
    return messages.PoseEstimate(
        timestamp_ns=pose.timestamp_ns,
        position=np.array([pose.position.x, pose.position.y, pose.position.z]),
        orientation=np.array([pose.orientation.w, pose.orientation.x, pose.orientation.y, pose.orientation.z]),
        velocity=np.array([pose.velocity.x, pose.velocity.y, pose.velocity.z]),
        covariance=covariance,
        tracking_state=estimates_pb2.TrackingState.Name(pose.status.state),
    )


_METHODS = {
    messages.Imu: "StreamImu", messages.PointCloud: "StreamPointCloud", messages.Image: "StreamImage",
    messages.Gnss: "StreamGnss", messages.WheelOdometry: "StreamWheelOdometry", messages.Radar: "StreamRadar",
    messages.Range: "StreamRange", messages.Detections: "StreamDetections",
}
_END = object()


class _SensorStream:
    """One bidirectional stream: a thread reads the poses the server sends back."""

    def __init__(self, stub, method: str, sensor: str, metadata, poses: List[messages.PoseEstimate], lock: threading.Lock):
        self.sensor = sensor
        self.error: Optional[StreamError] = None
        self._queue: "queue.Queue" = queue.Queue(maxsize=16)
        self._responses = getattr(stub, method)(self._requests(), metadata=metadata + [("x-sensor", sensor)])
        self._reader = threading.Thread(target=self._read, args=(poses, lock), daemon=True)
        self._reader.start()

    def _requests(self):
        while True:
            item = self._queue.get()
            if item is _END:
                return
            yield item

    def _read(self, poses, lock):
        try:
            for pose in self._responses:
                with lock:
                    poses.append(pose_from_proto(pose))
        except grpc.RpcError as error:
            self.error = StreamError(self.sensor, error.code(), error.details())
            self._drain()

    def _drain(self):
        try:
            while True:
                self._queue.get_nowait()
        except queue.Empty:
            pass

    def put(self, request):
        while self.error is None:
            try:
                self._queue.put(request, timeout=0.1)
                return
            except queue.Full:
                continue
        raise self.error

    def finish(self, timeout: float):
        if self.error is None:
            try:
                self._queue.put(_END, timeout=timeout)
            except queue.Full:
                pass
        self._reader.join(timeout)
        if self.error is not None:
            raise self.error


# Statuses after which a stream is reopened: the server or its replica went away, a proxy reset
# the stream, or the session moved to another replica.
_TRANSIENT = {grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.UNKNOWN, grpc.StatusCode.INTERNAL, grpc.StatusCode.CANCELLED,
              grpc.StatusCode.ABORTED}


class SensorStreams:
    """Streams of one session, one per sensor, each opened on its sensor's first message.

    address: "host:port" of the server's gRPC port (8084 by default); token: a bearer token when
    the server checks them; root_certificates: PEM bytes for a TLS server (None: plaintext).
    `poses` collects the PoseEstimate dataclasses the server sends back (every stream's).
    A stream the server ends with a transient status (UNAVAILABLE: its replica died or the session
    moved to another replica) is reopened with backoff (0.1 s doubling to 2 s) for up to
    `reconnect_timeout` s without a pose coming back (0: never), and its messages of the last
    `replay` s are sent again; `reconnects` counts the reopened streams.
    """

    def __init__(self, address: str, session_id: str, token: Optional[str] = None, root_certificates: Optional[bytes] = None,
                 reconnect_timeout: float = 30.0, replay: float = 1.0):
        if root_certificates is None:
            self._channel = grpc.insecure_channel(address)
        else:
            self._channel = grpc.secure_channel(address, grpc.ssl_channel_credentials(root_certificates))
        self._stub = service_pb2_grpc.FusionServiceStub(self._channel)
        self._metadata = [("x-session-id", session_id)]
        if token:
            self._metadata.append(("authorization", f"Bearer {token}"))
        self._streams: Dict[str, _SensorStream] = {}
        self._lock = threading.Lock()
        self.poses: List[messages.PoseEstimate] = []
        self.reconnects = 0
        self._reconnect_timeout = reconnect_timeout
        self._replay_ns = int(replay * 1e9)
        self._recent: Dict[str, collections.deque] = {}  # sensor -> (timestamp_ns, request) of the last `replay` s
        self._failing_since: Optional[float] = None
        self._poses_when_failing = 0

    def send(self, sensor: str, message: messages.Message) -> None:
        """Queues `message` on `sensor`'s stream (the sensor name of the session's configuration)."""
        request = to_proto(message)
        method = _METHODS[type(message)]
        if self._reconnect_timeout > 0:
            recent = self._recent.setdefault(sensor, collections.deque())
            recent.append((message.timestamp_ns, request))
            while len(recent) > 1 and message.timestamp_ns - recent[0][0] > self._replay_ns:
                recent.popleft()
        stream = self._streams.get(sensor)
        if stream is None:
            stream = _SensorStream(self._stub, method, sensor, self._metadata, self.poses, self._lock)
            self._streams[sensor] = stream
        try:
            stream.put(request)
        except StreamError as error:
            del self._streams[sensor]
            if self._reconnect_timeout <= 0 or error.code not in _TRANSIENT:
                raise
            self._reconnect(sensor, method, error)

    def _reconnect(self, sensor: str, method: str, error: StreamError) -> None:
        """Reopens `sensor`'s stream with backoff and sends its recent messages again."""
        with self._lock:
            poses = len(self.poses)
        if self._failing_since is not None and poses > self._poses_when_failing:
            self._failing_since = None  # the last reconnect worked: poses came back since
        if self._failing_since is None:
            self._failing_since, self._poses_when_failing = time.monotonic(), poses
        backoff = 0.1
        while error.code in _TRANSIENT and time.monotonic() + backoff < self._failing_since + self._reconnect_timeout:
            time.sleep(backoff)
            backoff = min(2.0, backoff * 2)
            stream = _SensorStream(self._stub, method, sensor, self._metadata, self.poses, self._lock)
            try:
                for _, request in self._recent[sensor]:
                    stream.put(request)
            except StreamError as again:
                error = again
                continue
            self._streams[sensor] = stream
            self.reconnects += 1
            return
        raise error

    def send_log(self, path: str, sensors: Dict[str, str], rate: Optional[float] = 1.0) -> Dict[str, int]:
        """Sends every message of a sensor log whose topic `sensors` maps to a sensor name, in
        log-time order, paced at `rate` times real time (None: as fast as the streams take them).
        Returns the messages sent per sensor; topics not in `sensors` are left out."""
        if rate is not None and not rate > 0:
            raise ValueError(f"rate: expected a positive number or None, got {rate}")
        sent: Dict[str, int] = {}
        start_wall, start_log = time.monotonic(), None
        for record in read_log(path):
            sensor = sensors.get(record.topic)
            if sensor is None or isinstance(record.message, messages.PoseEstimate):
                continue
            if rate is not None:
                start_log = record.log_time_ns if start_log is None else start_log
                wait = (record.log_time_ns - start_log) * 1e-9 / rate - (time.monotonic() - start_wall)
                if wait > 0:
                    time.sleep(wait)
            self.send(sensor, record.message)
            sent[sensor] = sent.get(sensor, 0) + 1
        return sent

    def close(self, timeout: float = 60.0) -> None:
        """Ends every stream and waits until the server has answered them; raises the first StreamError."""
        errors = []
        for stream in self._streams.values():
            try:
                stream.finish(timeout)
            except StreamError as error:
                errors.append(error)
        self._streams.clear()
        self._channel.close()
        if errors:
            raise errors[0]

    def __enter__(self) -> "SensorStreams":
        return self

    def __exit__(self, exc_type, *rest) -> None:
        if exc_type is None:
            self.close()
        else:
            self._channel.close()


def subscribe_poses(address: str, session_id: str, token: Optional[str] = None,
                    root_certificates: Optional[bytes] = None) -> Iterator[messages.PoseEstimate]:
    """Every pose the session emits from now on (SubscribePose); the iteration ends when the
    session ends (the server then closes the stream with FAILED_PRECONDITION). Any other refusal
    (unknown session, token) raises StreamError."""
    channel = grpc.insecure_channel(address) if root_certificates is None else grpc.secure_channel(
        address, grpc.ssl_channel_credentials(root_certificates))
    metadata = [("authorization", f"Bearer {token}")] if token else []
    try:
        for pose in service_pb2_grpc.FusionServiceStub(channel).SubscribePose(service_pb2.SessionId(id=session_id), metadata=metadata):
            yield pose_from_proto(pose)
    except grpc.RpcError as error:
        if error.code() != grpc.StatusCode.FAILED_PRECONDITION:
            raise StreamError("SubscribePose", error.code(), error.details()) from None
    finally:
        channel.close()

