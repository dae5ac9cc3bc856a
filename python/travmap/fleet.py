"""Run travmap over thousands of drives on a Ray cluster.

One Ray task per input file runs the `travmap` binary on it (`annotate` or
`dataset`). Outputs are named from the input (its stem and a hash of its absolute
path), so a re-run skips every file whose output already exists: travmap writes
atomically, so an output that exists is complete. A task whose travmap was killed
(a signal, a lost node) is retried; an input that travmap rejects (exit code 1,
bad data) is reported, not retried, since it would fail the same way again. The
run ends with a summary of files, frames, skipped frames and failures, printed and
written to OUT_DIR/fleet-summary.json.

    python -m travmap.fleet annotate 'logs/**/*.mcap' --out-dir annotated/
    python -m travmap.fleet dataset 'logs/**/*.mcap' --out-dir cells/ -- --set training.grid_size_m=24
    python -m travmap.fleet annotate 'logs/**/*.mcap' --out-dir annotated/ --adapt

`--adapt` adapts the model to each drive before annotating it (`travmap annotate
--adapt`: self-supervised, from the drive itself; docs/method.md "Adaptation").

On a cluster, start Ray there and pass `--address auto` (or set RAY_ADDRESS); every
node runs the travmap command its own `pip install travmap` put beside this module
(or the one `--travmap` names).
"""

from __future__ import annotations

import argparse
import glob
import hashlib
import json
import os
import re
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import ray

from ._commands import binary

# What each command writes, by the suffix of its output.
SUFFIXES = {"annotate": ".annotated.mcap", "dataset": ".cells.parquet"}

# travmap's exit codes (docs/guide.md "Exit codes and errors").
COMPLETE, ERROR, COMPLETED_WITH_SKIPS = 0, 1, 3


@dataclass
class FileResult:
    input: str
    output: str
    status: str  # "done", "already done", "failed"
    exit_code: int | None = None
    frames: int = 0
    skipped_frames: int = 0
    attempts: int = 0
    seconds: float = 0.0
    error: str = ""


@dataclass
class Summary:
    files: int = 0
    done: int = 0
    already_done: int = 0
    failed: int = 0
    frames: int = 0
    skipped_frames: int = 0
    seconds: float = 0.0
    failures: list = field(default_factory=list)


def output_path(input_path: str, out_dir: str, command: str) -> str:
    """The deterministic output of `input_path`: its stem plus a hash of its
    absolute path, so two `drive.mcap` in different folders do not collide."""
    absolute = os.path.abspath(input_path)
    digest = hashlib.sha256(absolute.encode()).hexdigest()[:10]
    stem = Path(input_path).name.removesuffix(".mcap")
    return os.path.join(out_dir, f"{stem}-{digest}{SUFFIXES[command]}")


def run_travmap(travmap: str, command: str, input_path: str, output: str, extra: list[str], retries: int) -> FileResult:
    """Runs travmap on one file, retrying a run that was killed rather than refused."""
    result = FileResult(input=input_path, output=output, status="failed")
    started = time.monotonic()
    for attempt in range(1, retries + 2):
        result.attempts = attempt
        process = subprocess.run(
            [travmap, command, input_path, "-o", output, "--json", "--quiet", "--keep-going", *extra],
            capture_output=True,
            text=True,
        )
        result.exit_code = process.returncode
        if process.returncode in (COMPLETE, COMPLETED_WITH_SKIPS):
            report = json.loads(process.stdout)
            result.status = "done"
            result.frames = int(report["frames"])
            skipped = re.search(r"completed with (\d+) skipped frame", process.stderr)
            result.skipped_frames = int(skipped.group(1)) if skipped else 0
            break
        result.error = process.stderr.strip().splitlines()[-1] if process.stderr.strip() else f"exit {process.returncode}"
        if process.returncode == ERROR:
            break  # the input itself is bad: the same error again on a retry
    result.seconds = time.monotonic() - started
    return result


@ray.remote
def process_file(travmap: str, command: str, input_path: str, output: str, extra: list[str], retries: int) -> dict:
    return asdict(run_travmap(travmap, command, input_path, output, extra, retries))


def run_fleet(
    command: str,
    inputs: list[str],
    out_dir: str,
    travmap: str,
    extra: list[str] | None = None,
    retries: int = 2,
    max_task_retries: int = 3,
) -> Summary:
    """Annotates or extracts every input on the connected Ray cluster; returns and
    writes the summary. Files whose output exists are not run again."""
    extra = extra or []
    os.makedirs(out_dir, exist_ok=True)
    started = time.monotonic()
    summary = Summary(files=len(inputs))
    pending = []
    for input_path in sorted(set(inputs)):
        output = output_path(input_path, out_dir, command)
        if os.path.exists(output):
            summary.already_done += 1
            continue
        # max_retries: Ray re-runs the task when its worker or node dies.
        task = process_file.options(max_retries=max_task_retries)
        pending.append(task.remote(travmap, command, input_path, output, extra, retries))
    while pending:
        ready, pending = ray.wait(pending, num_returns=1)
        try:
            result = FileResult(**ray.get(ready[0]))
        except ray.exceptions.RayError as error:  # the task itself was lost for good
            summary.failed += 1
            summary.failures.append({"input": "?", "error": str(error)})
            continue
        if result.status == "done":
            summary.done += 1
            summary.frames += result.frames
            summary.skipped_frames += result.skipped_frames
        else:
            summary.failed += 1
            summary.failures.append({"input": result.input, "exit_code": result.exit_code, "error": result.error})
    summary.seconds = time.monotonic() - started
    summary.failures.sort(key=lambda f: f["input"])
    with open(os.path.join(out_dir, "fleet-summary.json"), "w") as f:
        json.dump(asdict(summary), f, indent=2)
    return summary


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    extra = []
    if "--" in argv:
        extra = argv[argv.index("--") + 1 :]
        argv = argv[: argv.index("--")]
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("command", choices=sorted(SUFFIXES))
    parser.add_argument("inputs", nargs="+", help="MCAP files or glob patterns (quoted; ** recurses)")
    parser.add_argument("--out-dir", required=True)
    parser.add_argument("--travmap", default=None, help="the travmap binary on every node (default: the package's own)")
    parser.add_argument("--address", default=None, help="Ray cluster address (default: RAY_ADDRESS or a local Ray)")
    parser.add_argument("--num-cpus", type=int, default=None, help="CPUs of a local Ray")
    parser.add_argument("--retries", type=int, default=2, help="re-runs of a travmap that was killed")
    parser.add_argument("--adapt", action="store_true", help="annotate: adapt the model to each drive first")
    args = parser.parse_args(argv)
    if args.adapt:
        if args.command != "annotate":
            parser.error("--adapt goes with annotate")
        extra = ["--adapt", *extra]
    inputs = [path for pattern in args.inputs for path in (glob.glob(pattern, recursive=True) or [pattern])]
    ray.init(address=args.address, num_cpus=args.num_cpus if args.address is None else None)
    summary = run_fleet(args.command, inputs, args.out_dir, args.travmap or binary(), extra, args.retries)
    print(
        f"{summary.files} files: {summary.done} done, {summary.already_done} already done, "
        f"{summary.failed} failed; {summary.frames} frames, {summary.skipped_frames} skipped frames, "
        f"{summary.seconds:.1f} s"
    )
    for failure in summary.failures:
        print(f"failed: {failure['input']}: {failure['error']}", file=sys.stderr)
    return 1 if summary.failed else 0


if __name__ == "__main__":
    sys.exit(main())
