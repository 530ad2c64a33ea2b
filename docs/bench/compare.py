#!/usr/bin/env python3
"""Times whole processes side by side, alternating, and reports the median wall time and peak resident memory of
each command (issue 11, item 2). Usage:

    python3 docs/bench/compare.py RUNS FILE.csv
        (runs `magcal-fit FILE --method vector --no-diagnose` from target/release and
         `python3 docs/bench/polars_numpy.py FILE` RUNS times each, alternating)
"""
import os
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))


def run(cmd):
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    if status != 0:
        sys.exit(f"{cmd} failed: {proc.stderr.read().decode()}")
    return wall, usage.ru_maxrss / 1024  # MiB (ru_maxrss is in KiB on Linux)


def main(runs, path):
    commands = {
        "magcal-fit --method vector --no-diagnose": [
            os.path.join(ROOT, "target", "release", "magcal-fit"), path, "--method", "vector", "--no-diagnose"],
        "polars read_csv + numpy": [sys.executable, os.path.join(HERE, "polars_numpy.py"), path],
    }
    results = {name: [] for name in commands}
    for _ in range(runs):
        for name, cmd in commands.items():
            results[name].append(run(cmd))
    size = os.path.getsize(path) / 1e6
    print(f"{path} ({size:.0f} MB), {runs} runs each, alternating")
    print("| command | wall s (median) | min–max | peak MiB (median) |")
    print("|---|---|---|---|")
    for name, rows in results.items():
        walls = [w for w, _ in rows]
        print(f"| {name} | {statistics.median(walls):.3f} | {min(walls):.3f}–{max(walls):.3f} | "
              f"{statistics.median(m for _, m in rows):.0f} |")


if __name__ == "__main__":
    main(int(sys.argv[1]), sys.argv[2])
