#!/usr/bin/python3
"""Writes the small sample data set in examples/data/ (deterministic; stdlib only).

A ground robot drives a circle of radius 10 m at 1 m/s for 20 s (yaw rate 0.1 rad/s),
starting at the ENU origin heading east, with its ENU origin at WGS84 37.0 N, 122.0 W, 10 m:
  imu.csv        100 Hz, body FLU, specific force (m/s^2) and angular rate (rad/s), with noise
  gnss.csv       5 Hz fixes (FIX_3D), 2 cm horizontal noise
  wheels.csv     50 Hz cumulative left/right wheel distances, separation 0.5 m
  ground_truth.tum  100 Hz true poses (TUM)
  estimate.tum      10 Hz estimate: 1 % scale error, 2 cm noise, expressed in a frame rotated
                    0.3 rad and shifted (needs SE(3)/Sim(3) alignment before APE)
Run: /usr/bin/python3 scripts/make_sample_data.py examples/data
"""
import math
import random
import sys

START_NS = 1_700_000_000_000_000_000
DURATION_S = 20.0
SPEED = 1.0
YAW_RATE = 0.1
RADIUS = SPEED / YAW_RATE
GRAVITY = 9.80665
LAT0, LON0, ALT0 = 37.0, -122.0, 10.0
WGS84_A = 6378137.0
WGS84_E2 = 6.69437999014e-3


def pose(t):
    yaw = YAW_RATE * t
    return RADIUS * math.sin(yaw), RADIUS * (1.0 - math.cos(yaw)), 0.0, yaw


def fmt(x):
    return repr(float(x))


def main(out):
    rng = random.Random(83)
    lat0 = math.radians(LAT0)
    meridian = WGS84_A * (1 - WGS84_E2) / (1 - WGS84_E2 * math.sin(lat0) ** 2) ** 1.5
    normal = WGS84_A / math.sqrt(1 - WGS84_E2 * math.sin(lat0) ** 2)

    with open(f"{out}/imu.csv", "w") as f:
        f.write("timestamp_ns,ax,ay,az,wx,wy,wz\n")
        for i in range(int(DURATION_S * 100) + 1):
            t_ns = START_NS + i * 10_000_000
            n = lambda s: rng.gauss(0.0, s)
            # Centripetal acceleration points left (+y body); the IMU senses gravity as +z.
            f.write(",".join([str(t_ns), fmt(n(0.02)), fmt(SPEED * YAW_RATE + n(0.02)), fmt(GRAVITY + n(0.02)),
                              fmt(n(0.001)), fmt(n(0.001)), fmt(YAW_RATE + n(0.001))]) + "\n")

    with open(f"{out}/gnss.csv", "w") as f:
        f.write("timestamp_ns,latitude,longitude,altitude,fix_type,satellites_used,hdop\n")
        for i in range(int(DURATION_S * 5) + 1):
            t = i * 0.2
            east, north, up, _ = pose(t)
            east += rng.gauss(0, 0.02)
            north += rng.gauss(0, 0.02)
            lat = LAT0 + math.degrees(north / meridian)
            lon = LON0 + math.degrees(east / (normal * math.cos(lat0)))
            f.write(",".join([str(START_NS + i * 200_000_000), f"{lat:.9f}", f"{lon:.9f}", f"{ALT0 + up:.3f}",
                              "FIX_3D", "12", "0.8"]) + "\n")

    separation = 0.5
    with open(f"{out}/wheels.csv", "w") as f:
        f.write("timestamp_ns,left_distance,right_distance,wheel_separation\n")
        for i in range(int(DURATION_S * 50) + 1):
            t = i * 0.02
            left = (SPEED - YAW_RATE * separation / 2) * t
            right = (SPEED + YAW_RATE * separation / 2) * t
            f.write(",".join([str(START_NS + i * 20_000_000), f"{left:.6f}", f"{right:.6f}", fmt(separation)]) + "\n")

    def tum_line(t_ns, x, y, z, yaw):
        qw, qz = math.cos(yaw / 2), math.sin(yaw / 2)
        return f"{t_ns // 1_000_000_000}.{t_ns % 1_000_000_000:09d} {x:.6f} {y:.6f} {z:.6f} 0 0 {qz:.9f} {qw:.9f}\n"

    with open(f"{out}/ground_truth.tum", "w") as f:
        f.write("# timestamp tx ty tz qx qy qz qw (ENU, body FLU)\n")
        for i in range(int(DURATION_S * 100) + 1):
            x, y, z, yaw = pose(i * 0.01)
            f.write(tum_line(START_NS + i * 10_000_000, x, y, z, yaw))

    with open(f"{out}/estimate.tum", "w") as f:
        f.write("# timestamp tx ty tz qx qy qz qw (odometry frame: rotated 0.3 rad, shifted)\n")
        frame_yaw, shift = 0.3, (5.0, -2.0, 0.5)
        c, s = math.cos(frame_yaw), math.sin(frame_yaw)
        for i in range(int(DURATION_S * 10) + 1):
            x, y, z, yaw = pose(i * 0.1)
            x, y = 1.01 * x + rng.gauss(0, 0.02), 1.01 * y + rng.gauss(0, 0.02)
            f.write(tum_line(START_NS + i * 100_000_000, c * x - s * y + shift[0], s * x + c * y + shift[1],
                             z + shift[2], yaw + frame_yaw + rng.gauss(0, 0.005)))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "examples/data")
