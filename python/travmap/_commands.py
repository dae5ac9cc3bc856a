"""The whole-drive commands, run by the `travmap` binary this package installs:
`dataset` and `eval` give what `travmap dataset` and `travmap eval --json` give,
because they are those commands."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sysconfig
import tempfile
import warnings
from pathlib import Path
from typing import Any, Iterable, Union

from ._travmap import TravmapError, TravmapWarning

Paths = Union[str, os.PathLike, Iterable[Union[str, os.PathLike]]]

# The keywords of `open` and `run` that are the command's flags, by flag; `set`
# is `--set` once per setting.
_FLAGS = {
    "config": "--config",
    "poses": "--poses",
    "cloud_topic": "--cloud-topic",
    "lidar_calibration": "--lidar-calibration",
    "lidar_frame": "--lidar-frame",
    "world_frame": "--world-frame",
    "camera_topic": "--camera-topic",
    "pose_topic": "--pose-topic",
    "rate": "--rate",
}


def _error(message: str, exit_code: int) -> TravmapError:
    error = TravmapError(message)
    error.exit_code = exit_code
    return error


def binary() -> str:
    """The `travmap` command this package installed (`TRAVMAP_BIN` overrides it)."""
    override = os.environ.get("TRAVMAP_BIN")
    if override:
        return override
    name = "travmap.exe" if os.name == "nt" else "travmap"
    schemes = [sysconfig.get_default_scheme()]
    user = f"{os.name}_user"
    if user in sysconfig.get_scheme_names():
        schemes.append(user)
    for scheme in schemes:
        candidate = Path(sysconfig.get_path("scripts", scheme)) / name
        if candidate.is_file():
            return str(candidate)
    found = shutil.which(name)
    if found:
        return found
    raise _error("the travmap command is not installed beside this package (pip install travmap)", 1)


def _arguments(paths: Paths, frames: Any, settings: dict) -> list[str]:
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    arguments = [os.fspath(p) for p in paths]
    if frames is not None:
        if isinstance(frames, bool) or not isinstance(frames, (int, str, range)):
            raise TypeError(
                f"frames={frames!r}: None, a frame number, a range, or text as on the command line (\"A..B\", \"A..=B\", \"A..\")"
            )
        if isinstance(frames, int) and frames < 0:
            raise _error(f"frames={frames}: frame numbers start at 0", 2)
        if isinstance(frames, range):
            if frames.step != 1:
                raise _error(f"frames={frames}: give a range of consecutive frames, step 1", 2)
            frames = f"{frames.start}..{frames.stop}"
        arguments += ["--frames", str(frames)]
    for key, value in settings.items():
        if value is None:
            continue
        if key == "set":
            items = value.items() if isinstance(value, dict) else [(s, None) for s in ([value] if isinstance(value, str) else value)]
            for name, setting in items:
                text = name if setting is None else f"{name}={str(setting).lower() if isinstance(setting, bool) else setting}"
                arguments += ["--set", text]
        elif key == "keep_going":
            arguments += ["--keep-going"] if value else []
        elif key in _FLAGS:
            for one in [value] if isinstance(value, (str, int, float, os.PathLike)) else value:
                arguments += [_FLAGS[key], os.fspath(one) if isinstance(one, os.PathLike) else str(one)]
        else:
            raise TypeError(f"unexpected keyword argument '{key}' (known: set, keep_going, {', '.join(_FLAGS)})")
    return arguments


def _model_flag(model: Any) -> list[str]:
    """`--model` of a model keyword: a name or a path."""
    if model is None:
        return []
    if not isinstance(model, (str, os.PathLike)):
        raise TypeError(f"model={model!r}: \"road\", \"offroad\" or a model file's path")
    return ["--model", os.fspath(model)]


def _command(arguments: list[str]) -> dict:
    """Runs travmap with `--json`; returns its summary, raises its error."""
    process = subprocess.run([binary(), *arguments, "--json", "--quiet"], capture_output=True, text=True)
    if process.returncode not in (0, 3):
        message, code = process.stderr.strip(), process.returncode
        try:
            error = json.loads(message.splitlines()[-1])
            message, code = error.get("error", message), error.get("exit_code", code)
        except (ValueError, IndexError, AttributeError):
            pass
        raise _error(message, code)
    lines = [json.loads(line) for line in process.stdout.splitlines() if line.strip()]
    summary = lines[-1] if lines else {}
    if process.returncode == 3:
        warnings.warn(
            f"travmap {arguments[0]} completed with frames skipped or lost: {process.stderr.strip()}",
            TravmapWarning,
            stacklevel=3,
        )
    return summary


def dataset(paths: Paths, output: str | os.PathLike | None = None, frames: Any = None, model: str | None = None, **settings):
    """Labelled cells of every frame as `travmap dataset` writes them: a
    `pyarrow.Table` (needs pyarrow). With `output`, the Parquet file (or, for a
    folder, its part files) is kept there; without, a temporary one is read and
    removed. Keywords are `travmap.open`'s."""
    import pyarrow.parquet as pq

    extra = _model_flag(model)
    with tempfile.TemporaryDirectory(prefix="travmap-dataset-") as scratch:
        target = os.fspath(output) if output is not None else os.path.join(scratch, "cells.parquet")
        _command(["dataset", *_arguments(paths, frames, settings), *extra, "-o", target])
        return pq.read_table(target)


def eval(paths: Paths, model: str | None = None, frames: Any = None, **settings) -> dict:
    """Scores the model on labelled drives: the summary `travmap eval --json`
    prints, as a dict (IoU per class, mIoU, timings). Keywords are `travmap.open`'s."""
    extra = _model_flag(model)
    return _command(["eval", *_arguments(paths, frames, settings), *extra])
