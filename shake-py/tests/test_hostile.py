"""Hostile inputs to the Python package, drawn at random (seeded): every
case must return finite results on M, or raise a subclass of
``geoshake.ShakeError`` (or, for a scalar argument of the wrong Python
type, the ``TypeError``/``OverflowError`` of the argument conversion).

Drawn per case (``numpy.random.default_rng([seed, i])``, so a case does
not depend on the ones before it):

- ``declare``: a valid declaration garbled (characters deleted, inserted,
  replaced, segments repeated, tokens of the grammar inserted), deeply
  nested or very long expressions, parameters missing, extra, hostile or
  of the wrong type; a declaration that is accepted is run for a few steps;
- ``run``/``ensemble``: a compiled model or a declared pendulum, z0 of the
  wrong dtype (complex, bool, object, str), shape or size, NaN or ±∞
  entries, far from M; h, steps, time, stride, method, base, tolerances
  and the iteration budget hostile (0, negative, NaN, ±∞, huge, 2⁶⁴, the
  wrong type), unknown keyword arguments;
- ``Bonds``: masses, pairs (out of range, self-bonds, duplicates, wrong
  shape or dtype) and lengths hostile, then ``shake_positions`` and
  ``project_momenta`` on arrays that are NaN, far, of the wrong shape,
  dtype or layout;
- ``geoshake.ase.FixBondLengths`` (when ASE is installed): the same
  through ASE's ``Atoms`` and the constraint's ``adjust_*`` calls;
- ``particles``: rigid dimers from ``declare_particles`` with a forces
  callable that raises, returns NaN or the wrong shape or type, or calls
  back into its own system, a thermostat hostile or of the wrong type,
  then ``step``, ``run``, ``ensemble``, ``potential_energy`` and
  ``constraint_forces`` on hostile arrays.

Verdicts: ok, typed (a ``ShakeError``, or a conversion error of a scalar
drawn with the wrong type), silent (a result that is not finite, off M,
at times other than k·h, or an input array changed by a failed call), panic
(a Rust panic surfacing as ``PanicException``, or the interpreter dying),
hang (no answer within ``DEADLINE`` seconds) and other (any other
exception). The cases run in a child interpreter that reports each
verdict on a line; the parent restarts it after a crash or a hang, so
either is counted, not fatal. The test fails unless silent, panic, hang
and other are all 0.

Quick mode (the default, in ``shake-py/test.sh``): ``GEOSHAKE_FUZZ_CASES``
cases (default 2000) per kind; long mode: set it, e.g.
``GEOSHAKE_FUZZ_CASES=10000 python -m pytest -q -s tests/test_hostile.py``.
``GEOSHAKE_FUZZ_SEED`` (default 13) changes the stream.
"""

import json
import math
import os
import queue
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

CASES = int(os.environ.get("GEOSHAKE_FUZZ_CASES", "2000"))
SEED = int(os.environ.get("GEOSHAKE_FUZZ_SEED", "13"))
DEADLINE = 20.0
EPS = np.finfo(float).eps

PENDULUM = """
struct Pendulum {
    parameters { length, gravity }
    dof q[2], p[2];
    hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
    constraints { rod: q[0]^2 + q[1]^2 - length^2 }
}"""

TOKENS = [
    "(", ")", "{", "}", "[", "]", ";", ",", "^", "*", "/", "+", "-", "=",
    "q[0]", "p[1]", "q[7]", "sqrt(", "exp(", "ln(", "sin(", "let x =",
    "sum(k in 0..3)", "hamiltonian", "constraints", "dof", "parameters",
    "struct", "1e308", "1e-320", "NaN", "0", "-0", "\u00e9", "\x00", "\n",
    "length", "gravity", "//", "/*", "*/", '"', "'",
]

SPECIAL = [0.0, -0.0, math.nan, math.inf, -math.inf, 1e300, -1e300, 1e-300,
           5e-324, sys.float_info.max, -1.0]


# ---------------------------------------------------------------------------
# Drawing
# ---------------------------------------------------------------------------


