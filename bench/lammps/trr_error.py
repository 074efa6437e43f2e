#!/usr/bin/env python3
"""Max relative bond-length error |(|r| - l)| / l and max relative velocity
residual |v_ab . r_ab| / (|v_ab| |r_ab|) over every water of a GROMACS .trr
(written by mdrun from water.mdp with nstxout = nstvout = nsteps), at its
last frame, in the precision the file holds (double from gmx_d, single from
gmx). The same two numbers as dump_error.py prints for LAMMPS.

Usage: trr_error.py traj.trr
Bonds are taken as minimum images (mdrun puts atoms back in the box, so a
water may straddle its faces); lengths in nm (O-H 0.1, H-O-H 109.47 deg).
The .trr is read directly: `gmx dump` prints 5 to 8 digits."""
import struct
import sys
import numpy as np

# The same measure as LAMMPS' (this script's directory is on sys.path).
from dump_error import water_errors

R_OH = 0.1
R_HH = 2.0 * R_OH * np.sin(np.deg2rad(109.47) / 2.0)
TRR_MAGIC = 1993


def frames(path):
    """Yield (box, x, v) for each frame of a .trr (XDR, big-endian)."""
    data = open(path, "rb").read()
    pos = 0

    def ints(k):
        nonlocal pos
        vals = struct.unpack_from(f">{k}i", data, pos)
        pos += 4 * k
        return vals

    while pos < len(data):
        magic, _slen, nchar = ints(3)
        if magic != TRR_MAGIC:
            sys.exit(f"trr_error.py: {path}: not a .trr (magic {magic})")
        pos += (nchar + 3) // 4 * 4                       # version string, padded
        (ir, e, box, vir, pres, top, sym, xs, vs, fs, natoms, _step, _nre) = ints(13)
        size = next((s // (3 * natoms) for s in (xs, vs, fs) if s), None) or box // 9
        real = {4: ">f", 8: ">d"}[size]
        pos += 2 * size                                   # t, lambda
        pos += ir + e + top + sym                         # unused blocks (zero in mdrun output)

        def reals(nbytes, shape):
            nonlocal pos
            if not nbytes:
                return None
            a = np.frombuffer(data, dtype=real, count=nbytes // size, offset=pos).astype(float)
            pos += nbytes
            return a.reshape(shape)

        b = reals(box, (3, 3))
        reals(vir, (3, 3))
        reals(pres, (3, 3))
        x = reals(xs, (natoms, 3))
        v = reals(vs, (natoms, 3))
        reals(fs, (natoms, 3))
        yield b, x, v, size


def main():
    last = None
    for fr in frames(sys.argv[1]):
        if fr[1] is not None and fr[2] is not None:
            last = fr
    if last is None:
        sys.exit(f"trr_error.py: {sys.argv[1]}: no frame with both x and v")
    box, x, v, size = last
    err, vel = water_errors(x, v, R_OH, R_HH, box=np.diag(box))
    print(f"max_rel_length_error={err:.2e} max_rel_velocity={vel:.2e} precision={'double' if size == 8 else 'single'}")


if __name__ == "__main__":
    main()
