"""The `travmap` module as a user installs it (the wheel, in a fresh virtual
environment): frames point for point as `convert` writes them, grids cell for cell
as `travmap run --json` prints them, errors as the command reports them. Needs the
shared data beside the repository; tests/python.rs runs it in CI."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import travmap

REPO = Path(__file__).resolve().parents[2]
SHARED = REPO / ".." / "shared" / "data"
SAMPLE = SHARED / "semantickitti-00" / "sequences" / "00"
# Three kinds of input: a KITTI sequence, a rosbag2 log of Velodyne packets, and an
# Ouster capture (pcap) with its metadata beside it.
PACKET_LOG = REPO / "fixtures" / "nebula" / "vlp32" / "1713492677464078412"
CAPTURE = REPO / "fixtures" / "ouster-sdk" / "OS-1-128_767798045_1024x10_20230712_120049.pcap"

needs_sample = pytest.mark.skipif(not SAMPLE.is_dir(), reason="../shared/data missing")


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([travmap.binary(), *map(str, args)], capture_output=True, text=True)


def json_lines(process: subprocess.CompletedProcess) -> list:
    assert process.returncode == 0, process.stderr
    return [json.loads(line) for line in process.stdout.splitlines()]


@pytest.fixture(scope="module")
def converted(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("converted") / "drive.mcap"
    cli("convert", SAMPLE, "-o", path, "-q").check_returncode()
    return path


@needs_sample
def test_the_command_is_on_path_beside_the_module():
    assert shutil.which("travmap") is not None
    assert Path(shutil.which("travmap")).samefile(travmap.binary())
    scores = subprocess.run(["travmap", "eval", str(SAMPLE), "--json"], capture_output=True, text=True)
    assert scores.returncode == 0, scores.stderr
    assert json.loads(scores.stdout.splitlines()[-1])["scored_frames"] == 3


@needs_sample
def test_frames_are_the_scans_with_their_labels_and_poses():
    drive = travmap.open(SAMPLE)
    assert len(drive) == 6 and drive.frames == list(range(6)) and drive.kind == "kitti"
    frames = list(drive)
    assert [f.index for f in frames] == list(range(6))
    first = frames[0]
    raw = np.fromfile(SAMPLE / "velodyne" / "000000.bin", dtype=np.float32).reshape(-1, 4)
    assert first.points.dtype == np.float32 and first.points.flags["C_CONTIGUOUS"]
    # The array wraps the reader's own buffer: NumPy allocated none and copied nothing.
    assert not first.points.flags["OWNDATA"] and first.points.base is not None
    np.testing.assert_array_equal(first.points, raw)
    labels = np.fromfile(SAMPLE / "labels" / "000000.label", dtype=np.uint32)
    np.testing.assert_array_equal(first.labels, labels)
    assert frames[5].labels is None  # three of the six scans are labelled
    poses = np.loadtxt(SAMPLE / "poses.txt").reshape(-1, 3, 4)
    # KITTI's poses are the left camera's; the sensor's is that times Tr.
    assert first.world_from_sensor.shape == (4, 4)
    np.testing.assert_allclose(first.world_from_sensor[3], [0, 0, 0, 1])
    assert len(poses) >= 6
    assert frames[1].stamp_ns > first.stamp_ns


@needs_sample
def test_frames_are_what_convert_writes_point_for_point(converted):
    from_sequence = list(travmap.open(SAMPLE))
    from_log = list(travmap.open(converted))
    assert len(from_log) == len(from_sequence)
    for a, b in zip(from_sequence, from_log):
        np.testing.assert_array_equal(a.points, b.points)
        np.testing.assert_array_equal(a.labels if a.labels is not None else [], b.labels if b.labels is not None else [])
        np.testing.assert_allclose(a.world_from_sensor, b.world_from_sensor, atol=1e-9)
    # And as another reader decodes the MCAP: each PointCloud2's x, y, z.
    reader = pytest.importorskip("mcap_ros2.reader")
    clouds = [
        m.ros_msg
        for m in reader.read_ros2_messages(str(converted))
        if m.schema.name == "sensor_msgs/msg/PointCloud2"
    ]
    assert len(clouds) == len(from_log)
    for cloud, frame in zip(clouds, from_log):
        offsets = {field.name: field.offset for field in cloud.fields}
        data = np.frombuffer(bytes(cloud.data), dtype=np.uint8).reshape(-1, cloud.point_step)
        xyz = np.stack([data[:, offsets[k] : offsets[k] + 4].copy().view(np.float32)[:, 0] for k in "xyz"], axis=1)
        np.testing.assert_array_equal(xyz, frame.points[:, :3])


def run_json_frames(path: Path, *flags: str) -> list:
    return [r for r in json_lines(cli("run", path, "--json", *flags)) if "cells" in r]


@pytest.mark.parametrize("path", [SAMPLE, PACKET_LOG, CAPTURE], ids=["kitti", "rosbag2-packets", "pcap"])
def test_grids_are_run_json_cell_for_cell(path):
    if not path.exists():
        pytest.skip(f"{path} missing")
    printed = run_json_frames(path)
    grids = list(travmap.run(path))
    assert len(grids) == len(printed) > 0
    for grid, frame in zip(grids, printed):
        assert (grid.index, grid.stamp_ns) == (frame["frame"], frame["stamp_ns"])
        assert (grid.cell_size_m, grid.cells_per_side) == (frame["cell_size_m"], frame["cells_per_side"])
        assert list(grid.min_corner_in_world) == frame["min_corner_in_world"]
        assert grid.occupancy.dtype == np.int8 and grid.occupancy.shape == (grid.cells_per_side,) * 2
        assert grid.occupancy.ravel().tolist() == frame["cells"]
        # The names the arrays had first are the same arrays.
        assert (grid.cells == grid.occupancy).all() and (grid.classes == grid.traversable).all()
        # The other arrays agree with the occupancy they filtered into.
        traversable = grid.occupancy == 0
        assert ((grid.traversable == 1) == traversable).all()
        assert not grid.predictable[grid.cells == -1].any() or (grid.cells != -1).any()
        assert grid.features.shape == (grid.cells_per_side, grid.cells_per_side, len(grid.feature_names))
        assert np.isnan(grid.decision[~grid.predictable]).all()
        # The layers a planner reads: P rises with the margin, unsure where it is small.
        p, d = grid.probability[grid.predictable], grid.decision[grid.predictable]
        assert (np.diff(p[np.argsort(d)]) >= -1e-6).all() and (0 <= p).all() and (p <= 1).all()
        assert (grid.unsure[grid.predictable] == (np.abs(d) < 1)).all()
        assert np.nanmin(grid.elevation_range) >= 0 and np.isfinite(grid.elevation).any()
        assert grid.remission == frame["remission"] and grid.without_remission == frame["without_remission"]
        assert set(grid.timings) == set(frame["timings"])


@needs_sample
def test_a_model_runs_over_an_opened_drive_and_names_its_features():
    model = travmap.Model("offroad")
    assert model.name == "embedded offroad model" and model.support_vectors > 0
    grids = list(model.run(travmap.open(SAMPLE, frames="2..4", images=False)))
    assert [g.index for g in grids] == [2, 3]
    printed = run_json_frames(SAMPLE, "--model", "offroad", "--frames", "2..4")
    assert [g.cells.ravel().tolist() for g in grids] == [f["cells"] for f in printed]
    x_min, x_max, y_min, y_max = grids[0].extent
    assert x_max - x_min == pytest.approx(grids[0].cell_size_m * grids[0].cells_per_side)


@needs_sample
def test_settings_and_frames_are_the_command_lines():
    grids = list(travmap.run(SAMPLE, frames=range(1, 3), set={"grid.size_m": 24}))
    printed = run_json_frames(SAMPLE, "--frames", "1..3", "--set", "grid.size_m=24")
    assert [g.cells.ravel().tolist() for g in grids] == [f["cells"] for f in printed]
    assert grids[0].cells_per_side == 60
    assert [f.index for f in travmap.open(SAMPLE, frames=4)] == [4]
    assert len(travmap.open(SAMPLE, frames="3..")) == 3


@needs_sample
def test_a_damaged_file_raises_the_commands_error(tmp_path, converted):
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(converted.read_bytes()[:5000])
    with pytest.raises(travmap.TravmapError) as raised:
        list(travmap.run(broken))
    assert raised.value.exit_code == 1 and str(broken) in str(raised.value)
    command = cli("run", broken)
    assert command.returncode == 1
    assert str(raised.value) in command.stderr


def test_what_the_command_says_of_a_drive_is_warned(recwarn):
    rellis = SHARED / "rellis3d-000104" / "sequences" / "00"
    if not rellis.is_dir():
        pytest.skip(f"{rellis} missing")
    said = [line[len("notice: "):] for line in cli("run", rellis, "-q").stderr.splitlines() if line.startswith("notice: ")]
    assert any("fit the model poorly" in line for line in said)
    grids = list(travmap.run(rellis))
    warned = [str(w.message) for w in recwarn if issubclass(w.category, travmap.TravmapWarning)]
    # The road model on off-road ground: the command's notices, word for word.
    assert [line for line in said if "poorly" in line] == [w for w in warned if "poorly" in w]
    assert grids and all(not w.startswith("notice") for w in warned)
    # A sample the model knows: nothing to say.
    if SAMPLE.is_dir():
        recwarn.clear()
        list(travmap.run(SAMPLE))
        assert not [w for w in recwarn if issubclass(w.category, travmap.TravmapWarning)]


@needs_sample
def test_a_drive_cut_short_warns_where_the_command_exits_3(tmp_path, converted):
    cut = tmp_path / "cut.mcap"
    data = converted.read_bytes()
    cut.write_bytes(data[: len(data) * 4 // 5])
    with pytest.warns(travmap.TravmapWarning, match="lost part"):
        grids = list(travmap.run(cut))
    assert 1 <= len(grids) < 6
    assert cli("run", cut).returncode == 3
    drive = travmap.open(cut)
    with pytest.warns(travmap.TravmapWarning):
        frames = list(drive)
    assert drive.lost and len(frames) == len(grids)


def test_mistakes_raise_before_any_work(tmp_path):
    with pytest.raises(travmap.TravmapError, match="does not exist") as missing:
        travmap.open(tmp_path / "nowhere")
    assert missing.value.exit_code == 1
    if SAMPLE.is_dir():
        with pytest.raises(travmap.TravmapError) as typo:
            travmap.open(SAMPLE, set={"grid.size_mm": 24})
        assert typo.value.exit_code == 2 and "size_mm" in str(typo.value)
        with pytest.raises(travmap.TravmapError, match="no scans in frames 40..=41"):
            travmap.open(SAMPLE, frames="40..42")
        with pytest.raises(travmap.TravmapError, match="scan rate of 0.01 to 1000 Hz, got 0.0"):
            travmap.open(SAMPLE, rate=0)
        with pytest.raises(TypeError, match="cloud_topics"):
            travmap.open(SAMPLE, cloud_topics="/points")
    with pytest.raises(travmap.TravmapError):
        travmap.Model(str(tmp_path / "missing.json"))


@needs_sample
def test_an_iteration_left_early_ends_its_reading():
    drive = travmap.open(SAMPLE)
    for frame in drive:
        break
    del frame
    # The drive reads again from the start, as often as asked.
    assert [f.index for f in drive] == list(range(6))
    grids = travmap.run(SAMPLE)
    assert next(grids).index == 0
    del grids


@needs_sample
def test_eval_and_dataset_are_the_commands():
    scores = travmap.eval(SAMPLE)
    printed = json_lines(cli("eval", SAMPLE, "--json"))[-1]
    assert scores["scores"] == printed["scores"] and scores["confusion"] == printed["confusion"]
    pyarrow = pytest.importorskip("pyarrow")
    table = travmap.dataset([SAMPLE], set={"training.grid_size_m": 12})
    assert isinstance(table, pyarrow.Table) and table.num_rows > 0
    assert {"frame", "row", "col", "ground_truth_traversable"} <= set(table.column_names)
    assert set(table.column("frame").to_pylist()) <= set(range(6))


def test_help_reads_like_the_command_lines():
    said = " ".join(travmap.open.__doc__.split())
    assert "any input the `travmap` command reads" in said
    assert "frames: None (every frame)" in said and "keep_going" in said
    assert "Raises TravmapError" in said
    assert "as `travmap run` does" in " ".join(travmap.run.__doc__.split())


@needs_sample
def test_the_fleet_runs_as_a_module_with_the_packages_command(tmp_path, converted):
    pytest.importorskip("ray")
    out = tmp_path / "out"
    ran = subprocess.run(
        [sys.executable, "-m", "travmap.fleet", "dataset", str(converted), "--out-dir", str(out), "--num-cpus", "1"],
        capture_output=True,
        text=True,
        env={**os.environ, "RAY_DISABLE_IMPORT_WARNING": "1"},
    )
    assert ran.returncode == 0, ran.stderr
    assert "1 files: 1 done" in ran.stdout


def test_mistaken_arguments_name_themselves():
    with pytest.raises(TypeError, match="set=5"):
        travmap.open(SAMPLE, set=5)
    with pytest.raises(TypeError, match="model=5"):
        travmap.run(SAMPLE, model=5)
    with pytest.raises(travmap.TravmapError, match="start at 0"):
        travmap.open(SAMPLE, frames=-1)
    with pytest.raises(TypeError, match="frames=3.5"):
        travmap.eval(SAMPLE, frames=3.5)
    with pytest.raises(travmap.TravmapError, match="road.*offroad"):
        travmap.Model("nope")
    assert travmap.__version__ and travmap.__version__ != "0+unknown"
