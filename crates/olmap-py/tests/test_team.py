"""Simulation, team mapping, beacons and mutual localisation equal the command line's."""

import math

import numpy as np
import pytest

import olmap
from conftest import same_report


@pytest.fixture(scope="module")
def small():
    # Two robots, three stops each, in the box room: a few seconds.
    return olmap.simulate(world="box-room", robots=2, scans_per_robot=3, seed=3, scanner="lidar")


def test_simulate_is_seeded_and_has_truth(small):
    again = olmap.simulate(world="box-room", robots=2, scans_per_robot=3, seed=3, scanner="lidar")
    assert small.robots == ["robot0", "robot1"] and small.world == "box-room"
    for r in range(2):
        a, b = small.scans(r), again.scans(r)
        assert len(a) == 3
        assert all(np.array_equal(x.points, y.points) for x, y in zip(a, b))
        assert len(small.truth(r)) == 3
        assert np.array_equal(small.odometry(r)[0], np.eye(4))
    assert len(small.scans("robot1")) == 3
    with pytest.raises(ValueError, match="robot"):
        small.scans(5)


def test_the_corridor_ring_is_driven_round_its_centre_line_with_drifting_odometry():
    # The ring's centre line is the 23 x 13 m rectangle with its corner at (1.5, 1.5);
    # robots keep within the route's jitter of it (clamped to 0.2 m).
    data = olmap.simulate(world="corridor-ring", robots=2, scans_per_robot=4, seed=2,
                          odometry="drifting", scanner="lidar")
    assert data.world == "corridor-ring"

    def off_centre(x, y):
        out_x, out_y = max(1.5 - x, x - 24.5, 0.0), max(1.5 - y, y - 14.5, 0.0)
        if out_x > 0 or out_y > 0:
            return math.hypot(out_x, out_y)
        return min(abs(x - 1.5), abs(x - 24.5), abs(y - 1.5), abs(y - 14.5))

    for r in range(2):
        truth = data.truth(r)
        assert all(off_centre(t[0, 3], t[1, 3]) <= 0.2 + 1e-9 for t in truth)
        # Drifting odometry (5 % scale, 2 degrees per metre, 7.5 cm per move) is not the
        # truth after 3 moves of 1-2 m.
        moved = np.linalg.inv(truth[0]) @ truth[3]
        assert np.linalg.norm(moved[:3, 3] - data.odometry(r)[3][:3, 3]) > 1e-3
    with pytest.raises(ValueError, match="drifting"):
        olmap.simulate(world="corridor-ring", robots=1, scans_per_robot=1, odometry="wobbly")


def test_map_team_equals_the_cli_and_the_truth(small, cli, tmp_path):
    ds_dir = tmp_path / "dataset"
    small.write(ds_dir)
    cli_out = tmp_path / "cli"
    report = cli("team", "--json", ds_dir, "-o", cli_out)
    res = olmap.map_team(ds_dir)
    # Same placements, by name, to 1e-9 (the report schema is the CLI's).
    same_report(res.report, report)
    cli_poses = olmap.read_poses(cli_out / "team_poses.txt")
    assert set(res.poses) == set(cli_poses)
    for name, pose in res.poses.items():
        # The pose list file is text: compare to its printed precision.
        assert np.abs(pose - cli_poses[name]).max() < 1e-5, name
    c_cli, n_cli = olmap.OccupancyMap.load(cli_out / "team.olm").voxels()
    c_py, n_py = res.map.voxels()
    assert np.array_equal(c_cli, c_py) and np.array_equal(n_cli, n_py)
    # Against the truth: the team map of a box room places every scan within 0.3 m (the
    # gross-error threshold of the thesis' Figure 6.11).
    team = res.report["evaluation"]["team"]
    assert team["placed"] == 6 and team["max_m"] < 0.3


def test_map_team_in_memory_and_to_a_folder(small, tmp_path):
    res = olmap.map_team(small, out=tmp_path / "out")
    assert (tmp_path / "out" / "team.olm").is_file()
    assert (tmp_path / "out" / "report.json").is_file()
    assert len(res.poses) == 6
    mem = olmap.map_team(small)
    assert set(mem.poses) == set(res.poses)
    for name in mem.poses:
        assert np.array_equal(mem.poses[name], res.poses[name])


def test_detect_beacons_finds_a_pole():
    """A pole of radius 0.125 m at (2, 0.5) seen by a scanner with 0.5° steps: ranges from
    the ray-circle intersection, background wall at 6 m."""
    cx, cy, radius = 2.0, 0.5, 0.125
    angles = np.radians(np.arange(-90.0, 90.0 + 1e-9, 0.5))
    ranges = np.full(angles.size, 6.0)
    for i, a in enumerate(angles):
        d = np.array([math.cos(a), math.sin(a)])
        b = d @ np.array([cx, cy])
        disc = b * b - (cx * cx + cy * cy - radius * radius)
        if disc >= 0:
            ranges[i] = b - math.sqrt(disc)
    found = olmap.detect_beacons(ranges, angles, radius=radius)
    near = [f for f in found if math.hypot(f["x"] - cx, f["y"] - cy) < 0.02]
    assert len(near) == 1, found
    assert near[0]["returns"] >= 5


