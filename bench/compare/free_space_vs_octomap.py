#!/usr/bin/env python3
"""Free-space mapping, olmap against OctoMap, like for like, in one run.

For each case (the shared real scans): olmap inserts the clouds into a log-odds map with
free space (`olmap voxelize --free-space --threads 1`) and writes the same clouds, placed
by the same poses, as an OctoMap ScanGraph; OctoMap's own `graph2tree` (Debian
`octomap-tools`, one thread) inserts that graph at the same resolution, sensor model
(hit 0.7, miss 0.4, clamping 0.1192-0.971: both defaults) and maximum range (none);
`olmap compare-bt` compares the two trees voxel by voxel. Insertion times are each
tool's own (file reading and writing excluded); memory is olmap's map storage against
OctoMap's `memoryUsage()` of its pruned tree, as graph2tree prints it.

Usage: bench/compare/free_space_vs_octomap.py [--data DIR] [--olmap BIN]
           [--resolution M] [--repeat N] [--json]
Needs: an olmap release build (`cargo build --release`), `graph2tree` on PATH.
"""

import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from common import loadavg, parser, run  # noqa: E402


def cases(data):
    tdk = os.path.join(data, "3dtk_dat")
    scans = [os.path.join(tdk, f"scan00{i}.3d") for i in range(3)]
    frames = ",".join(os.path.join(tdk, f"scan00{i}.frames") for i in range(3))
    return [
        ("scan.dat (1 scan, 88k points)", [os.path.join(data, "octomap_share_data", "scan.dat")], []),
        ("3DTK 000-002 (3 scans, 234k points)", scans, ["--poses", frames, "--3dtk-valid"]),
    ]


def main():
    ap = parser(__doc__)
    ap.add_argument("--resolution", type=float, default=0.05, help="voxel edge, metres (default 0.05)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per tool; medians are reported (default 3)")
    ap.add_argument("--json", action="store_true", help="print JSON rows instead of a table")
    a = ap.parse_args()
    if shutil.which("graph2tree") is None:
        sys.exit("graph2tree not found: install OctoMap's tools (Debian/Ubuntu: apt install octomap-tools)")
    if not os.path.exists(a.olmap):
        sys.exit(f"{a.olmap} not found: build it with `cargo build --release`")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, clouds, extra in cases(a.data):
            ours, graph, theirs = (os.path.join(tmp, f) for f in ("ours.bt", "scans.graph", "octomap.bt"))
            load_before = loadavg()
            ol = []
            for _ in range(a.repeat):
                rep = json.loads(run([a.olmap, "voxelize", "--free-space", "--json", "--threads", "1",
                                      "--resolution", str(a.resolution), "-o", ours, "--scan-graph", graph]
                                     + extra + clouds))
                ol.append(rep)
            om_times, om_mem = [], None
            for _ in range(a.repeat):
                text = run(["graph2tree", "-i", graph, "-o", theirs, "-res", str(a.resolution)])
                om_times.append(float(re.search(r"time to insert scans: ([0-9.eE+-]+)", text).group(1)))
                # The first "Memory:" line is the pruned (lossless) tree, before the
                # maximum-likelihood conversion.
                om_mem = int(re.search(r"Memory: (\d+) byte", text).group(1))
            cmp = json.loads(run([a.olmap, "compare-bt", "--json", ours, theirs]))
            t_ol = statistics.median(r["insert_seconds"] for r in ol)
            t_om = statistics.median(om_times)
            rows.append({
                "case": name,
                "resolution": a.resolution,
                "points": ol[0]["points"],
                "olmap_insert_s": t_ol,
                "octomap_insert_s": t_om,
                "speedup": t_om / t_ol,
                "olmap_memory_bytes": ol[0]["memory_bytes"],
                "octomap_memory_bytes": om_mem,
                "memory_ratio": om_mem / ol[0]["memory_bytes"],
                "known_olmap": cmp["known_here"],
                "known_octomap": cmp["known_there"],
                "known_both": cmp["both_known"],
                "agreement": cmp["agreement"],
                "load_1min_before": load_before,
                "load_1min_after": loadavg(),
            })
    if a.json:
        print(json.dumps(rows, indent=2))
        return
    print(f"| case | olmap insert (1 thread) | OctoMap insert | speed-up | olmap memory | OctoMap memoryUsage() | "
          f"memory ratio | voxels known to both | agreement | load avg before/after |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['case']} @ {r['resolution']} m | {r['olmap_insert_s']:.3f} s | {r['octomap_insert_s']:.3f} s | "
              f"{r['speedup']:.1f}x | {r['olmap_memory_bytes'] / 2**20:.1f} MiB | {r['octomap_memory_bytes'] / 2**20:.1f} MiB | "
              f"{r['memory_ratio']:.1f}x less | {r['known_both']:,} | {100 * r['agreement']:.4f} % | "
              f"{r['load_1min_before']:.2f} / {r['load_1min_after']:.2f} |")


if __name__ == "__main__":
    main()