def hostile_float(rng, lo, hi):
    u = rng.random()
    if u < 0.75:
        return float(rng.uniform(lo, hi))
    if u < 0.9:
        return SPECIAL[rng.integers(len(SPECIAL))]
    return float((-1) ** rng.integers(2) * 10.0 ** rng.integers(-320, 309))


class Draw:
    """One case's random choices, and whether any scalar was drawn of a
    type the signature does not take (then TypeError/OverflowError of the
    conversion is a deserved refusal)."""

    def __init__(self, rng):
        self.rng = rng
        self.wrong_type = False

    def pick(self, options):
        return options[self.rng.integers(len(options))]

    def chance(self, p):
        return self.rng.random() < p

    def scalar(self, normal, ints=False):
        """A scalar argument: mostly ``normal()``, else hostile or of the
        wrong type."""
        u = self.rng.random()
        if u < 0.9:
            return normal()
        if u < 0.96:
            if ints:
                v = self.pick([0, -1, 2**53, 2**53 + 1, 2**63, 2**64, 2**70, 10**6])
                if v < 0 or v >= 2**64:
                    self.wrong_type = True  # OverflowError of u64/usize
                return v
            return hostile_float(self.rng, -1e3, 1e3)
        self.wrong_type = True
        return self.pick(["1", None, [1.0], 1 + 2j, 3.5, object(), b"x"])


def garble(rng, src):
    s = list(src)
    for _ in range(rng.integers(1, 6)):
        op = rng.integers(5)
        i = int(rng.integers(len(s) + 1))
        if op == 0 and s:
            del s[min(i, len(s) - 1)]
        elif op == 1:
            s.insert(i, chr(int(rng.integers(1, 0x2FF))))
        elif op == 2 and s:
            s[min(i, len(s) - 1)] = TOKENS[rng.integers(len(TOKENS))]
        elif op == 3:
            s.insert(i, " " + TOKENS[rng.integers(len(TOKENS))] + " ")
        else:
            j = int(rng.integers(len(s) + 1))
            a, b = min(i, j), max(i, j)
            s[a:a] = s[a:b]
    return "".join(s)


def big_expression(rng):
    kind = rng.integers(4)
    n = int(rng.integers(1, 400))
    if kind == 0:
        return "(" * n + "q[0]" + ")" * n
    if kind == 1:
        return " + ".join(f"{rng.uniform(-2, 2):.3f} * q[{k % 2}]^2" for k in range(n))
    if kind == 2:
        return "-" * n + "q[1]"
    return "^".join(["q[0]"] * min(n, 40))


def declare_case(d):
    rng = d.rng
    u = rng.random()
    if u < 0.6:
        src = garble(rng, PENDULUM)
    elif u < 0.85:
        src = PENDULUM.replace("gravity * q[1]", f"gravity * q[1] + 0 * ({big_expression(rng)})")
    else:
        src = "".join(TOKENS[k] for k in rng.integers(len(TOKENS), size=rng.integers(0, 60)))
    params = {}
    for name in ["length", "gravity", "extra"]:
        if name == "extra" and not d.chance(0.1):
            continue
        if d.chance(0.05):
            continue  # missing
        params[name] = d.scalar(lambda: float(rng.uniform(0.5, 2.0)))
    return src, params


def model_system(d):
    import geoshake

    rng = d.rng
    if d.chance(0.3):
        return geoshake.declare(PENDULUM, length=1.0, gravity=9.81)
    name = d.pick(["Pendulum", "SphericalPendulum", "DoublePendulum", "HopfGravity", "Chain4"])
    params = {
        "Pendulum": ["length", "gravity"],
        "SphericalPendulum": ["length", "gravity"],
        "DoublePendulum": ["l1", "l2", "gravity"],
        "HopfGravity": ["g0", "g1", "radius2"],
        "Chain4": ["length", "gravity"],
    }[name]
    values = {p: (hostile_float(rng, 0.5, 2.0) if d.chance(0.1) else float(rng.uniform(0.5, 2.0)))
              for p in params}
    return getattr(geoshake.models, name)(**values)


