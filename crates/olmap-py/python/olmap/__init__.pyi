"""Type stubs of the olmap Python package (see ``help(olmap)``)."""

import os
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

PathLike = Union[str, "os.PathLike[str]"]
Progress = Optional[Callable[[str, int, int], Any]]  # progress(stage, done, total)
ArrayLike = npt.ArrayLike
Pose = npt.ArrayLike  # a 4x4 homogeneous transform
Points = Union["PointCloud", npt.ArrayLike]  # PointCloud or (N, 3) metres

class FormatError(OSError):
    """A file is not what its name or content claims."""

class TooLargeError(ValueError):
    """A request beyond a limit olmap enforces."""

class PointCloud:
    """A point cloud in its sensor frame (metres), immutable."""
    def __init__(
        self,
        points: npt.ArrayLike,
        intensity: Optional[npt.ArrayLike] = None,
        origin: Optional[npt.ArrayLike] = None,
    ) -> None: ...
    @property
    def points(self) -> npt.NDArray[np.float64]: ...
    @property
    def intensity(self) -> Optional[npt.NDArray[np.float32]]: ...
    @property
    def origin(self) -> npt.NDArray[np.float64]: ...
    @property
    def source(self) -> str: ...
    def transformed(self, pose: Pose) -> "PointCloud": ...
    def __len__(self) -> int: ...

class Alignment:
    """The result of align or localize."""
    @property
    def T_target_source(self) -> npt.NDArray[np.float64]: ...
    @property
    def trusted(self) -> bool: ...
    @property
    def doubts(self) -> List[str]: ...
    @property
    def significance(self) -> float: ...
    @property
    def overlap(self) -> int: ...
    @property
    def overlap_fraction(self) -> float: ...
    @property
    def ambiguity(self) -> int: ...
    @property
    def weakly_constrained(self) -> List[str]: ...
    @property
    def seconds(self) -> float: ...
    @property
    def report(self) -> Dict[str, Any]: ...

class FreeSpaceMap:
    """A 3D occupancy map with free space, at OctoMap's semantics."""
    UNKNOWN: int
    FREE: int
    OCCUPIED: int
    def __init__(
        self,
        resolution: float = 0.05,
        prob_hit: float = 0.7,
        prob_miss: float = 0.4,
        clamp_min: float = 0.1192,
        clamp_max: float = 0.971,
        occupancy_threshold: float = 0.5,
        max_range: Optional[float] = None,
    ) -> None: ...
    @property
    def resolution(self) -> float: ...
    def __len__(self) -> int: ...
    def insert_scan(
        self, points: Points, pose: Optional[Pose] = None, threads: int = 0
    ) -> Dict[str, int]: ...
    def states(self, points: npt.ArrayLike) -> npt.NDArray[np.uint8]: ...
    def probabilities(self, points: npt.ArrayLike) -> npt.NDArray[np.float64]: ...
    def voxels(self) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.uint8]]: ...
    def stats(self) -> Dict[str, int]: ...
    def save_bt(self, path: PathLike) -> None: ...

class OccupancyMap:
    """A sparse 3D occupancy map of integer counts."""
    def __init__(self, resolution: float = 0.05) -> None: ...
    @property
    def resolution(self) -> float: ...
    @property
    def source(self) -> str: ...
    def __len__(self) -> int: ...
    def insert_scan(
        self,
        points: Points,
        pose: Optional[Pose] = None,
        ray_trace: bool = True,
        max_range: float = 30.0,
        threads: int = 0,
    ) -> Dict[str, int]: ...
    def count_at(self, xyz: npt.ArrayLike) -> int: ...
    def counts(self, points: npt.ArrayLike) -> npt.NDArray[np.int64]: ...
    def voxels(self) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]: ...
    def cast_ray(
        self,
        origin: npt.ArrayLike,
        direction: npt.ArrayLike,
        max_range: float = 30.0,
        min_count: int = 1,
    ) -> Optional[Tuple[npt.NDArray[np.float64], float]]: ...
    def merge(self, other: "OccupancyMap") -> None: ...
    def threshold(self, min_count: int) -> "OccupancyMap": ...
    def save(self, path: PathLike) -> None: ...
    @staticmethod
    def load(path: PathLike) -> "OccupancyMap": ...

class MapBuild:
    """The result of build_map."""
    @property
    def poses(self) -> List[Optional[npt.NDArray[np.float64]]]: ...
    @property
    def names(self) -> List[str]: ...
    @property
    def map(self) -> OccupancyMap: ...
    @property
    def report(self) -> Dict[str, Any]: ...