def test_mutual_localisation_equals_the_cli_and_the_geometry(cli):
    """Robot B stands at (3, 1) m with heading 40° in A's frame; each beacon is 0.07 m
    ahead of its scanner (thesis Figure 3.5). The ranges and bearings each robot measures
    follow; both the library and the CLI must give B's pose back."""
    d, bx, by, h = 0.07, 3.0, 1.0, math.radians(40.0)
    rot = lambda t: np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])
    b_beacon_in_a = np.array([bx, by]) + rot(h) @ np.array([d, 0.0])
    a_beacon_in_b = rot(-h) @ (np.array([d, 0.0]) - np.array([bx, by]))
    a, alpha = float(np.linalg.norm(b_beacon_in_a)), math.degrees(math.atan2(b_beacon_in_a[1], b_beacon_in_a[0]))
    b, beta = float(np.linalg.norm(a_beacon_in_b)), math.degrees(math.atan2(a_beacon_in_b[1], a_beacon_in_b[0]))
    report = cli("mutual", "--json", "--a", repr(a), "--alpha", repr(alpha), "--b", repr(b), "--beta", repr(beta))
    res = olmap.mutual_localisation(a, alpha, b, beta, offset=d)
    assert res == report
    assert abs(res["x_m"] - bx) < 1e-9 and abs(res["y_m"] - by) < 1e-9
    assert abs(res["heading_deg"] - 40.0) < 1e-7


def test_build_map_with_odometry_places_simulated_scans_at_the_truth(small):
    scans, truth = small.scans(0), small.truth(0)
    build = olmap.build_map(scans, odometry=small.odometry(0), mode="sequential")
    assert all(p is not None for p in build.poses)
    first = np.linalg.inv(truth[0])
    for k, (pose, t) in enumerate(zip(build.poses, truth)):
        expected = first @ t
        # The box room is 8 x 6 m with 2 cm range noise: a few centimetres (thesis §5.4's
        # simulated error at 0.1 m voxels is about a voxel at most).
        assert np.linalg.norm(pose[:3, 3] - expected[:3, 3]) < 0.1, k
    assert build.report["scans"] == 3


def test_incremental_mode_places_scans_in_the_order_given_with_the_first_as_frame(small):
    scans, odo, truth = small.scans(0), small.odometry(0), small.truth(0)
    build = olmap.build_map(scans, odometry=odo, mode="incremental")
    # Every scan places on arrival here, so the incremental mapper gives the sequential
    # mapper's poses exactly (the same placement step), and both are at the truth.
    sequential = olmap.build_map(scans, odometry=odo, mode="sequential")
    first = np.linalg.inv(truth[0])
    for k, (pose, other, t) in enumerate(zip(build.poses, sequential.poses, truth)):
        assert pose is not None and np.array_equal(pose, other), k
        assert np.linalg.norm(pose[:3, 3] - (first @ t)[:3, 3]) < 0.1, k
    # Its frame is the first scan given: naming another is refused.
    with pytest.raises(ValueError, match="first in the input"):
        olmap.build_map(scans, odometry=odo, mode="incremental", first=1)


def test_progress_callbacks_report_and_their_errors_surface(small):
    calls = []
    # With odometry: the box room is an empty 8 x 6 m box, the same turned half round, so
    # without a prior the verdict cannot tell a scan's place from its half-turned twin and
    # (rightly) leaves it out.
    olmap.build_map(small.scans(0), odometry=small.odometry(0),
                    progress=lambda *a: calls.append(a))
    assert calls and all(stage == "map" for stage, _, _ in calls)
    assert calls[-1][1] == calls[-1][2] == 3
    assert [done for _, done, _ in calls] == sorted(done for _, done, _ in calls)
    team_calls = []
    olmap.map_team(small, progress=lambda *a: team_calls.append(a))
    assert team_calls[-1] == ("team map", 6, 6)
    sim_calls = []
    olmap.simulate(world="box-room", robots=1, scans_per_robot=2, scanner="lidar",
                   progress=lambda *a: sim_calls.append(a))
    assert sim_calls[-1] == ("simulate", 2, 2)

    def boom(*_):
        raise RuntimeError("stop here")

    with pytest.raises(RuntimeError, match="stop here"):
        olmap.build_map(small.scans(0), progress=boom)
    with pytest.raises(TypeError, match="progress"):
        olmap.build_map(small.scans(0), progress=3)
