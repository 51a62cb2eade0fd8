#!/usr/bin/env python3
"""Pose-graph optimisation, olmap against GTSAM, on the standard benchmark graphs.

For each graph of the shared data (`pose_graphs/`: parking-garage and sphere2500 in SE(3),
M3500 in SE(2)): olmap optimises it (`olmap graph optimise`, chordal start, its own
`seconds`) and writes the result; GTSAM (PyPI `gtsam`, pinned in requirements.txt) reads
the same file with `readG2o`, anchors the first pose with a tight prior, and

* evaluates its own error (1/2 sum r^T Omega r, GTSAM's convention) at olmap's written
  poses: an independent check of what olmap claims;
* runs its Levenberg-Marquardt from the file's values and, for SE(3), from its own
  chordal start (`InitializePose3`), reporting the error reached and the time.

Both tools run on one core (taskset core 0, one thread); times are medians of --repeat
runs, each tool timing only its optimisation (file reading excluded).

Usage: bench/compare/pose_graphs_vs_gtsam.py [--data DIR] [--olmap BIN] [--repeat N] [--json]
"""

import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import loadavg, parser, run  # noqa: E402

GRAPHS = ["parking-garage", "sphere2500", "M3500"]

# Runs in a child process pinned like olmap: GTSAM's own part of the comparison.
GTSAM_CHILD = r"""
import json, sys, time, gtsam
inp, ours, repeat = sys.argv[1], sys.argv[2], int(sys.argv[3])
is3d = "SE3" in open(inp).read(4000)
graph, initial = gtsam.readG2o(inp, is3d)
first = min(initial.keys())
if is3d:
    graph.add(gtsam.PriorFactorPose3(first, initial.atPose3(first),
              gtsam.noiseModel.Diagonal.Variances([1e-6] * 6)))
else:
    graph.add(gtsam.PriorFactorPose2(first, initial.atPose2(first),
              gtsam.noiseModel.Diagonal.Variances([1e-6] * 3)))
_, olmap_values = gtsam.readG2o(ours, is3d)
params = gtsam.LevenbergMarquardtParams()
params.setMaxIterations(200)
params.setRelativeErrorTol(1e-10)
params.setAbsoluteErrorTol(1e-10)
def solve(start_fn):
    times, err = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        start = start_fn()
        result = gtsam.LevenbergMarquardtOptimizer(graph, start, params).optimize()
        times.append(time.perf_counter() - t)
        err = graph.error(result)
    return {"error": err, "seconds": sorted(times)[len(times) // 2]}
out = {
    "error_at_initial": graph.error(initial),
    "error_at_olmap": graph.error(olmap_values),
    "lm_from_file": solve(lambda: initial),
}
if is3d:
    out["lm_from_chordal"] = solve(lambda: gtsam.InitializePose3.initialize(graph))
print(json.dumps(out))
"""


def main():
    ap = parser(__doc__)
    ap.add_argument("--repeat", type=int, default=3, help="runs per tool; medians are reported (default 3)")
    ap.add_argument("--json", action="store_true", help="print JSON rows instead of a table")
    a = ap.parse_args()
    if not os.path.exists(a.olmap):
        sys.exit(f"{a.olmap} not found: build it with `cargo build --release`")
    try:
        import gtsam  # noqa: F401
    except ImportError:
        sys.exit("gtsam not found: pip install -r bench/compare/requirements.txt")
    pin = ["taskset", "-c", "0"] if shutil.which("taskset") else []
    env = dict(os.environ, RAYON_NUM_THREADS="1", OMP_NUM_THREADS="1", TBB_NUM_THREADS="1")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in GRAPHS:
            path = os.path.join(a.data, "pose_graphs", f"{name}.g2o")
            ours = os.path.join(tmp, f"{name}.olmap.g2o")
            load_before = loadavg()
            reps = [json.loads(run(pin + [a.olmap, "graph", "optimise", path, "-o", ours, "--json"], env=env))
                    for _ in range(a.repeat)]
            theirs = json.loads(run(pin + [sys.executable, "-c", GTSAM_CHILD, path, ours, str(a.repeat)], env=env))
            t_ol = statistics.median(r["seconds"] for r in reps)
            best_gtsam = min((v for k, v in theirs.items() if k.startswith("lm_")), key=lambda v: v["error"])
            rows.append({
                "graph": name,
                "olmap_cost_ceres": reps[0]["final_cost"],
                "olmap_iterations": reps[0]["iterations"],
                "olmap_seconds": t_ol,
                "gtsam_error_at_olmap": theirs["error_at_olmap"],
                "gtsam_error_at_initial": theirs["error_at_initial"],
                "gtsam_lm_from_file": theirs["lm_from_file"],
                "gtsam_lm_from_chordal": theirs.get("lm_from_chordal"),
                "gtsam_best_error": best_gtsam["error"],
                "speed_ratio": best_gtsam["seconds"] / t_ol if t_ol > 0 else float("nan"),
                "load": [load_before, loadavg()],
            })
    if a.json:
        print(json.dumps(rows, indent=2))
        return
    print("| graph | olmap: cost (Ceres) / GTSAM's error at olmap's poses | olmap s | GTSAM LM from file: error, s "
          "| GTSAM LM from chordal: error, s | olmap vs GTSAM's best (time) | load |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        ch = r["gtsam_lm_from_chordal"]
        chordal = f"{ch['error']:.6g}, {ch['seconds']:.3f}" if ch else "-"
        print(f"| {r['graph']} | {r['olmap_cost_ceres']:.6g} / {r['gtsam_error_at_olmap']:.6g} | {r['olmap_seconds']:.3f} "
              f"| {r['gtsam_lm_from_file']['error']:.6g}, {r['gtsam_lm_from_file']['seconds']:.3f} "
              f"| {chordal} "
              f"| {r['speed_ratio']:.2f}x | {r['load'][0]:.1f}-{r['load'][1]:.1f} |")


if __name__ == "__main__":
    main()