def z0_of(d, system, rows=None):
    rng = d.rng
    n = 2 * system.dof
    shape = (n,) if rows is None else (rows, n)
    z = rng.normal(size=shape)
    u = rng.random()
    if u < 0.7:
        # A state near M: a projection onto M^H of a random point is asked
        # for by project=True; far ones are refused or projected.
        pass
    elif u < 0.75:
        z = z * 10.0 ** rng.integers(-8, 8)
    elif u < 0.8 and z.size:
        z.flat[rng.integers(z.size)] = d.pick([math.nan, math.inf, -math.inf])
    elif u < 0.84:
        z = z.astype(d.pick([np.complex128, np.bool_, object, str, np.float32, np.int64]))
    elif u < 0.88:
        bad = list(shape)
        bad[-1] += int(rng.integers(-2, 3)) or 1
        z = rng.normal(size=tuple(bad))
    elif u < 0.91:
        z = z.tolist()
    elif u < 0.94:
        z = d.pick([None, "z", 1.0, [], [[1.0, 2.0], [3.0]], np.zeros((0,))])
    elif u < 0.96:
        z = np.zeros(shape)
    else:
        z = np.asfortranarray(np.stack([z, z], axis=-1))[..., 0] if z.ndim else z
    return z


def run_kwargs(d):
    rng = d.rng
    kw = {}
    if d.chance(0.5):
        kw["steps"] = d.scalar(lambda: int(rng.integers(0, 30)), ints=True)
    else:
        kw["time"] = d.scalar(lambda: float(rng.uniform(-1, 2)))
    if d.chance(0.1):
        kw.pop("steps", None) if d.chance(0.5) else kw.update(steps=3, time=0.3)
    if d.chance(0.5):
        kw["method"] = d.pick(["rattle"] * 4 + ["shake"] * 4 + ["RATTLE", "", "verlet", None])
        if kw["method"] is None:
            d.wrong_type = True
    if d.chance(0.5):
        kw["base"] = d.pick(["midpoint", "verlet", "euler"] * 3 + ["rk4", "", None])
        if kw["base"] is None:
            d.wrong_type = True
    if d.chance(0.3):
        kw["stride"] = d.scalar(lambda: int(rng.integers(1, 5)), ints=True)
    if d.chance(0.3):
        kw["project"] = d.pick([True, False])
    if d.chance(0.2):
        kw["constraint_tolerance"] = d.scalar(lambda: 10.0 ** rng.uniform(-14, -4))
    if d.chance(0.2):
        kw["newton_tolerance"] = d.scalar(lambda: 10.0 ** rng.uniform(-16, -10))
    if d.chance(0.2):
        kw["max_iterations"] = d.scalar(lambda: int(rng.integers(0, 60)), ints=True)
    if d.chance(0.03):
        kw[d.pick(["step", "tolerance", "method_", "h"])] = 1
        d.wrong_type = True  # an unknown (or repeated) keyword: TypeError
    return kw


# ---------------------------------------------------------------------------
# Judging
# ---------------------------------------------------------------------------


class Silent(Exception):
    pass


def on_m(system, traj, first_given, ctol, ntol):
    """Every row finite, |g| within the step bound relative to the state's
    size; the first row (when stored as given, project=False) within the
    constraint tolerance's bound instead."""
    traj = np.asarray(traj)
    if not np.all(np.isfinite(traj)):
        raise Silent("non-finite state in an Ok result")
    for i, z in enumerate(traj):
        g = np.abs(system.constraints(z))
        s = 1.0 + np.max(np.abs(z)) ** 2
        if i == 0 and first_given:
            bound = 4.0 * max(ctol, 1e-12) * s
        else:
            bound = max(1e-12, 16.0 * ntol) * s
        if g.size and not np.max(g) <= bound:
            raise Silent(f"row {i}: |g| = {np.max(g):.2e} > {bound:.2e}")


def judge_result(system, res, h, kw):
    if len(res) == 0:
        raise Silent("empty trajectory")
    ctol = kw.get("constraint_tolerance") or 1e-8
    ntol = kw.get("newton_tolerance") or 1e-14
    on_m(system, res.trajectory, kw.get("project", True) is False, ctol, ntol)
    times = np.asarray(res.times)
    want = np.asarray(res.steps).astype(float) * h
    if not np.array_equal(times, want):
        raise Silent(f"times {times[:4]} are not k·h {want[:4]}")


