"""OccupancyMap: counts, queries, merges and .olm/.bt round trips."""

import numpy as np
import pytest

import olmap


def wall_scan(x=2.05, n=20):
    """Points on a wall at x metres ahead, spread over y and z (one voxel deep at 0.1 m)."""
    ys, zs = np.meshgrid(np.linspace(-0.95, 0.95, n), np.linspace(0.05, 1.95, n))
    return np.column_stack([np.full(ys.size, x), ys.ravel(), zs.ravel()])


def test_endpoint_counts_and_queries():
    m = olmap.OccupancyMap(resolution=0.1)
    assert m.resolution == 0.1 and len(m) == 0
    pts = np.array([[0.05, 0.05, 0.05], [0.06, 0.04, 0.02], [1.05, 0.05, 0.05]])
    stats = m.insert_scan(pts, ray_trace=False)
    assert stats["rays"] == 3 and stats["skipped"] == 0
    assert len(m) == 2
    assert m.count_at([0.01, 0.01, 0.01]) == 2
    assert m.count_at([5.0, 5.0, 5.0]) == 0
    assert list(m.counts(pts)) == [2, 2, 1]
    centres, counts = m.voxels()
    assert centres.shape == (2, 3) and centres.dtype == np.float64
    assert np.allclose(centres, [[0.05, 0.05, 0.05], [1.05, 0.05, 0.05]])
    assert list(counts) == [2, 1]


def test_points_on_voxel_boundaries_are_found_where_they_were_inserted():
    """Points are stored as float32: 0.3 is 0.30000001 there (voxel 3 at 0.1 m) but
    0.29999999999999999 as float64 (voxel 2). Queries round the same way as insertion."""
    pts = np.array([[0.3, 0.7, 1.1], [0.6, 0.9, 0.2], [1.5, 2.3, 0.3]])
    m = olmap.OccupancyMap(resolution=0.1)
    m.insert_scan(pts, ray_trace=False)
    assert list(m.counts(pts)) == [1, 1, 1]
    assert all(m.count_at(p) == 1 for p in pts)


def test_merging_a_map_into_itself_doubles_it():
    m = olmap.OccupancyMap(0.1)
    m.insert_scan(wall_scan(2.05), ray_trace=False)
    m.merge(m)
    assert m.count_at([2.05, 0.05, 1.0]) == 2


def test_ray_tracing_clears_what_a_later_scan_sees_through():
    m = olmap.OccupancyMap(resolution=0.1)
    m.insert_scan(wall_scan(2.05))
    assert m.count_at([2.05, 0.05, 1.0]) == 1
    # The wall is gone: a scan sees 2 m farther through it.
    stats = m.insert_scan(wall_scan(4.05))
    assert stats["removed_voxels"] > 0
    assert m.count_at([2.05, 0.05, 1.0]) == 0
    assert m.count_at([4.05, 0.05, 1.0]) == 1


def test_pose_places_the_scan():
    m = olmap.OccupancyMap(resolution=0.1)
    pose = np.eye(4)
    pose[:3, 3] = [10.0, 0.0, 0.0]
    m.insert_scan(wall_scan(2.05), pose=pose, ray_trace=False)
    assert m.count_at([12.05, 0.05, 1.0]) == 1
    assert m.count_at([2.05, 0.05, 1.0]) == 0


def test_cast_ray_finds_the_first_occupied_voxel():
    m = olmap.OccupancyMap(resolution=0.1)
    m.insert_scan(wall_scan(2.05), ray_trace=False)
    hit = m.cast_ray([0.05, 0.05, 1.05], [1.0, 0.0, 0.0], max_range=10.0)
    assert hit is not None
    centre, distance = hit
    assert np.allclose(centre, [2.05, 0.05, 1.05])
    # The ray enters the voxel [2.0, 2.1) at x = 2.0: 1.95 m from its origin.
    assert abs(distance - 1.95) < 1e-9
    assert m.cast_ray([0.05, 0.05, 1.05], [-1.0, 0.0, 0.0]) is None
    assert m.cast_ray([0.05, 0.05, 1.05], [1.0, 0.0, 0.0], max_range=1.0) is None
    with pytest.raises(ValueError, match="direction"):
        m.cast_ray([0, 0, 0], [0, 0, 0])


def test_merge_adds_counts():
    a, b = olmap.OccupancyMap(0.1), olmap.OccupancyMap(0.1)
    a.insert_scan(wall_scan(2.05), ray_trace=False)
    b.insert_scan(wall_scan(2.05), ray_trace=False)
    b.insert_scan(wall_scan(3.05), ray_trace=False)
    a.merge(b)
    assert a.count_at([2.05, 0.05, 1.0]) == 2
    assert a.count_at([3.05, 0.05, 1.0]) == 1
    with pytest.raises(ValueError, match="resolution"):
        a.merge(olmap.OccupancyMap(0.2))
    strong = a.threshold(2)
    assert strong.count_at([2.05, 0.05, 1.0]) == 2
    assert strong.count_at([3.05, 0.05, 1.0]) == 0


def test_olm_and_bt_round_trips(tmp_path):
    m = olmap.OccupancyMap(resolution=0.1)
    for x in (2.05, 2.05, 3.05):
        m.insert_scan(wall_scan(x), ray_trace=False)
    m.save(tmp_path / "m.olm")
    back = olmap.OccupancyMap.load(tmp_path / "m.olm")
    assert back.source == str(tmp_path / "m.olm")
    c0, n0 = m.voxels()
    c1, n1 = back.voxels()
    assert np.array_equal(c0, c1) and np.array_equal(n0, n1)
    m.save(tmp_path / "m.bt")
    bt = olmap.OccupancyMap.load(tmp_path / "m.bt")
    assert bt.resolution == pytest.approx(0.1)
    c2, n2 = bt.voxels()
    # OctoMap stores occupancy, not olmap's counts: the same occupied voxels come back.
    assert np.allclose(c0, c2)
    assert (n2 > 0).all()
