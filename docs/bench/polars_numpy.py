#!/usr/bin/env python3
"""The vector calibration of a magcal bench file with polars + numpy, for the side-by-side comparison of the README's
Performance section (issue 11, item 2). Not part of the build or of CI.

Reads `t,mx,my,mz,temp,qw,qx,qy,qz` (the `# key: value` metadata lines skipped, `field_ned_ut` taken from them),
rotates the world field into sensor axes with each row's quaternion (scalar first, sensor to NED), and fits the 12
parameters of `B = A·m + b` by least squares on centred data: the same estimate as magcal's vector fit without its
noise correction, robust reweighting and standard errors. Prints A, b and the residual RMS.

    python3 docs/bench/polars_numpy.py independent-1000000.csv
"""
import sys

import numpy as np
import polars as pl


def main(path):
    field = None
    with open(path) as f:
        for line in f:
            if not line.startswith("#"):
                break
            if line.startswith("# field_ned_ut:"):
                field = np.array([float(v) for v in line.split(":", 1)[1].split(",")])
    df = pl.read_csv(path, comment_prefix="#")
    m = df.select(["mx", "my", "mz"]).to_numpy()
    q = df.select(["qw", "qx", "qy", "qz"]).to_numpy()
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    # R (sensor → NED) for each row; the expected field in sensor axes is Rᵀ·F.
    r = np.empty((len(q), 3, 3))
    r[:, 0, 0] = 1 - 2 * (y * y + z * z)
    r[:, 0, 1] = 2 * (x * y - w * z)
    r[:, 0, 2] = 2 * (x * z + w * y)
    r[:, 1, 0] = 2 * (x * y + w * z)
    r[:, 1, 1] = 1 - 2 * (x * x + z * z)
    r[:, 1, 2] = 2 * (y * z - w * x)
    r[:, 2, 0] = 2 * (x * z - w * y)
    r[:, 2, 1] = 2 * (y * z + w * x)
    r[:, 2, 2] = 1 - 2 * (x * x + y * y)
    expected = np.einsum("nji,j->ni", r, field)
    mm, em = m.mean(axis=0), expected.mean(axis=0)
    a_t, *_ = np.linalg.lstsq(m - mm, expected - em, rcond=None)
    a = a_t.T
    b = em - a @ mm
    resid = m @ a.T + b - expected
    print("A =", np.array2string(a, precision=5))
    print("b =", np.array2string(b, precision=4))
    print("residual RMS per axis =", np.sqrt((resid**2).mean(axis=0)))


if __name__ == "__main__":
    main(sys.argv[1])
