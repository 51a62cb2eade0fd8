#!/usr/bin/env python3
"""The large world (issue 27): map building and global localisation at warehouse scale.

1. `olmap simulate --world warehouse`: one robot with the 32-beam lidar drives the
   serpentine route of the 200 x 200 m warehouse (31 double rack rows) for --stops stops
   --step metres apart, with typical odometry.
2. `olmap map --mode incremental` maps every scan in order from its odometry (0.1 m):
   wall time, peak memory (`/usr/bin/time -v`), scans placed, and the error of the
   placed poses against the truth after the best rigid fit (ATE; the map frame is the
   first scan's, which registration alone cannot know better than its first match).
3. `olmap voxelize` fuses every scan but the query scans, at the mapped poses, into the
   localisation map (--loc-resolution, endpoints; the default 0.025 m holds over 10^7
   voxels): voxels and bytes per voxel.
4. `olmap localize --global` localises each query scan (every --query-every th stop, not
   in the map) with no initial guess, at --search-resolution (a finer map is read at its
   pyramid level within it), on --threads threads: seconds, peak memory, error
   against the truth (through the fitted map frame), and whether olmap trusted it. By
   default one process localises every query (`--also`): the map is prepared once, its
   preparation timed apart, and each query's seconds are its own (a localisation
   service); --one-shot runs one process per query, each preparing the map for itself.

Usage: bench/large_world.py [--olmap BIN] [--stops N] [--step MIN,MAX] [--seed S]
           [--threads T] [--loc-resolution M] [--search-resolution M] [--query-every K]
           [--one-shot] [--keep DIR] [--json]
Needs an olmap release build (`cargo build --release`) and GNU time (`/usr/bin/time`).
"""

import argparse
import json
import math
import os
import re
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "compare"))
from common import loadavg  # noqa: E402


def timed(cmd):
    """Runs `cmd` under GNU time: (stdout, peak resident bytes)."""
    out = subprocess.run(["/usr/bin/time", "-v"] + cmd, capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"failed: {' '.join(cmd[:6])} …\n{out.stderr[-2000:]}")
    peak = re.search(r"Maximum resident set size \(kbytes\): (\d+)", out.stderr)
    return out.stdout, int(peak.group(1)) * 1024 if peak else None


def read_poses(path):
    """An olmap pose list: name -> (x, y, z, yaw)."""
    poses = {}
    for line in open(path):
        if line.startswith("#") or not line.strip():
            continue
        f = line.split()
        v = list(map(float, f[1:13]))
        poses[f[0]] = (v[3], v[7], v[11], math.atan2(v[4], v[0]))
    return poses


def rigid_fit(est, ref, names):
    """The planar rigid transform (theta, tx, ty) taking est positions onto ref positions."""
    n = len(names)
    me = [sum(est[k][i] for k in names) / n for i in (0, 1)]
    mr = [sum(ref[k][i] for k in names) / n for i in (0, 1)]
    sxx = sxy = 0.0
    for k in names:
        ex, ey = est[k][0] - me[0], est[k][1] - me[1]
        rx, ry = ref[k][0] - mr[0], ref[k][1] - mr[1]
        sxx += ex * rx + ey * ry
        sxy += ex * ry - ey * rx
    th = math.atan2(sxy, sxx)
    c, s = math.cos(th), math.sin(th)
    return th, mr[0] - (c * me[0] - s * me[1]), mr[1] - (s * me[0] + c * me[1])


