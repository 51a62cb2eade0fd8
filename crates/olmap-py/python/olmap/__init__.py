"""olmap: 3D mapping and localisation for one or many mobile robots.

Python bindings of the olmap Rust library (J. Ryde's thesis *Cooperative 3D Mapping and
Localisation of Multiple Mobile Robots*): sparse voxel maps of integer counts ("occupancy
lists"), global scan alignment with no initial guess and a trust verdict, map building,
multi-robot simulation and team mapping, beacon detection.

Conventions: metres, seconds; angles in degrees at the interface where the command line
uses degrees (``max_tilt``, ``window``'s yaw, bearings), radians for laser-scan beam
angles; right-handed frames, x forward, y left, z up; a pose ``T_a_b`` is a 4x4 float64
array mapping points of frame b into frame a (``p_a = R p_b + t``).

Arrays in: any (N, 3) array-like of numbers (float32 or float64, C- or Fortran-ordered,
strided views; ``np.asarray(open3d_cloud.points)``) is copied into Rust before the
computation, which runs with the GIL released (two Python threads use two cores).
Arrays out: new float64 numpy arrays.

Errors: ``ValueError`` for bad arguments, ``OSError`` subclasses for files
(``FileNotFoundError``, ``PermissionError``, ``olmap.FormatError`` for a file that is
not what it claims), ``olmap.TooLargeError`` (a ``ValueError``) beyond olmap's limits;
every message names the argument or the file at fault.

Example::

    import numpy as np, olmap
    source = olmap.read_cloud("scan001.3d", valid_3dtk=True)
    target = olmap.read_cloud("scan000.3d", valid_3dtk=True)
    res = olmap.align(source, target, resolution=0.1)
    if res.trusted:
        print(res.T_target_source)
    else:
        print("not trusted:", res.doubts)
"""

from ._olmap import (
    __version__,
    Alignment,
    FormatError,
    FreeSpaceMap,
    Localizer,
    MapBuild,
    OccupancyMap,
    PointCloud,
    SimDataset,
    TeamResult,
    TooLargeError,
    align,
    build_map,
    detect_beacons,
    localize,
    map_team,
    mutual_localisation,
    read_cloud,
    read_poses,
    simulate,
    write_cloud,
)

__all__ = [
    "__version__",
    "Alignment",
    "FormatError",
    "FreeSpaceMap",
    "Localizer",
    "MapBuild",
    "OccupancyMap",
    "PointCloud",
    "SimDataset",
    "TeamResult",
    "TooLargeError",
    "align",
    "build_map",
    "detect_beacons",
    "localize",
    "map_team",
    "mutual_localisation",
    "read_cloud",
    "read_poses",
    "simulate",
    "write_cloud",
]
