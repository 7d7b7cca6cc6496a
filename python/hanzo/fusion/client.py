"""A small client of the hanzo-fusion server's REST API (docs/server.md), standard library only.

    from hanzo.fusion.client import FusionClient
    client = FusionClient("http://localhost:8083", token="...")
    session = client.create_session(open("fusion.yaml").read(), open("calibration.yaml").read(), name="yard")
    # stream sensor data over gRPC (hanzo-fusion stream LOG --session ID, or the FusionService API)
    pose = client.pose(session["id"])
    poses = client.trajectory(session["id"])          # every stored pose, paged for you
    points = client.map_points(session["id"])         # N x 3 numpy array (world frame, m)
    client.loop_closure(session["id"], from_keyframe=4, to_keyframe=120)
    camera = client.calibrate_camera("camera_front", ["board_00.png", ...], inner_corners=(9, 6), square_size=0.05)

Every failure raises FusionError with the server's HTTP status, error code, message and field.
"""

import base64
import json
import ssl
import urllib.error
import urllib.parse
import urllib.request

import numpy as np


class FusionError(Exception):
    """An error answer of the server (or no answer: status 0)."""

    def __init__(self, status, code, message, field=""):
        super().__init__(f"HTTP {status} {code}: {message}" + (f" (field '{field}')" if field else ""))
        self.status = status
        self.code = code
        self.message = message
        self.field = field


def parse_pcd(data):
    """The x, y, z of a binary PCD (as GET /map?format=pcd answers) as an N x 3 float32 array."""
    marker = b"DATA binary\n"
    end = data.find(marker)
    if end < 0:
        raise ValueError("not a binary PCD")
    header = dict(line.split(" ", 1) for line in data[:end].decode("ascii").splitlines() if line and not line.startswith("#"))
    names = header["FIELDS"].split()
    sizes = [int(size) for size in header["SIZE"].split()]
    types = header["TYPE"].split()
    counts = [int(count) for count in header["COUNT"].split()]
    points = int(header["POINTS"])
    kinds = {("F", 4): "<f4", ("F", 8): "<f8", ("U", 1): "u1", ("U", 2): "<u2", ("U", 4): "<u4", ("I", 4): "<i4"}
    dtype = np.dtype([(name, kinds[(kind, size)], (count,)) if count > 1 else (name, kinds[(kind, size)])
                      for name, kind, size, count in zip(names, types, sizes, counts)])
    body = data[end + len(marker):]
    if len(body) < points * dtype.itemsize:
        raise ValueError(f"PCD: {points} points announced, {len(body) // dtype.itemsize} present")
    records = np.frombuffer(body, dtype=dtype, count=points)
    return np.stack([records["x"], records["y"], records["z"]], axis=1).astype(np.float32)


