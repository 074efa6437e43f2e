#!/usr/bin/env python3
"""Max relative bond-length error |(|r| - l)| / l and max relative velocity
residual |v_ab . r_ab| / (|v_ab| |r_ab|) over every water of a LAMMPS dump
(written by in.water with -var dumpn N), at the last frame.

Usage: dump_error.py traj.dump
The same two numbers that shake's `scale` example reports as
max_rel_length_error and max_rel_velocity (measured from the states, not from
the solver's own residual)."""
import sys
import numpy as np

R_OH = 1.0
R_HH = 2.0 * np.sin(np.deg2rad(109.47) / 2.0)


def last_frame(path):
    with open(path) as f:
        lines = f.read().split("ITEM: TIMESTEP\n")[-1].splitlines()
    n = int(lines[2])
    rows = np.array([[float(v) for v in l.split()] for l in lines[8:8 + n]])
    rows = rows[np.argsort(rows[:, 0])]
    return rows[:, 3:6], rows[:, 6:9]


def water_errors(x, v, r_oh, r_hh, box=None):
    """(max relative bond-length error, max relative velocity residual) of
    waters O, H, H in consecutive rows of x and v; bonds as minimum images
    when `box` (the box's edge lengths) is given."""
    o, h1, h2 = x[0::3], x[1::3], x[2::3]
    vo, vh1, vh2 = v[0::3], v[1::3], v[2::3]
    err, vel = 0.0, 0.0
    for a, b, va, vb, l in ((o, h1, vo, vh1, r_oh), (o, h2, vo, vh2, r_oh), (h1, h2, vh1, vh2, r_hh)):
        r = a - b
        if box is not None:
            r -= box * np.round(r / box)
        dv = va - vb
        rn = np.linalg.norm(r, axis=1)
        err = max(err, np.max(np.abs(rn - l) / l))
        vel = max(vel, np.max(np.abs((r * dv).sum(1)) / (rn * np.maximum(np.linalg.norm(dv, axis=1), 1e-300))))
    return err, vel


def main():
    x, v = last_frame(sys.argv[1])
    err, vel = water_errors(x, v, R_OH, R_HH)
    print(f"max_rel_length_error={err:.2e} max_rel_velocity={vel:.2e}")


if __name__ == "__main__":
    main()
