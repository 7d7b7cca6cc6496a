"""hanzo-fusion's Python API: the whole sensor-fusion pipeline (Session), sensor logs, trajectory
evaluation, factor graphs, LiDAR odometry and 2D laser SLAM; clients of the server in
hanzo.fusion.client (REST) and hanzo.fusion.streaming (gRPC). docs/python.md.

    from hanzo.fusion import Session, read_log, replay, ape
    from hanzo.fusion import FactorGraph, Pose3, Point3, X
"""

from hanzo.fusion._fusion import (  # noqa: F401
    B,
    CarmenLog,
    FactorGraph,
    ImuPreintegration,
    IncrementalSmoother,
    L,
    LidarOdometry,
    LidarOdometryEstimate,
    ObjectStore,
    OptimizeResult,
    PinholeCamera,
    PlanarLaserSlam,
    PlanarScanEstimate,
    Session,
    Point3,
    Pose2,
    Pose3,
    V,
    X,
    ape,
    geodetic_to_enu,
    merge_maps,
    key_to_string,
    read_carmen,
    read_g2o,
    read_trajectory,
    rpe,
    write_trajectory,
)
from hanzo.fusion._fusion import __version__  # noqa: F401
from hanzo.fusion.log import LogWriter, read_log, replay  # noqa: F401
from hanzo.fusion.messages import (  # noqa: F401
    CameraIntrinsics,
    Detection,
    Detections,
    Distortion,
    Gnss,
    Image,
    Imu,
    LogRecord,
    PointCloud,
    PoseEstimate,
    Radar,
    Range,
    WheelOdometry,
)