def judge_error(e):
    """A run's error: its partial trajectory ends at step k − 1."""
    k = getattr(e, "step", None)
    steps = getattr(e, "steps", None)
    traj = getattr(e, "trajectory", None)
    if traj is not None and np.size(traj) and not np.all(np.isfinite(traj)):
        raise Silent(f"{type(e).__name__}: non-finite partial trajectory")
    if k is not None and k >= 1 and steps is not None and len(steps):
        if int(steps[-1]) + 1 != int(k):
            raise Silent(f"{type(e).__name__} at step {k}, last stored step {steps[-1]}")


def bonds_on_m(pairs, lengths, x, tol):
    d = x[pairs[:, 1]] - x[pairs[:, 0]]
    # |d| scaled first: differences of 1e200 must not overflow to ∞.
    big = np.max(np.abs(d), axis=1, keepdims=True)
    big[big == 0] = 1.0
    r = big[:, 0] * np.sqrt(((d / big) ** 2).sum(1))
    l = np.abs(lengths)
    rel = np.abs(r - l) / l
    if not np.all(np.isfinite(x)):
        raise Silent("shake_positions: Ok with non-finite positions")
    # The round-off of a bond's coordinates, at which the solver accepts a
    # stalled iteration: min(4ε ‖(x_i, x_j)‖ / extent, √ε), extent = r / √2
    # (geoshake_runtime's tolerance::roundoff_floor).
    with np.errstate(divide="ignore", invalid="ignore"):
        n2 = (x[pairs[:, 0]] ** 2).sum(1) + (x[pairs[:, 1]] ** 2).sum(1)
        floor = np.minimum(4 * EPS * np.sqrt(2 * n2) / r, np.sqrt(EPS))
    floor = np.nan_to_num(floor, nan=0.0)
    if rel.size and not np.all(rel <= 2 * np.maximum(tol, floor) + 16 * EPS):
        raise Silent(
            f"shake_positions: Ok with a bond off by {np.max(rel):.2e} (tol {tol:.1e}, "
            f"|x| up to {np.max(np.abs(x)):.1e}, floor up to {np.max(floor):.1e})"
        )


def bonds_hidden(pairs, masses, q, p, p_in):
    if not np.all(np.isfinite(p)):
        raise Silent("project_momenta: Ok with non-finite momenta")
    s = max(np.max(np.abs(p), initial=0.0), np.max(np.abs(p_in), initial=0.0))
    # Momenta within 2⁵² of the subnormal range hold too few bits for a
    # relative test (5e-324 has one).
    if s < np.finfo(float).tiny / EPS or not np.isfinite(s):
        return
    m = np.asarray(masses, dtype=float)[:, None]
    with np.errstate(all="ignore"):
        v, v_in = (p / s) / m, (p_in / s) / m
    r = q[pairs[:, 1]] - q[pairs[:, 0]]
    rn = np.sqrt((r**2).sum(1))
    dv, dv_in = v[pairs[:, 1]] - v[pairs[:, 0]], v_in[pairs[:, 1]] - v_in[pairs[:, 0]]
    scale = np.maximum(np.sqrt((dv**2).sum(1)), np.sqrt((dv_in**2).sum(1)))
    ok = (rn > 0) & (scale > 0) & np.isfinite(scale) & np.isfinite(rn)
    rel = np.abs((r * dv).sum(1))[ok] / (rn[ok] * scale[ok])
    if rel.size and not np.max(rel) <= 4 * 1.4901161193847656e-8:
        raise Silent(f"project_momenta: hidden residual {np.max(rel):.2e}")


# ---------------------------------------------------------------------------
# The cases
# ---------------------------------------------------------------------------


def case_declare(d):
    import geoshake

    src, params = declare_case(d)
    system = geoshake.declare(src, **params)
    z0 = np.array([1.0, 0.0, 0.0, 0.3])[: 2 * system.dof]
    if z0.size != 2 * system.dof:
        return
    res = geoshake.run(system, z0, 0.01, steps=5)
    judge_result(system, res, 0.01, {})


