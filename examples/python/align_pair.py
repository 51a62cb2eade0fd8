"""Align two real scans with no initial guess and act only on a trusted result.

    python examples/python/align_pair.py [SOURCE TARGET]

Default: scan001 onto scan000 of the 3DTK example in the shared data ($OLMAP_DATA, or
../shared/data beside the repository), where the data README gives scan001 1.568 m ahead.
"""

import os
import pathlib
import sys

import numpy as np

import olmap


def main(argv):
    if len(argv) == 2:
        source_path, target_path = map(pathlib.Path, argv)
        valid = source_path.suffix == ".3d"
    else:
        repo = pathlib.Path(__file__).resolve().parents[2]
        data = pathlib.Path(os.environ.get("OLMAP_DATA", repo.parent / "shared" / "data"))
        source_path = data / "3dtk_dat" / "scan001.3d"
        target_path = data / "3dtk_dat" / "scan000.3d"
        valid = True
    source = olmap.read_cloud(source_path, valid_3dtk=valid)
    target = olmap.read_cloud(target_path, valid_3dtk=valid)
    print(f"{source}\n{target}")
    res = olmap.align(source, target, resolution=0.1, dof="xyz-yaw")
    np.set_printoptions(precision=4, suppress=True)
    print("T_target_source =\n", res.T_target_source)
    print(f"significance {res.significance:.1f}, overlap {100 * res.overlap_fraction:.1f} %, "
          f"{res.seconds:.2f} s")
    if not res.trusted:
        print("NOT trusted:", "; ".join(res.doubts))
        return 1
    print("trusted")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
