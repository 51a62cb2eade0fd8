"""Array inputs of every kind give the very same result: float32 and float64, C and
Fortran order, strided and transposed views, lists, PointCloud objects."""

import numpy as np
import pytest

import olmap


@pytest.fixture(scope="module")
def reference(pair):
    return olmap.align(*pair)


def readonly(points):
    a = points.copy()
    a.flags.writeable = False
    return a


def variants(points):
    """The same (N, 3) float64 points in many layouts (float32 holds them exactly: olmap
    stores points as float32)."""
    wide = np.zeros((points.shape[0], 7))
    wide[:, 2:5] = points
    doubled = np.repeat(points, 2, axis=0)
    return {
        "float64 C": np.ascontiguousarray(points),
        "float32 C": points.astype(np.float32),
        "float64 Fortran": np.asfortranarray(points),
        "float32 Fortran": np.asfortranarray(points.astype(np.float32)),
        "column slice of a wider array": wide[:, 2:5],
        "every other row": doubled[::2],
        "read-only": readonly(points),
        "big-endian float64": points.astype(">f8"),
        "PointCloud": olmap.PointCloud(points),
    }


def test_every_layout_aligns_to_the_same_pose(pair, reference):
    source, target = pair
    for name, arr in variants(source.points).items():
        if not isinstance(arr, olmap.PointCloud):
            assert arr.shape == source.points.shape
        res = olmap.align(arr, target)
        assert np.array_equal(res.T_target_source, reference.T_target_source), name
        assert res.trusted == reference.trusted, name
    for name, arr in variants(target.points).items():
        res = olmap.align(source, arr)
        assert np.array_equal(res.T_target_source, reference.T_target_source), name


def test_a_list_of_lists_and_integers_are_points():
    cloud = olmap.PointCloud([[1, 2, 3], [4, 5, 6]])
    assert cloud.points.dtype == np.float64
    assert np.array_equal(cloud.points, [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    m = olmap.OccupancyMap(0.5)
    m.insert_scan(np.array([[1, 1, 1]], dtype=np.int32), ray_trace=False)
    assert m.count_at([1.2, 1.2, 1.2]) == 1


def test_point_cloud_attributes_round_trip():
    pts = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]])
    cloud = olmap.PointCloud(pts, intensity=[0.5, 1.0, 2.0], origin=(0.1, 0.2, 0.3))
    assert len(cloud) == 3
    assert np.array_equal(cloud.points, pts)
    assert cloud.intensity.dtype == np.float32
    assert np.array_equal(cloud.intensity, np.array([0.5, 1.0, 2.0], dtype=np.float32))
    assert np.allclose(cloud.origin, [0.1, 0.2, 0.3])
    assert olmap.PointCloud(pts).intensity is None
    # A returned array is a copy: changing it does not change the cloud.
    cloud.points[0, 0] = 100.0
    assert cloud.points[0, 0] == 1.0
    moved = cloud.transformed(np.diag([1.0, 1.0, 1.0, 1.0]) + np.eye(4, k=3) * 0)
    assert np.array_equal(moved.points, pts)
    t = np.eye(4)
    t[:3, 3] = [1.0, 0.0, -1.0]
    moved = cloud.transformed(t)
    assert np.allclose(moved.points, pts + [1.0, 0.0, -1.0])
    assert np.allclose(moved.origin, [1.1, 0.2, -0.7])


def test_write_and_read_every_text_and_binary_format(tmp_path):
    rng = np.random.default_rng(7)
    pts = rng.uniform(-10, 10, size=(500, 3)).astype(np.float32).astype(np.float64)
    for ext in ["pcd", "ply", "xyz", "las", "laz"]:
        path = tmp_path / f"cloud.{ext}"
        olmap.write_cloud(path, pts)
        back = olmap.read_cloud(path)
        assert back.source == str(path)
        # LAS stores millimetre integers; the others keep float32 exactly.
        tol = 1e-3 if ext in ("las", "laz") else 0.0
        assert np.abs(back.points - pts).max() <= tol, ext
    olmap.write_cloud(tmp_path / "i.pcd", pts, intensity=np.arange(500))
    assert np.array_equal(olmap.read_cloud(tmp_path / "i.pcd").intensity, np.arange(500, dtype=np.float32))
    # format= overrides the name.
    olmap.write_cloud(tmp_path / "cloud.txt", pts, format="xyz")
    assert len(olmap.read_cloud(tmp_path / "cloud.txt", format="xyz")) == 500