def case_run(d):
    import geoshake

    system = model_system(d)
    h = d.scalar(lambda: float(d.rng.choice([-1, 1]) * d.rng.uniform(0.005, 0.1)))
    kw = run_kwargs(d)
    if "steps" not in kw and "time" not in kw:
        kw["steps"] = 3
    # A valid run of more than 2·10³ steps is a long run, not a hostile
    # input (the deadline is for hangs): cut to its last digits.
    if isinstance(kw.get("steps"), int) and 2000 < kw["steps"] <= 2**53:
        kw["steps"] %= 100
    if isinstance(kw.get("time"), float) and isinstance(h, float) and h != 0:
        n = kw["time"] / h
        if n > 2000 and math.isfinite(n):
            kw["time"] = h * (int(n) % 100)
    if d.chance(0.3):
        rows = int(d.rng.integers(0, 4))
        z0s = z0_of(d, system, rows=rows)
        errors = d.pick(["raise", "return", "return", "ignore"])
        outs = geoshake.ensemble(system, z0s, h, errors=errors, **kw)
        for r in outs:
            if isinstance(r, geoshake.ShakeError):
                judge_error(r)
            else:
                judge_result(system, r, h, kw)
        return
    z0 = z0_of(d, system)
    try:
        res = geoshake.run(system, z0, h, **kw)
    except geoshake.ShakeError as e:
        judge_error(e)
        raise
    judge_result(system, res, h, kw)


def bonds_arrays(d):
    rng = d.rng
    n = int(rng.integers(2, 9))
    masses = rng.uniform(1.0, 16.0, size=n)
    if d.chance(0.15):
        masses[rng.integers(n)] = hostile_float(rng, 1.0, 16.0)
    q = rng.normal(size=(n, 3)) * 2.0
    pairs = np.array([(a, a + 1) for a in range(n - 1)])
    u = rng.random()
    if u < 0.05:
        pairs = np.vstack([pairs, [0, n + int(rng.integers(0, 3))]])
    elif u < 0.08:
        pairs = np.vstack([pairs, [1, 1]])
    elif u < 0.11:
        pairs = np.vstack([pairs, pairs[:1]])
    elif u < 0.13:
        pairs = np.vstack([pairs, [-1, 0]])
    elif u < 0.15:
        pairs = pairs.astype(float) + 0.5
        d.wrong_type = True  # Bonds takes integer pairs: the conversion's TypeError
    elif u < 0.17:
        pairs = pairs.ravel()
        d.wrong_type = True
    elif u < 0.2 and n >= 3:
        pairs = np.vstack([pairs, [0, 2]])  # a triangle
    d_ = q[np.clip(pairs[..., 1].astype(int), 0, n - 1)] - q[np.clip(pairs[..., 0].astype(int), 0, n - 1)] \
        if pairs.ndim == 2 else np.ones((1, 3))
    lengths = np.sqrt((d_**2).sum(-1))
    if d.chance(0.1):
        lengths = lengths.copy()
        lengths[rng.integers(len(lengths))] = hostile_float(rng, 0.5, 2.0)
    if d.chance(0.03):
        lengths = lengths[:-1]
    if d.chance(0.03):
        masses = masses[:-1]
    return masses, pairs, lengths, q