class FusionClient:
    """Sessions, poses, trajectories, maps and loop closures of one server."""

    def __init__(self, url="http://localhost:8083", token=None, timeout=60.0, ca_file=None):
        if not url.startswith(("http://", "https://")):
            raise ValueError(f"url '{url}': expected http://HOST:PORT or https://HOST:PORT")
        self.url = url.rstrip("/")
        self.token = token
        self.timeout = timeout
        self._ssl = ssl.create_default_context(cafile=ca_file) if url.startswith("https://") else None

    def _request(self, method, path, body=None, raw=False):
        headers = {"Authorization": f"Bearer {self.token}"} if self.token else {}
        data = None
        if isinstance(body, (bytes, bytearray)):
            data = bytes(body)
            headers["Content-Type"] = "application/octet-stream"
        elif body is not None:
            data = json.dumps(body).encode()
            headers["Content-Type"] = "application/json"
        request = urllib.request.Request(self.url + path, data=data, method=method, headers=headers)
        try:
            with urllib.request.urlopen(request, timeout=self.timeout, context=self._ssl) as response:
                payload = response.read()
                headers_out = response.headers
        except urllib.error.HTTPError as error:
            payload = error.read()
            try:
                answer = json.loads(payload)["error"]
                raise FusionError(error.code, answer.get("code", ""), answer.get("message", ""), answer.get("field", "")) from None
            except (ValueError, KeyError, TypeError):
                raise FusionError(error.code, "", payload.decode(errors="replace")) from None
        except urllib.error.URLError as error:
            raise FusionError(0, "unreachable", f"{self.url}: {error.reason}") from None
        if raw:
            return payload, headers_out
        return json.loads(payload) if payload else None

    # --- server ---
    def health(self):
        return self._request("GET", "/v1/health")

    # --- sessions ---
    def create_session(self, config, calibration=None, name="", record=None, privacy=None):
        """config / calibration: the YAML text of the files, or the same as dicts. record: record
        the raw sensor streams (None: the server's default); privacy: "blur", "black" or "off"
        for the recorded images (None: the server's default)."""
        body = {"name": name, "config": config}
        if calibration:
            body["calibration"] = calibration
        if record is not None:
            body["record"] = record
        if privacy is not None:
            body["privacy"] = privacy
        return self._request("POST", "/v1/sessions", body)

    def sessions(self):
        return self._request("GET", "/v1/sessions")["sessions"]

    def session(self, session_id):
        return self._request("GET", f"/v1/sessions/{_quote(session_id)}")

    def register_sensor(self, session_id, name, config, calibration=None):
        body = {"name": name, "config": config}
        if calibration:
            body["calibration"] = calibration
        return self._request("POST", f"/v1/sessions/{_quote(session_id)}/sensors", body)

    def end_session(self, session_id):
        return self._request("DELETE", f"/v1/sessions/{_quote(session_id)}")

    def recording(self, session_id):
        """The bytes of an ended session's recording (a sensor log; encrypted when the server
        encrypts recordings: decrypt with `hanzo-fusion crypto decrypt`)."""
        payload, _ = self._request("GET", f"/v1/sessions/{_quote(session_id)}/recording", raw=True)
        return payload

    # --- estimates ---
    def pose(self, session_id):
        return self._request("GET", f"/v1/sessions/{_quote(session_id)}/pose")

    def trajectory(self, session_id, after=None, page_size=10000):
        """Every stored pose with timestamp_ns > after, oldest first (fetched page by page)."""
        poses = []
        while True:
            query = {"limit": page_size}
            if after is not None:
                query["after"] = after
            page = self._request("GET", f"/v1/sessions/{_quote(session_id)}/trajectory?{urllib.parse.urlencode(query)}")
            poses.extend(page["poses"])
            after = page["next_after"]
            if after is None:
                return poses

    # --- maps ---
    def map(self, session_id, format="fmap"):
        """The session's map: bytes of the FusionMap file (fmap), PCD or PLY; a dict for json."""
        payload, _ = self._request("GET", f"/v1/sessions/{_quote(session_id)}/map?format={_quote(format)}", raw=True)
        return json.loads(payload) if format == "json" else payload

    def map_points(self, session_id):
        """The map's point layer as an N x 3 float32 array (world frame, m)."""
        return parse_pcd(self.map(session_id, "pcd"))

    def loop_closure(self, session_id, from_keyframe=None, to_keyframe=None, position=None, orientation_wxyz=None,
                     covariance=None):
        """A manual loop closure: none of the arguments searches at the newest map keyframe;
        from/to registers those keyframes' scans; with position (and orientation_wxyz) it is
        added as given; covariance: 6 x 6 over (rho, phi)."""
        body = {}
        if from_keyframe is not None:
            body["from_keyframe"] = int(from_keyframe)
        if to_keyframe is not None:
            body["to_keyframe"] = int(to_keyframe)
        if position is not None:
            body["relative_pose"] = {"position": [float(v) for v in position]}
            if orientation_wxyz is not None:
                body["relative_pose"]["orientation_wxyz"] = [float(v) for v in orientation_wxyz]
        if covariance is not None:
            body["covariance"] = [float(v) for v in np.asarray(covariance, dtype=float).reshape(36)]
        return self._request("POST", f"/v1/sessions/{_quote(session_id)}/loop-closure", body)

    # --- stored maps ---
    def maps(self):
        """Stored maps of the organization (sessions' maps and loaded ones), each with its versions."""
        return self._request("GET", "/v1/maps")["maps"]

    def load_map(self, fusion_map, name=""):
        """Stores a FusionMap file (bytes) as the next version of its map_id; returns
        {"map_id", "version", "parent_version", "bytes"}. Needs fusion:map:write."""
        query = f"?name={_quote(name)}" if name else ""
        return self._request("POST", f"/v1/maps{query}", bytes(fusion_map))

    def stored_map(self, map_id, version=None, format="fmap", at_ns=None):
        """A stored version (the latest when None; with at_ns the newest created at or before that
        time, ns since the epoch): FusionMap / PCD / PLY bytes; json: the versions."""
        query = {"format": format}
        if version is not None:
            query["version"] = int(version)
        if at_ns is not None:
            query["at_ns"] = int(at_ns)
        payload, _ = self._request("GET", f"/v1/maps/{_quote(map_id)}?{urllib.parse.urlencode(query)}", raw=True)
        return json.loads(payload) if format == "json" else payload

    def relocalize(self, session_id, map_id, version=None, position=None, orientation_wxyz=None, linear_window_m=None,
                   angular_window_rad=None, sensor=None, frames=None, min_agreeing_frames=None):
        """Localizes the session in a stored map and moves it into the map's frame. sensor:
        "lidar" (the newest sweeps in the map's points), "camera" (the newest left images in its
        visual landmarks; frames of them tried, min_agreeing_frames must agree) or None (the
        LiDAR when the session maps one). LiDAR: without position the whole map is searched;
        with it (the body's pose in the map) only the windows around it. Returns the outcome
        (sensor, T_map_world, and the sensor's numbers)."""
        body = {"map_id": map_id}
        if sensor is not None:
            body["sensor"] = str(sensor)
        if frames is not None:
            body["frames"] = int(frames)
        if min_agreeing_frames is not None:
            body["min_agreeing_frames"] = int(min_agreeing_frames)
        if version is not None:
            body["version"] = int(version)
        if position is not None:
            body["initial_pose"] = {"position": [float(v) for v in position]}
            if orientation_wxyz is not None:
                body["initial_pose"]["orientation_wxyz"] = [float(v) for v in orientation_wxyz]
        if linear_window_m is not None:
            body["linear_window_m"] = float(linear_window_m)
        if angular_window_rad is not None:
            body["angular_window_rad"] = float(angular_window_rad)
        return self._request("POST", f"/v1/sessions/{_quote(session_id)}/relocalize", body)

    # --- calibration ---
    def calibrate_camera(self, sensor, images, inner_corners, square_size, model="radtan", estimate_k3=False, timestamps_ns=None):
        """A camera's intrinsics and distortion from images of a checkerboard (POST /v1/calibrate,
        procedure camera_intrinsics). images: image files (paths, or bytes of PNG / JPEG / PGM
        ...), all the same size; inner_corners: (along a row, along a column), e.g. (9, 6);
        square_size in metres. Returns intrinsics, distortion_model, distortion_coeffs, rms_px and
        the views; nothing is stored."""
        encoded = []
        for index, image in enumerate(images):
            if not isinstance(image, (bytes, bytearray)):
                with open(image, "rb") as file:
                    image = file.read()
            entry = {"data": base64.b64encode(bytes(image)).decode("ascii")}
            if timestamps_ns is not None:
                entry["timestamp_ns"] = int(timestamps_ns[index])
            encoded.append(entry)
        body = {"procedure": "camera_intrinsics", "sensor": sensor, "model": model, "estimate_k3": bool(estimate_k3),
                "board": {"inner_corners_x": int(inner_corners[0]), "inner_corners_y": int(inner_corners[1]),
                          "square_size": float(square_size)},
                "images": encoded}
        return self._request("POST", "/v1/calibrate", body)


def _quote(text):
    return urllib.parse.quote(str(text), safe="")
