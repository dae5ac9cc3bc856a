"""travmap: traversability maps from recorded drives, in Python.

The same library as the `travmap` command (which this package also installs):

    import travmap
    drive = travmap.open("sequences/00")            # any input the command reads
    for frame in drive:                              # frame.points: N x 4 float32
        ...
    for grid in travmap.run("drive.mcap", model="road"):
        grid.traversable, grid.probability, grid.features  # [row, col] NumPy arrays
    table = travmap.dataset(["sequences/00"])       # labelled cells, a pyarrow.Table
    scores = travmap.eval("sequences/00")           # `travmap eval --json`'s summary

Errors raise TravmapError with the command's message and exit code; a drive read to
its end with frames skipped or parts lost (where the command exits 3) warns with
TravmapWarning.
"""

from ._travmap import Drive, Frame, Frames, Grid, Grids, Model, TravmapError, TravmapWarning, open, run
from ._commands import binary, dataset, eval

try:
    from importlib.metadata import PackageNotFoundError, version as _version

    __version__ = _version("travmap")
except PackageNotFoundError:  # run from a source tree, not installed
    __version__ = "0+unknown"

__all__ = [
    "Drive",
    "Frame",
    "Frames",
    "Grid",
    "Grids",
    "Model",
    "TravmapError",
    "TravmapWarning",
    "__version__",
    "binary",
    "dataset",
    "eval",
    "open",
    "run",
]