def case_bonds(d):
    import geoshake

    rng = d.rng
    masses, pairs, lengths, q = bonds_arrays(d)
    kw = {}
    if d.chance(0.3):
        kw["tolerance"] = d.scalar(lambda: 10.0 ** rng.uniform(-15, -6))
    if d.chance(0.2):
        kw["max_iterations"] = d.scalar(lambda: int(rng.integers(0, 60)), ints=True)
    tol = kw.get("tolerance", 1e-13)
    bonds = geoshake.Bonds(masses, pairs, lengths, **kw)
    q0 = q.copy()
    u = rng.random()
    if u < 0.1:
        q0.flat[rng.integers(q0.size)] = math.nan
    elif u < 0.15:
        q0 = q0 * 1e6
    elif u < 0.2:
        q0 = q0[:-1]
    x = q0 + 1e-3 * rng.normal(size=q0.shape) * hostile_float(rng, 0.1, 10.0)
    v = rng.random()
    if v < 0.05:
        x = x.astype(np.float32)
    elif v < 0.1:
        x = np.asfortranarray(x)
    elif v < 0.13:
        x = x.tolist()
    elif v < 0.16:
        x = x[::2]
    if d.chance(0.5):
        given = np.array(x, dtype=object, copy=True) if isinstance(x, list) else np.copy(x)
        try:
            bonds.shake_positions(q0, x)
        except geoshake.ShakeError:
            if isinstance(x, np.ndarray) and not np.array_equal(x, given, equal_nan=True):
                raise Silent("shake_positions failed but changed x")
            raise
        x = np.asarray(x, dtype=float)
        bonds_on_m(np.asarray(pairs).reshape(-1, 2).astype(int), np.asarray(lengths, float), x, tol)
    else:
        p = rng.normal(size=q0.shape) * hostile_float(rng, 0.1, 10.0)
        given = np.copy(p)
        try:
            bonds.project_momenta(q0, p)
        except geoshake.ShakeError:
            if not np.array_equal(p, given, equal_nan=True):
                raise Silent("project_momenta failed but changed p")
            raise
        bonds_hidden(np.asarray(pairs).reshape(-1, 2).astype(int), masses, q0, p, given)


def case_ase(d):
    try:
        from ase import Atoms
    except ImportError:
        return "skip"
    import geoshake
    from geoshake.ase import FixBondLengths

    rng = d.rng
    masses, pairs, lengths, q = bonds_arrays(d)
    tol = 1e-13
    if d.chance(0.2):
        tol = d.scalar(lambda: 10.0 ** rng.uniform(-15, -6))
    if len(masses) != len(q):
        masses = np.resize(masses, len(q))
    atoms = Atoms(positions=q, masses=np.abs(np.nan_to_num(masses)) + 0.0)
    atoms.set_masses(masses)
    c = FixBondLengths(pairs, tolerance=tol, bondlengths=lengths if d.chance(0.5) else None)
    new = q + 1e-3 * rng.normal(size=q.shape)
    if d.chance(0.1):
        new.flat[rng.integers(new.size)] = math.nan
    if d.chance(0.5):
        c.adjust_positions(atoms, new)
        if not np.all(np.isfinite(new)):
            raise Silent("adjust_positions: Ok with non-finite positions")
    else:
        p = rng.normal(size=q.shape)
        given = p.copy()
        c.adjust_momenta(atoms, p)
        bonds_hidden(np.asarray(c.pairs).reshape(-1, 2).astype(int), masses, q, p, given)


DIMERS = """struct Dimers {
    particles x[3];
    constraints { bond[k in bonds(a, b; length)]: norm2(x[a] - x[b]) - length^2 }
}"""


class UserForceError(Exception):
    """What a hostile forces callable raises on purpose."""


def hostile_forces(d, n):
    """A forces callable for n particles: a harmonic trap, or (from a
    random call on) one that raises, returns NaN or ∞, the wrong shape,
    type or dtype, or calls back into the system it belongs to; or no
    callable at all. Returns (forces, how)."""
    rng = d.rng
    k = float(rng.uniform(0.1, 2.0))
    how = d.pick(["trap"] * 8 + ["raise", "nan", "inf", "shape", "flat", "triple", "list",
                                 "strings", "object", "none", "complex", "reenter"])
    after = int(rng.integers(1, 6))
    calls = [0]
    owner = {}

    def forces(q):
        calls[0] += 1
        if how == "trap" or calls[0] < after:
            return 0.5 * k * float(np.sum(q * q)), -k * q
        if how == "raise":
            raise UserForceError("deliberate")
        if how == "reenter":
            owner["system"].step(q, q)
        return {
            "nan": lambda: (0.0, np.full_like(q, math.nan)),
            "inf": lambda: (math.inf, -k * q),
            "shape": lambda: (0.0, -k * q[:-1]),
            "flat": lambda: (0.0, (-k * q).ravel()),
            "triple": lambda: (0.0, -k * q, 1),
            "list": lambda: [0.0, -k * q],
            "strings": lambda: ("V", "F"),
            "object": lambda: object(),
            "none": lambda: None,
            "complex": lambda: (0.0, -k * q + 0j),
            "reenter": lambda: (0.0, -k * q),
        }[how]()

    if d.chance(0.04):
        return d.pick([3.0, "trap", np.zeros((n, 3))]), "noncallable"
    return forces, how, owner


