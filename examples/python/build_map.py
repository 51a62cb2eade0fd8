"""Build a map from a folder of scans and save it (.olm and OctoMap .bt).

    python examples/python/build_map.py [SCAN_FOLDER] [OUT_PREFIX]

Default: the three 3DTK example scans of the shared data, written to ./example_map.olm and
./example_map.bt.
"""

import os
import pathlib
import sys

import olmap


def main(argv):
    repo = pathlib.Path(__file__).resolve().parents[2]
    data = pathlib.Path(os.environ.get("OLMAP_DATA", repo.parent / "shared" / "data"))
    folder = pathlib.Path(argv[0]) if argv else data / "3dtk_dat"
    prefix = argv[1] if len(argv) > 1 else "example_map"
    paths = sorted(p for p in folder.iterdir() if p.suffix in {".3d", ".pcd", ".ply", ".xyz", ".las", ".laz"})
    scans = [olmap.read_cloud(p, valid_3dtk=p.suffix == ".3d") for p in paths]
    build = olmap.build_map(scans, names=[p.stem for p in paths], resolution=0.1)
    for name, pose in zip(build.names, build.poses):
        if pose is None:
            print(f"  {name}: rejected")
        else:
            x, y, z = pose[:3, 3]
            print(f"  {name}: ({x:.3f}, {y:.3f}, {z:.3f}) m")
    for r in build.report["rejected"]:
        print(f"  {r['name']} rejected: {'; '.join(r['reasons'])}")
    build.map.save(f"{prefix}.olm")
    build.map.save(f"{prefix}.bt")
    print(f"{len(build.map)} voxels at {build.map.resolution} m -> {prefix}.olm, {prefix}.bt")
    return 0 if all(p is not None for p in build.poses) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
