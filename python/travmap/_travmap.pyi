"""Type stubs of travmap's native module (crates/python)."""

import os
from typing import Iterator, Mapping, Optional, Sequence, Union

import numpy as np
import numpy.typing as npt
import sys

if sys.version_info >= (3, 11):
    from typing import TypedDict, Unpack
else:
    from typing_extensions import TypedDict, Unpack

FrameSelection = Union[None, int, range, str]
Texts = Union[str, Sequence[str]]

class Settings(TypedDict, total=False):
    """The keywords of `open` and `run`: the command line's flags by their long names;
    `images` decodes camera images (`open`: yes; `run`: when the model reads them)."""

    config: Union[str, os.PathLike]
    set: Union[Mapping[str, object], Texts]
    poses: str
    cloud_topic: Texts
    lidar_calibration: Texts
    lidar_frame: Texts
    world_frame: str
    camera_topic: str
    pose_topic: str
    rate: float
    keep_going: bool
    images: bool

class TravmapError(Exception):
    """What the command line reports as `error: ...`; `exit_code` 1 an error,
    2 a mistake in the arguments or settings, 3 completed with frames skipped."""

    exit_code: int

class TravmapWarning(UserWarning):
    """What the command says of a drive on stderr (a poor fit to the model, remission
    it could not use, unknown label ids), or that it was read to its end with frames
    skipped (keep_going=True) or parts lost, where the command exits 3."""

class Frame:
    """One LiDAR scan as read."""

    index: int
    stamp_ns: int
    points: npt.NDArray[np.float32]
    """N x 4: x, y, z (metres, sensor frame) and remission (0..1, or 0 when unusable)."""
    labels: Optional[npt.NDArray[np.uint32]]
    world_from_sensor: npt.NDArray[np.float64]
    """4 x 4: the sensor's pose in the drive's world frame."""
    image: Optional[npt.NDArray[np.uint8]]
    """H x W x 3 RGB camera image."""
    image_from_sensor: Optional[npt.NDArray[np.float64]]
    """3 x 4: homogeneous sensor coordinates to homogeneous pixels."""
    dropped_points: int
    remission: str
    sensors: list[str]

class Frames(Iterator[Frame]):
    def __iter__(self) -> "Frames": ...
    def __next__(self) -> Frame: ...

class Drive:
    """A drive opened by `travmap.open`: iterate it for its frames."""

    path: os.PathLike
    kind: str
    frames: list[int]
    notices: list[str]
    skipped: list[tuple[int, str]]
    lost: list[str]
    world_frame: str
    def __len__(self) -> int: ...
    def __iter__(self) -> Frames: ...

class Grid:
    """One frame's grid; arrays are [row, col], row 0 at min y, col 0 at min x."""

    index: int
    stamp_ns: int
    cell_size_m: float
    cells_per_side: int
    min_corner_in_world: tuple[float, float]
    occupancy: npt.NDArray[np.int8]
    """Occupancy after the filter, as `run --json`'s cells and nav2: 0 traversable, 100 not, -1 unknown."""
    traversable: npt.NDArray[np.int8]
    """After the filter: 1 traversable, 0 not, -1 unknown."""
    @property
    def cells(self) -> npt.NDArray[np.int8]:
        """occupancy, by the name it had first."""
    @property
    def classes(self) -> npt.NDArray[np.int8]:
        """traversable, by the name it had first."""
    predicted: npt.NDArray[np.int8]
    """Class before the filter."""
    decision: npt.NDArray[np.float32]
    """Margin (> 0 traversable), NaN where unpredictable."""
    probability: npt.NDArray[np.float32]
    """P(traversable) by the model's calibration, before the filter; NaN where unpredictable."""
    elevation: npt.NDArray[np.float32]
    """World z of the ground under the cell (its lowest point of the scan), m; NaN without points."""
    elevation_range: npt.NDArray[np.float32]
    """Highest minus lowest point of the cell over the window, m; NaN where unpredictable."""
    unsure: npt.NDArray[np.float32]
    """1 where |margin| < 1, 0 elsewhere, NaN where unpredictable."""
    predictable: npt.NDArray[np.bool_]
    features: npt.NDArray[np.float32]
    """[row, col, feature], named by feature_names."""
    feature_names: list[str]
    world_from_sensor: npt.NDArray[np.float64]
    timings: dict[str, float]
    dropped_points: int
    remission: str
    without_remission: bool
    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) in world metres, for imshow(extent=...)."""

class Grids(Iterator[Grid]):
    """The grids as they are computed: an iterator, each grid handed out once (a second
    loop over the same Grids is empty; list(...) keeps them, or run again)."""

    def __iter__(self) -> "Grids": ...
    def __next__(self) -> Grid: ...

class Model:
    """"road", "offroad" (compiled in) or a model file's path."""

    name: str
    support_vectors: int
    feature_names: list[str]
    uses_appearance: bool
    def __init__(self, model: Union[str, os.PathLike] = "road") -> None: ...
    def run(self, drive: Drive) -> Grids:
        """The grids of every frame of `drive`, in order, as they are computed."""

def open(
    path: Union[str, os.PathLike],
    frames: FrameSelection = None,
    **settings: Unpack[Settings],
) -> Drive:
    """Opens any input the `travmap` command reads."""

def run(
    path: Union[str, os.PathLike],
    model: Union[Model, str, None] = None,
    frames: FrameSelection = None,
    **settings: Unpack[Settings],
) -> Grids:
    """Each frame's grid, as `travmap run` computes it."""