def particles_on_m(q, bonds, tol=1e-8):
    q = np.asarray(q)
    if not np.all(np.isfinite(q)):
        raise Silent("non-finite positions in a result")
    a, b = bonds[:, 0].astype(int), bonds[:, 1].astype(int)
    r = np.linalg.norm(q[..., a, :] - q[..., b, :], axis=-1)
    if r.size and not np.abs(r - 1.0).max() <= tol:
        raise Silent(f"a bond off by {np.abs(r - 1.0).max():.2e}")


def case_particles(d):
    """Rigid dimers (and maybe a free particle) declared from a string,
    with a hostile forces callable, thermostat, step size and method, then
    one of step, run, ensemble, potential_energy and constraint_forces on
    arrays that may be NaN, far, or of the wrong shape, dtype or count.
    The callable's own UserForceError is a deserved refusal."""
    import geoshake

    rng = d.rng
    count = int(rng.integers(1, 4))
    n = 2 * count + int(rng.integers(0, 2))
    masses = rng.uniform(1.0, 4.0, size=n)
    if d.chance(0.05):
        masses[rng.integers(n)] = hostile_float(rng, 1.0, 4.0)
    bonds = np.array([[2 * i, 2 * i + 1, 1.0] for i in range(count)])
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    q = np.repeat(3.0 * np.arange(n // 2 + 1), 2)[:n, None] * np.array([1.0, 0, 0])
    q[1::2] = q[0::2][: n // 2] + u[: n // 2]
    p = rng.normal(size=(n, 3))
    kw = {"method": d.pick(["rattle"] * 4 + ["shake"])}
    how, owner = "trap", {}
    if d.chance(0.7):
        forces = hostile_forces(d, n)
        kw["forces"], how = forces[0], forces[1]
        owner = forces[2] if len(forces) > 2 else {}
    if d.chance(0.4):
        if d.chance(0.05):
            kw["thermostat"] = d.pick(["langevin", 1.0, {"friction": 1.0}])
        else:
            kw["thermostat"] = geoshake.Langevin(
                d.scalar(lambda: float(rng.uniform(0.0, 2.0))),
                d.scalar(lambda: float(rng.uniform(0.0, 2.0))),
                seed=d.scalar(lambda: int(rng.integers(0, 2**63)), ints=True),
                substeps=d.scalar(lambda: int(rng.integers(1, 4)), ints=True),
            )
    h = d.scalar(lambda: float(rng.uniform(0.005, 0.05)))
    try:
        system = geoshake.declare_particles(DIMERS).system(masses, {"bonds": bonds}, h, **kw)
        owner["system"] = system
        q0, p0 = system.project(q, p)
        particles_on_m(q0, bonds)
        op = d.pick(["step", "run", "ensemble", "potential", "forces"])
        v = rng.random()
        if v < 0.08:
            q0 = q0.copy()
            q0.flat[rng.integers(q0.size)] = math.nan
        elif v < 0.12:
            q0 = q0[:-1]
        elif v < 0.15:
            q0 = q0.astype(complex)
        elif v < 0.18:
            p0 = p0 * 1e200
        if op == "step":
            q1, p1 = system.step(q0, p0)
            particles_on_m(q1, bonds)
            if d.chance(0.5):
                fc = system.constraint_forces(q1, p1)
                if not np.all(np.isfinite(fc.virial)):
                    raise Silent("non-finite virial")
        elif op == "run":
            run = system.run(q0, p0, int(rng.integers(0, 30)), stride=int(rng.integers(1, 4)))
            if len(run):
                particles_on_m(run.q, bonds)
            if run.error is not None and not isinstance(run.error, (geoshake.ShakeError, UserForceError)):
                raise Silent(f"run.error is {type(run.error).__name__}")
        elif op == "ensemble":
            k = int(rng.integers(0, 4))
            qs, ps = np.stack([q0] * k) if k else np.zeros((0,) + np.shape(q0)), np.stack([p0] * k) if k else np.zeros((0, n, 3))
            if d.chance(0.1):
                ps = ps[:-1]
            if d.chance(0.05):
                qs = [q0, q0[:-1]]
            for run in system.ensemble(qs, ps, int(rng.integers(0, 20))):
                if len(run):
                    particles_on_m(run.q, bonds)
                if run.error is not None and not isinstance(run.error, (geoshake.ShakeError, UserForceError)):
                    raise Silent(f"member error is {type(run.error).__name__}")
        elif op == "potential":
            if not np.isfinite(system.potential_energy(q0)) and how == "trap":
                raise Silent("V of a trap not finite")
        else:
            system.constraint_forces(q0, p0)
    except UserForceError:
        if how != "raise":
            raise Silent("UserForceError from a callable that does not raise it")
        return "ok"


KINDS = {"declare": case_declare, "run": case_run, "bonds": case_bonds, "ase": case_ase,
         "particles": case_particles}


def verdict(kind, seed, i):
    """Runs case i of `kind`: (verdict, detail)."""
    import geoshake

    d = Draw(np.random.default_rng([seed, i, list(KINDS).index(kind)]))
    try:
        with np.errstate(all="ignore"):
            r = KINDS[kind](d)
        return ("skip", "") if r == "skip" else ("ok", "")
    except Silent as e:
        return "silent", str(e)
    except geoshake.ShakeError as e:
        return "typed", type(e).__name__
    except (TypeError, OverflowError) as e:
        if d.wrong_type:
            return "typed", type(e).__name__
        return "other", f"{type(e).__name__}: {e}"
    except BaseException as e:  # noqa: BLE001 - every other exception is a finding
        if type(e).__name__ == "PanicException":
            return "panic", str(e)[:300]
        return "other", f"{type(e).__name__}: {str(e)[:300]}"


def child(kind, seed, first, last):
    for i in range(first, last):
        v, detail = verdict(kind, seed, i)
        print(json.dumps([i, v, detail]), flush=True)


# ---------------------------------------------------------------------------
# The parent: restarts the child after a crash or a hang
# ---------------------------------------------------------------------------


def drive(kind, cases, seed):
    counts = {k: 0 for k in ["ok", "typed", "silent", "panic", "hang", "other", "skip"]}
    typed, examples = {}, {}
    i = 0
    started = time.time()
    while i < cases:
        proc = subprocess.Popen(
            [sys.executable, __file__, kind, str(seed), str(i), str(cases)],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            cwd=os.path.dirname(os.path.abspath(__file__)),
        )
        lines = queue.Queue()
        threading.Thread(target=lambda: [lines.put(l) for l in proc.stdout] + [lines.put(None)],
                         daemon=True).start()
        while True:
            try:
                line = lines.get(timeout=DEADLINE)
            except queue.Empty:
                proc.kill()
                proc.wait()
                counts["hang"] += 1
                examples.setdefault("hang", f"case {i}")
                i += 1
                break
            if line is None:
                proc.wait()
                if i < cases:  # the interpreter died at case i
                    counts["panic"] += 1
                    examples.setdefault(f"crash {proc.returncode}", f"case {i}")
                    i += 1
                break
            j, v, detail = json.loads(line)
            assert j == i
            counts[v] += 1
            if v == "typed":
                typed[detail] = typed.get(detail, 0) + 1
            elif v not in ("ok", "skip"):
                examples.setdefault(f"{v}: {detail.split(':')[0][:60]}", f"case {i}: {detail}")
            i += 1
        if counts["hang"] >= 8:
            break
    elapsed = time.time() - started
    print(f"\n{kind}: {cases} cases in {elapsed:.1f} s (seed {seed}): {counts}")
    print(f"  typed: {dict(sorted(typed.items()))}")
    for k, e in examples.items():
        print(f"  {k}\n    {e}")
    return counts


@pytest.mark.parametrize("kind", list(KINDS))
def test_hostile_inputs_end_in_a_result_or_a_typed_error(kind):
    c = drive(kind, CASES, SEED)
    if c["skip"] == CASES:
        pytest.skip("ASE is not installed")
    assert (c["silent"], c["panic"], c["hang"], c["other"]) == (0, 0, 0, 0), c


if __name__ == "__main__":
    child(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]))
