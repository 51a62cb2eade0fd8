"""Simulate robots with degraded odometry mapping a lab together, map them as a team and
compare every scan with the ground truth (the thesis' chapter 6 experiment, small).

    python examples/python/team_demo.py [--robots N] [--scans N] [--seed S]
"""

import argparse
import sys

import numpy as np

import olmap


def main(argv):
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--robots", type=int, default=4)
    p.add_argument("--scans", type=int, default=10, help="scans per robot")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--world", default="lab")
    a = p.parse_args(argv)
    ds = olmap.simulate(world=a.world, robots=a.robots, scans_per_robot=a.scans, seed=a.seed,
                        odometry="degraded")
    print(ds)
    team = olmap.map_team(ds)
    # Errors against the truth, in the first robot's first-scan frame.
    truth0 = np.linalg.inv(ds.truth(0)[0])
    errors = []
    for r, robot in enumerate(ds.robots):
        for k, t in enumerate(ds.truth(r)):
            pose = team.poses.get(f"{robot}/scan{k:03d}")
            if pose is not None:
                errors.append(np.linalg.norm(pose[:3, 3] - (truth0 @ t)[:3, 3]))
    errors = np.array(errors)
    n = a.robots * a.scans
    print(f"team map: {len(errors)}/{n} scans placed, {len(team.map)} voxels; position error "
          f"median {np.median(errors):.3f} m, max {errors.max():.3f} m")
    summary = team.report["evaluation"]["team"]
    print(f"report: mean {summary['mean_m']:.3f} m, {100 * summary['share_above_0.3_m']:.1f} % "
          f"beyond 0.3 m")
    return 0 if len(errors) and errors.max() < 0.3 else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
