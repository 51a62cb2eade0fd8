"""FreeSpaceMap: unknown / free / occupied at OctoMap's semantics, numpy in and out."""

import math

import numpy as np
import pytest

import olmap


def wall_scan(x=2.05, n=20):
    """Points on a wall x metres ahead, spread over y and z."""
    ys, zs = np.meshgrid(np.linspace(-0.95, 0.95, n), np.linspace(0.05, 1.95, n))
    return np.column_stack([np.full(ys.size, x), ys.ravel(), zs.ravel()])


def test_a_wall_is_occupied_the_space_before_it_free_and_behind_it_unknown():
    m = olmap.FreeSpaceMap(resolution=0.1)
    assert m.resolution == 0.1 and len(m) == 0
    wall = wall_scan()
    stats = m.insert_scan(wall)
    assert stats["rays"] == 400 and stats["skipped"] == 0 and stats["truncated"] == 0
    # Every endpoint is occupied (OctoMap: one hit is logit(0.7) > 0).
    assert (m.states(wall) == olmap.FreeSpaceMap.OCCUPIED).all()
    probe = np.array([[1.0, 0.0, 0.5], [3.0, 0.0, 0.5], [-1.0, 0.0, 0.5]])
    assert list(m.states(probe)) == [m.FREE, m.UNKNOWN, m.UNKNOWN]
    p = m.probabilities(probe)
    assert abs(p[0] - 0.4) < 1e-3 and math.isnan(p[1])
    assert abs(m.probabilities(wall[:1])[0] - 0.7) < 1e-3
    s = m.stats()
    assert s["voxels"] == len(m) == s["free"] + s["occupied"]
    centres, states = m.voxels()
    assert centres.shape == (len(m), 3) and states.dtype == np.uint8
    assert (states == m.OCCUPIED).sum() == s["occupied"]
    # Rays through the wall's points to twice as far: one hit (logit(0.7) = 0.847) is
    # still occupied after two misses (0.847 - 2 x 0.405 = 0.036) and free after three.
    through = wall * 2.0
    for i in range(3):
        assert (m.states(wall) == m.OCCUPIED).all(), i
        m.insert_scan(through)
    assert (m.states(wall) == m.FREE).all()


def test_same_map_for_any_thread_count_and_bt_round_trip(tmp_path):
    rng = np.random.default_rng(7)
    pts = rng.uniform([-4, -4, -1], [4, 4, 2], size=(5000, 3))
    maps = []
    for threads in (1, 2):
        m = olmap.FreeSpaceMap(resolution=0.1, max_range=3.0)
        m.insert_scan(pts, threads=threads)
        maps.append(m)
    (c1, s1), (c2, s2) = maps[0].voxels(), maps[1].voxels()
    assert np.array_equal(c1, c2) and np.array_equal(s1, s2)
    path = tmp_path / "free.bt"
    maps[0].save_bt(path)
    # OccupancyMap reads the occupied leaves of the tree: exactly the occupied voxels.
    occupied = olmap.OccupancyMap.load(path)
    assert len(occupied) == maps[0].stats()["occupied"]


def test_bad_models_and_scans_are_refused():
    for bad in (dict(prob_hit=0.3), dict(prob_miss=0.6), dict(clamp_max=0.4), dict(max_range=0.0),
                dict(resolution=-1.0)):
        with pytest.raises(ValueError):
            olmap.FreeSpaceMap(**bad)
    m = olmap.FreeSpaceMap()
    with pytest.raises(ValueError):
        m.insert_scan(np.zeros((3, 2)))
    far = np.eye(4)
    far[0, 3] = 1e9
    with pytest.raises(ValueError):
        m.insert_scan(wall_scan(), pose=far)
    assert len(m) == 0