def apply(fit, p):
    th, tx, ty = fit
    c, s = math.cos(th), math.sin(th)
    return (c * p[0] - s * p[1] + tx, s * p[0] + c * p[1] + ty, p[2], p[3] + th)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    ap.add_argument("--olmap", default=os.path.join(root, "target", "release", "olmap"))
    ap.add_argument("--stops", type=int, default=500, help="scans (default 500)")
    ap.add_argument("--step", default="1.5,2.5", help="metres between stops, MIN,MAX (default 1.5,2.5)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--threads", type=int, default=2, help="threads of every step (default 2)")
    ap.add_argument("--loc-resolution", type=float, default=0.025,
                    help="localisation map voxel, m (default 0.025: over 10^7 voxels)")
    ap.add_argument("--search-resolution", type=float, default=0.1,
                    help="localisation's search resolution, m (default 0.1, olmap's)")
    ap.add_argument("--query-every", type=int, default=100, help="every K-th stop is a query (default 100)")
    ap.add_argument("--one-shot", action="store_true",
                    help="one olmap process per query scan (the map prepared for each)")
    ap.add_argument("--keep", help="keep the data and maps in this folder")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    if not os.path.exists(a.olmap):
        sys.exit(f"{a.olmap} not found: build it with `cargo build --release`")
    if not os.path.exists("/usr/bin/time"):
        sys.exit("/usr/bin/time (GNU time) not found")
    tmp = a.keep or tempfile.mkdtemp(prefix="olmap-large-")
    os.makedirs(tmp, exist_ok=True)
    data = os.path.join(tmp, "data")
    th = ["--threads", str(a.threads)]
    load = [loadavg()]
    sim = json.loads(subprocess.run(
        [a.olmap, "simulate", "--world", "warehouse", "--robots", "1", "--scans-per-robot", str(a.stops),
         "--step", a.step, "--scanner", "lidar", "--odometry", "typical", "--seed", str(a.seed),
         "-o", data, "--json"], capture_output=True, text=True, check=True).stdout)
    robot = os.path.join(data, "robot0")
    scans = sorted(os.listdir(os.path.join(robot, "scans")))
    paths = [os.path.join(robot, "scans", s) for s in scans]
    poses_out = os.path.join(tmp, "mapped.txt")
    out, map_peak = timed([a.olmap, "map"] + paths + ["--odometry", os.path.join(robot, "odometry.txt"),
                          "--mode", "incremental", "--poses-out", poses_out, "-o", os.path.join(tmp, "map.olm"),
                          "--json"] + th)
    mapped = json.loads(out)
    est, truth = read_poses(poses_out), read_poses(os.path.join(robot, "truth.txt"))
    names = [n for n in est if n in truth]
    fit = rigid_fit(est, truth, names)
    errs = [math.hypot(apply(fit, est[n])[0] - truth[n][0], apply(fit, est[n])[1] - truth[n][1]) for n in names]
    ate = math.sqrt(sum(e * e for e in errs) / len(errs))
    # The localisation map: every scan but the queries, at the mapped poses.
    queries = [i for i in range(0, len(scans), a.query_every) if i > 0]
    query_names = {os.path.splitext(scans[i])[0] for i in queries}
    kept = [p for p, s in zip(paths, scans) if os.path.splitext(s)[0] not in query_names
            and os.path.splitext(s)[0] in est]
    kept_poses = os.path.join(tmp, "kept.txt")
    with open(poses_out) as src, open(kept_poses, "w") as dst:
        for line in src:
            if line.startswith("#") or line.split()[0] not in query_names:
                dst.write(line)
    big = os.path.join(tmp, "big.olm")
    out, vox_peak = timed([a.olmap, "voxelize"] + kept + ["--poses", kept_poses, "--resolution",
                          str(a.loc_resolution), "-o", big, "--json"] + th)
    vox = json.loads(out)
    rows = []
    prepare_seconds = None
    res = ["--resolution", str(a.search_resolution)]
    if a.one_shot:
        results = []
        for i in queries:
            out, peak = timed([a.olmap, "localize", paths[i], big, "--global", "--json"] + res + th)
            results.append((json.loads(out), peak))
    else:
        also = ["--also"] + [paths[i] for i in queries[1:]] if len(queries) > 1 else []
        out, peak = timed([a.olmap, "localize", paths[queries[0]], big, "--global", "--json"]
                          + also + res + th)
        many = json.loads(out)
        prepare_seconds = many["prepare_seconds"]
        results = [(r, peak) for r in many["results"]]
    for i, (r, peak) in zip(queries, results):
        name = os.path.splitext(scans[i])[0]
        m = r["T_target_source"]
        p = apply(fit, (m[0][3], m[1][3], m[2][3], math.atan2(m[1][0], m[0][0])))
        t = truth[name]
        rows.append({
            "scan": name,
            "seconds": r.get("seconds"),
            "peak_memory_bytes": peak,
            "error_m": math.hypot(p[0] - t[0], p[1] - t[1]),
            "error_deg": abs(math.degrees(math.remainder(p[3] - t[3], 2 * math.pi))),
            "trusted": r.get("trusted"),
        })
    load.append(loadavg())
    report = {
        "stops": a.stops, "step_m": a.step, "seed": a.seed, "threads": a.threads,
        "points": sim["points"], "simulate_seconds": sim["seconds"],
        "map": {"seconds": mapped["seconds"], "placed": len(mapped["placed"]), "scans": mapped["scans"],
                "registrations": mapped["registrations"], "voxels": mapped["voxels"],
                "ate_rms_m": ate, "ate_max_m": max(errs), "peak_memory_bytes": map_peak},
        "localisation_map": {k: vox.get(k) for k in ("voxels", "resolution", "bytes_per_voxel", "seconds")}
        | {"peak_memory_bytes": vox_peak},
        "localisation": rows, "localisation_prepare_seconds": prepare_seconds,
        "search_resolution": a.search_resolution, "load": load,
        "folder": tmp if a.keep else None,
    }
    if a.json:
        print(json.dumps(report, indent=2))
        return
    m = report["map"]
    print(f"warehouse seed {a.seed}: {a.stops} lidar scans {a.step} m apart, {sim['points']:,} points, "
          f"simulated in {sim['seconds']:.1f} s; {a.threads} threads; load {load[0]:.1f}-{load[1]:.1f}")
    print(f"map building (incremental, 0.1 m): {m['seconds']:.1f} s, {m['placed']}/{m['scans']} placed, "
          f"{m['registrations']} registrations, ATE {m['ate_rms_m']:.3f} m rms / {m['ate_max_m']:.3f} m max, "
          f"{m['voxels']:,} voxels, peak {m['peak_memory_bytes'] / 2**20:.0f} MiB")
    lm = report["localisation_map"]
    print(f"localisation map ({lm['resolution']} m): {lm['voxels']:,} voxels, "
          f"{lm['bytes_per_voxel']:.1f} bytes per voxel, peak {lm['peak_memory_bytes'] / 2**20:.0f} MiB")
    if prepare_seconds is not None:
        print(f"  the map prepared once for every query in {prepare_seconds:.2f} s (peak: the whole run's), "
              f"searched at {a.search_resolution} m")
    for r in rows:
        print(f"  localise {r['scan']}: {r['seconds']:.2f} s, {r['error_m']:.3f} m / {r['error_deg']:.2f} deg, "
              f"trusted {r['trusted']}, peak {r['peak_memory_bytes'] / 2**20:.0f} MiB")


if __name__ == "__main__":
    main()
