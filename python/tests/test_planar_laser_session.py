"""A 2D laser scanner through hanzo.fusion.Session: a robot drives 20 m along a room with pillars,
its wheels read 3 % long, the laser's scan matching keeps the pose on the truth (the world is the
start pose)."""

import numpy as np

from hanzo.fusion import Session

CONFIG = """
fusion:
  frontend:
    planar: true
  sensors:
    lidar:
      type: planar_laser
      topic: /scan
      rate: 10
      body_frame: base_link
    wheels:
      topic: /wheels
      rate: 50
      body_frame: base_link
"""

# A 30 x 12 m room (walls as segments) with eight 0.3 m pillars; the robot starts at (0, 4).
WALLS = np.array([[-5, -2, 25, -2], [25, -2, 25, 10], [25, 10, -5, 10], [-5, 10, -5, -2]], dtype=float)
PILLARS = np.array([(x, y) for x in (2.0, 8.0, 14.0, 20.0) for y in (1.0, 7.5)])
START = np.array([0.0, 4.0])


def scan(position, beams=360, max_range=29.0):
    """Points (laser frame, heading along +x) of a 360-degree scan from `position`."""
    angles = np.linspace(-np.pi, np.pi, beams, endpoint=False)
    directions = np.column_stack([np.cos(angles), np.sin(angles)])
    ranges = np.full(beams, np.inf)
    for x1, y1, x2, y2 in WALLS:
        edge = np.array([x2 - x1, y2 - y1])
        offset = np.array([x1, y1]) - position
        det = -directions[:, 0] * edge[1] + directions[:, 1] * edge[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (-offset[0] * edge[1] + offset[1] * edge[0]) / det
            s = (directions[:, 0] * offset[1] - directions[:, 1] * offset[0]) / det
        hit = (np.abs(det) > 1e-9) & (t > 0) & (s >= 0) & (s <= 1)
        ranges = np.where(hit, np.minimum(ranges, t), ranges)
    for centre in PILLARS:
        f = position - centre
        b = directions @ f
        disc = b * b - (f @ f - 0.3**2)
        t = -b - np.sqrt(np.maximum(disc, 0.0))
        ranges = np.where((disc >= 0) & (t > 0), np.minimum(ranges, t), ranges)
    keep = ranges < max_range
    return np.column_stack([ranges[keep] * directions[keep, 0], ranges[keep] * directions[keep, 1], np.zeros(keep.sum())])


def test_laser_corrects_wheels_that_read_long(tmp_path):
    config = tmp_path / "fusion.yaml"
    config.write_text(CONFIG)
    session = Session(str(config))
    start = 1_700_000_000.0
    for k in range(1001):  # 20 s: wheels at 50 Hz, scans at 10 Hz; 1 m/s along x
        t = 0.02 * k
        driven = t
        assert session.push_wheels("wheels", start + t, 1.03 * driven, 1.03 * driven, 0.5) is None
        if k % 5 == 0:
            assert session.push_point_cloud("lidar", start + t, scan(START + np.array([driven, 0.0]))) is None
    session.flush()
    poses = session.poses()
    final = poses[-1]
    # The world is the start pose: the truth ends at (20, 0); the wheels alone would say 20.6.
    assert abs(final[1] - 20.0) < 0.1
    assert abs(final[2]) < 0.1
    summary = session.summary()
    assert summary["state"] in ("TRACKING", "DEGRADED")
    lidar = next(s for s in summary["sensors"] if s["name"] == "lidar")
    assert lidar["received"] == 201
    optimized = session.optimized_trajectory()
    assert abs(optimized[-1][1] - 20.0) < 0.1
    assert len(session.map_points()) > 100
