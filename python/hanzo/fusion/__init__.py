"""hanzo-fusion's Python API: factor graphs for sensor fusion and SLAM.

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
    geodetic_to_enu,
    key_to_string,
    read_carmen,
    read_g2o,
)
