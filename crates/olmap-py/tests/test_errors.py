"""Bad inputs raise the right exception types with messages naming what was wrong."""

import numpy as np
import pytest

import olmap

GOOD = np.random.default_rng(1).uniform(0, 5, size=(200, 3))


def test_bad_point_arrays_are_value_errors():
    with pytest.raises(ValueError, match=r"source: expected an \(N, 3\) array.*shape \(5, 2\)"):
        olmap.align(np.zeros((5, 2)), GOOD)
    with pytest.raises(ValueError, match=r"target: expected an olmap.PointCloud or an \(N, 3\) array"):
        olmap.align(GOOD, "not points")
    bad = GOOD.copy()
    bad[17, 1] = np.nan
    with pytest.raises(ValueError, match=r"points: row 17 is not finite"):
        olmap.PointCloud(bad)
    with pytest.raises(ValueError, match=r"intensity: 2 values for 200 points"):
        olmap.PointCloud(GOOD, intensity=[1.0, 2.0])
    with pytest.raises(ValueError, match=r"scans\[1\]"):
        olmap.build_map([GOOD, np.zeros((3, 4))])


def test_bad_parameters_are_value_errors():
    with pytest.raises(ValueError, match=r"dof: expected"):
        olmap.align(GOOD, GOOD, dof="xyz")
    with pytest.raises(ValueError, match=r"threads: expected 0"):
        olmap.align(GOOD, GOOD, threads=-1)
    with pytest.raises(ValueError, match=r"window: expected 3 numbers"):
        olmap.align(GOOD, GOOD, guess=np.eye(4), window=[1.0, 2.0])
    with pytest.raises(ValueError, match=r"max_tilt|tilt"):
        olmap.align(GOOD, GOOD, dof="6dof", max_tilt=200.0)
    with pytest.raises(ValueError, match=r"not finite in float32"):
        olmap.PointCloud([[1e39, 0.0, 0.0]])
    with pytest.raises(ValueError, match=r"window needs guess"):
        olmap.align(GOOD, GOOD, window=(1.0, 0.1, 10.0))
    with pytest.raises(ValueError, match=r"search: expected"):
        olmap.align(GOOD, GOOD, search="fast")
    with pytest.raises(ValueError, match=r"resolution"):
        olmap.align(GOOD, GOOD, resolution=-0.1)
    skew = np.eye(4)
    skew[0, 1] = 0.5
    with pytest.raises(ValueError, match=r"guess"):
        olmap.align(GOOD, GOOD, guess=skew)
    with pytest.raises(ValueError, match=r"guess: expected a 4x4"):
        olmap.align(GOOD, GOOD, guess=np.eye(3))
    with pytest.raises(ValueError):
        olmap.OccupancyMap(resolution=0.0)
    with pytest.raises(ValueError, match=r"odometry: 1 poses for 2 scans"):
        olmap.build_map([GOOD, GOOD], odometry=[np.eye(4)])
    with pytest.raises(ValueError, match=r"register_band|z_min"):
        olmap.build_map([GOOD, GOOD], register_band=(2.0, 1.0))
    with pytest.raises(ValueError, match=r"mode: expected"):
        olmap.build_map([GOOD, GOOD], mode="fast")
    with pytest.raises(ValueError, match=r"world: expected one of"):
        olmap.simulate(world="moon")
    with pytest.raises(ValueError, match=r"angles: a laser scan's beams are evenly spaced"):
        olmap.detect_beacons([1.0, 1.0, 1.0], [0.0, 0.1, 0.5])
    with pytest.raises(ValueError, match=r"mutual localisation"):
        olmap.mutual_localisation(2.0, 10.0, 5.0, 20.0)  # separations disagree by metres


def test_an_empty_target_is_a_value_error():
    with pytest.raises(ValueError, match=r"empty"):
        olmap.align(GOOD, np.zeros((0, 3)))


def test_file_problems_are_os_errors_naming_the_file(tmp_path):
    missing = tmp_path / "missing.pcd"
    with pytest.raises(FileNotFoundError, match="missing.pcd"):
        olmap.read_cloud(missing)
    with pytest.raises(FileNotFoundError, match="missing.olm"):
        olmap.OccupancyMap.load(tmp_path / "missing.olm")
    with pytest.raises(IsADirectoryError):
        olmap.read_cloud(tmp_path)
    broken = tmp_path / "broken.pcd"
    broken.write_text("# .PCD v0.7\nVERSION 0.7\nFIELDS x y\nSIZE 4 4\n")
    with pytest.raises(olmap.FormatError, match="broken.pcd") as e:
        olmap.read_cloud(broken)
    assert isinstance(e.value, OSError)
    with pytest.raises(OSError, match="nowhere"):
        olmap.write_cloud(tmp_path / "nowhere" / "x.pcd", GOOD)
    with pytest.raises(OSError, match="nowhere"):
        olmap.OccupancyMap(0.1).save(tmp_path / "nowhere" / "m.olm")
    # A map file is named .olm or .bt: another name is an unknown format.
    with pytest.raises(olmap.FormatError, match=r"\.olm"):
        olmap.OccupancyMap(0.1).save(tmp_path / "m.txt")
    with pytest.raises(ValueError, match=r"format: unknown point-cloud format"):
        olmap.read_cloud(broken, format="docx")


def test_a_point_beyond_the_voxel_key_range_is_too_large():
    far = np.array([[1e12, 0.0, 0.0]])
    with pytest.raises(olmap.TooLargeError) as e:
        olmap.OccupancyMap(0.01).insert_scan(far, ray_trace=False)
    assert isinstance(e.value, ValueError)


def test_more_threads_than_cores_warn_and_still_work():
    with pytest.warns(RuntimeWarning, match="threads"):
        m = olmap.OccupancyMap(0.5)
        m.insert_scan(GOOD, threads=100_000)
    assert len(m) > 0
