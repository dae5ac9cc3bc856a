"""travmap.run in Python against `travmap run --json` on the same input, alternating
11 times each (docs/speed.md, "Python"): run with the Python of an environment that
holds the wheel, e.g. `python scripts/python_speed.py ../shared/data/semantickitti-00/sequences/00`."""
import statistics
import subprocess
import sys
import time

import travmap

inputs = sys.argv[1:]
for path in inputs:
    cli, inproc, proc, opened = [], [], [], []
    for _ in range(11):
        t = time.perf_counter(); subprocess.run([travmap.binary(), "run", path, "--json"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True); cli.append(time.perf_counter() - t)
        t = time.perf_counter(); grids = list(travmap.run(path)); inproc.append(time.perf_counter() - t)
        t = time.perf_counter(); subprocess.run([sys.executable, "-c", f"import travmap; list(travmap.run({path!r}))"], check=True); proc.append(time.perf_counter() - t)
        t = time.perf_counter(); frames = [f.points.shape[0] for f in travmap.open(path, images=False)]; opened.append(time.perf_counter() - t)
    m = statistics.median
    print(f"{path}: frames {len(grids)}; cli run --json {m(cli)*1e3:.0f} ms; python in-process {m(inproc)*1e3:.0f} ms ({m(inproc)/m(cli):.2f}x); python process {m(proc)*1e3:.0f} ms ({m(proc)/m(cli):.2f}x); open+iterate {m(opened)*1e3:.0f} ms for {sum(frames)} points")
