"""`python -m travmap.fleet` on a local Ray (2 CPUs) over a handful of converted MCAP
files, one of them corrupt, with the travmap command the wheel installed. Needs the
shared data beside the repository."""

import json
import os
import shutil
import subprocess
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import ray

import travmap
from travmap import fleet as travmap_fleet

TRAVMAP = travmap.binary()
SEQUENCE = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "semantickitti-00" / "sequences" / "00"

pytestmark = pytest.mark.skipif(not SEQUENCE.is_dir(), reason="../shared/data missing")


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, logging_level="ERROR")
    yield
    ray.shutdown()


@pytest.fixture(scope="module")
def drives(tmp_path_factory):
    """Four drives of two frames each (two in a subfolder with the same names) and
    one truncated file."""
    root = tmp_path_factory.mktemp("logs")
    paths = []
    for folder, frames in [("a", "0..2"), ("a", "2..4"), ("b", "0..2"), ("b", "3..5")]:
        (root / folder).mkdir(exist_ok=True)
        path = root / folder / f"drive-{frames.replace('..', '-')}.mcap"
        subprocess.run([TRAVMAP, "convert", str(SEQUENCE), "-o", str(path), "--frames", frames, "-q"], check=True)
        paths.append(str(path))
    broken = root / "broken.mcap"
    broken.write_bytes(Path(paths[0]).read_bytes()[:5000])
    return paths, str(broken)


def test_annotates_every_file_reports_the_broken_one_and_skips_finished_ones(local_ray, drives, tmp_path):
    good, broken = drives
    out = tmp_path / "annotated"
    summary = travmap_fleet.run_fleet("annotate", good + [broken], str(out), TRAVMAP)
    assert (summary.files, summary.done, summary.already_done, summary.failed) == (5, 4, 0, 1)
    assert summary.frames == 8 and summary.skipped_frames == 0
    assert summary.failures[0]["input"] == broken
    assert summary.failures[0]["exit_code"] == 1 and "nothing complete to read" in summary.failures[0]["error"]
    outputs = sorted(p.name for p in out.glob("*.annotated.mcap"))
    assert len(outputs) == 4 and not (out / travmap_fleet.output_path(broken, str(out), "annotate")).exists()
    written = json.loads((out / "fleet-summary.json").read_text())
    assert written["done"] == 4 and written["failed"] == 1

    # A re-run touches nothing finished; a removed output is made again.
    first = Path(travmap_fleet.output_path(good[0], str(out), "annotate"))
    untouched = Path(travmap_fleet.output_path(good[1], str(out), "annotate"))
    untouched_mtime = untouched.stat().st_mtime_ns
    first.unlink()
    again = travmap_fleet.run_fleet("annotate", good + [broken], str(out), TRAVMAP)
    assert (again.done, again.already_done, again.failed, again.frames) == (1, 3, 1, 2)
    assert first.exists() and untouched.stat().st_mtime_ns == untouched_mtime


def test_outputs_are_named_by_input_path_so_equal_names_do_not_collide(tmp_path):
    a = travmap_fleet.output_path("/logs/a/drive.mcap", str(tmp_path), "dataset")
    b = travmap_fleet.output_path("/logs/b/drive.mcap", str(tmp_path), "dataset")
    assert a != b and a.endswith(".cells.parquet") and os.path.basename(a).startswith("drive-")
    assert a == travmap_fleet.output_path("/logs/a/drive.mcap", str(tmp_path), "dataset")


def test_extracts_datasets_that_pyarrow_reads(local_ray, drives, tmp_path):
    good, _ = drives
    out = tmp_path / "cells"
    summary = travmap_fleet.run_fleet("dataset", good, str(out), TRAVMAP, extra=["--set", "training.grid_size_m=12"])
    assert (summary.done, summary.failed, summary.frames) == (4, 0, 8)
    rows = 0
    for path in out.glob("*.cells.parquet"):
        table = pq.read_table(path)
        assert set(table.column("frame").to_pylist()) <= set(range(6))
        rows += table.num_rows
    assert rows > 0


def test_annotate_adapts_to_each_drive(local_ray, tmp_path):
    drive = tmp_path / "drive.mcap"
    subprocess.run([TRAVMAP, "convert", str(SEQUENCE), "-o", str(drive), "-q"], check=True)
    out = tmp_path / "annotated"
    # Six scans cover 3.6 m: fewer footprint cells than adapt asks by default.
    extra = ["--adapt", "--set", "adapt.min_footprint_cells=20"]
    summary = travmap_fleet.run_fleet("annotate", [str(drive)], str(out), TRAVMAP, extra=extra)
    assert (summary.done, summary.failed, summary.frames) == (1, 0, 6)
    from mcap.reader import make_reader

    with open(travmap_fleet.output_path(str(drive), str(out), "annotate"), "rb") as f:
        metadata = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
    adaptation = json.loads(metadata["travmap"]["adaptation"])
    assert adaptation["self_supervised"] and adaptation["footprint_cells"] > 0
    # The flag of the command line goes with annotate only.
    with pytest.raises(SystemExit):
        travmap_fleet.main(["dataset", str(drive), "--out-dir", str(out), "--adapt"])


def test_a_killed_travmap_is_retried_and_a_rejected_input_is_not(tmp_path):
    # A stand-in binary that dies by a signal on its first two runs, then fails cleanly.
    counter = tmp_path / "runs"
    fake = tmp_path / "fake-travmap"
    fake.write_text(
        "#!/bin/sh\n"
        f"n=$(cat {counter} 2>/dev/null || echo 0); n=$((n+1)); echo $n > {counter}\n"
        'if [ "$n" -le 2 ]; then kill -9 $$; fi\n'
        "echo 'error: bad input' >&2; exit 1\n"
    )
    fake.chmod(0o755)
    result = travmap_fleet.run_travmap(str(fake), "annotate", "x.mcap", str(tmp_path / "o"), [], retries=5)
    assert result.status == "failed" and result.attempts == 3 and result.exit_code == 1
    assert result.error == "error: bad input"
    shutil.rmtree(tmp_path)