class SimDataset:
    """A simulated multi-robot run with ground truth."""
    @property
    def robots(self) -> List[str]: ...
    @property
    def world(self) -> str: ...
    @property
    def seed(self) -> int: ...
    @property
    def sightings(self) -> int: ...
    def scans(self, robot: Union[int, str]) -> List[PointCloud]: ...
    def truth(self, robot: Union[int, str]) -> List[npt.NDArray[np.float64]]: ...
    def odometry(self, robot: Union[int, str]) -> List[npt.NDArray[np.float64]]: ...
    def write(self, path: PathLike) -> None: ...

class TeamResult:
    """The result of map_team."""
    @property
    def poses(self) -> Dict[str, npt.NDArray[np.float64]]: ...
    @property
    def map(self) -> OccupancyMap: ...
    @property
    def report(self) -> Dict[str, Any]: ...

def read_cloud(
    path: PathLike, format: Optional[str] = None, valid_3dtk: bool = False
) -> PointCloud: ...
def read_poses(path: PathLike) -> Dict[str, npt.NDArray[np.float64]]: ...
def write_cloud(
    path: PathLike,
    points: Points,
    format: Optional[str] = None,
    intensity: Optional[npt.ArrayLike] = None,
) -> None: ...
def align(
    source: Points,
    target: Points,
    resolution: float = 0.1,
    dof: str = "xyz-yaw",
    max_tilt: float = 15.0,
    guess: Optional[Pose] = None,
    window: Optional[Sequence[float]] = None,
    search: str = "multires",
    refine: bool = True,
    max_range: float = 30.0,
    threads: int = 0,
    levels: int = 0,
) -> Alignment: ...
def localize(
    scan: Points,
    map: OccupancyMap,
    dof: str = "xyz-yaw",
    max_tilt: float = 15.0,
    guess: Optional[Pose] = None,
    window: Optional[Sequence[float]] = None,
    search: str = "multires",
    refine: bool = True,
    max_range: float = 30.0,
    threads: int = 0,
    levels: int = 0,
    resolution: float = 0.1,
) -> Alignment: ...
class Localizer:
    """A map prepared once for localising many scans in it (see olmap.localize)."""
    def __init__(
        self,
        map: OccupancyMap,
        dof: str = "xyz-yaw",
        max_tilt: float = 15.0,
        search: str = "multires",
        refine: bool = True,
        max_range: float = 30.0,
        threads: int = 0,
        levels: int = 0,
        resolution: float = 0.1,
    ) -> None: ...
    def localize(
        self,
        scan: Points,
        guess: Optional[Pose] = None,
        window: Optional[Sequence[float]] = None,
        threads: int = 0,
    ) -> Alignment: ...
    def __len__(self) -> int: ...
    @property
    def resolution(self) -> float: ...
    @property
    def map_resolution(self) -> float: ...

def build_map(
    scans: Sequence[Points],
    odometry: Optional[Sequence[Pose]] = None,
    resolution: float = 0.1,
    mode: str = "batch",
    dof: str = "xyz-yaw",
    max_tilt: float = 15.0,
    max_range: float = 30.0,
    names: Optional[Sequence[str]] = None,
    first: int = 0,
    bucket_radius: float = 0.0,
    min_count: int = 1,
    register_band: Optional[Sequence[float]] = None,
    graph: bool = False,
    threads: int = 0,
    progress: Progress = None,
) -> MapBuild: ...
def simulate(
    world: str = "lab",
    robots: int = 4,
    scans_per_robot: int = 20,
    seed: int = 1,
    odometry: str = "typical",
    scanner: str = "mirror",
    range_noise: float = 0.02,
    beacon: str = "above",
    progress: Progress = None,
) -> SimDataset: ...
def map_team(
    dataset: Union[SimDataset, PathLike],
    solo: bool = False,
    clearing: bool = True,
    graph: bool = False,
    out: Optional[PathLike] = None,
    threads: int = 0,
    progress: Progress = None,
) -> TeamResult: ...
def detect_beacons(
    ranges: npt.ArrayLike,
    angles: npt.ArrayLike,
    radius: float = 0.125,
    method: str = "lsq",
    intensities: Optional[npt.ArrayLike] = None,
    max_rms: Optional[float] = None,
    intensity_threshold: float = 1.0,
) -> List[Dict[str, Any]]: ...
def mutual_localisation(
    a: float,
    alpha: float,
    b: float,
    beta: float,
    offset: float = 0.07,
    max_mismatch: float = 0.02,
    range_error: float = 0.02,
    beacon_width: float = 0.1,
) -> Dict[str, float]: ...
