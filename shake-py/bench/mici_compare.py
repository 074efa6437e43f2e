"""mici's RATTLE against ours, in one Python process, per step.

    shake-py/test.sh builds the package; then
    target/shake-py-venv/bin/pip install mici
    target/shake-py-venv/bin/python shake-py/bench/mici_compare.py

Same systems (the planar pendulum and chains of 4, 16 and 64 unit masses
and rods, anchored at the origin, in gravity), same H = V(q) + |p|²/2, same
step size h, same scheme: mici's ConstrainedLeapfrogIntegrator
is RATTLE over Störmer–Verlet (position projection by Newton, then the
velocity projection), ours is `geoshake.rattle(..., base="verlet")`. mici gets
hand-written gradients and Jacobians (no autodiff cost). Both start on M and
M^H (the chain straight and horizontal, at rest). mici's projection stops
at |g| ≤ 1e-10 and a position change ≤ 1e-10; ours with its defaults (Newton
to round-off, |g| within a few ulps), which is the stricter of the two.
"""

import time

import numpy as np

import geoshake

try:
    import mici
except ImportError:  # pragma: no cover
    raise SystemExit("pip install mici first")

H = 0.01
TOL = 1e-10
GRAVITY = 9.81


def chain_source(n):
    return f"""struct Chain {{
        parameters {{ length, gravity }}
        const N = {n};
        dof q[2*N], p[2*N];
        hamiltonian = sum i in 0..N {{ (p[2*i]^2 + p[2*i+1]^2) / 2 + gravity * q[2*i+1] }};
        constraints {{
            link[k in 0..N]: if k == 0 {{ q[0]^2 + q[1]^2 - length^2 }}
                else {{ (q[2*k] - q[2*k-2])^2 + (q[2*k+1] - q[2*k-1])^2 - length^2 }},
        }}
    }}"""


def mici_chain(n):
    """The chain (n = 1: the pendulum) as a mici system."""

    def neg_log_dens(q):
        return GRAVITY * q[1::2].sum()

    def grad_neg_log_dens(q):
        g = np.zeros_like(q)
        g[1::2] = GRAVITY
        return g

    def constr(q):
        x = q.reshape(n, 2)
        d = np.diff(np.vstack([np.zeros(2), x]), axis=0)
        return (d * d).sum(axis=1) - 1.0

    def jacob_constr(q):
        x = q.reshape(n, 2)
        d = np.diff(np.vstack([np.zeros(2), x]), axis=0)
        j = np.zeros((n, 2 * n))
        for k in range(n):
            j[k, 2 * k : 2 * k + 2] = 2 * d[k]
            if k > 0:
                j[k, 2 * k - 2 : 2 * k] = -2 * d[k]
        return j

    system = mici.systems.DenseConstrainedEuclideanMetricSystem(
        neg_log_dens,
        constr,
        grad_neg_log_dens=grad_neg_log_dens,
        jacob_constr=jacob_constr,
    )
    integrator = mici.integrators.ConstrainedLeapfrogIntegrator(
        system,
        step_size=H,
        projection_solver_kwargs={"constraint_tol": TOL, "position_tol": TOL},
    )
    return system, integrator


def start(n):
    q = np.ravel([[k + 1.0, 0.0] for k in range(n)])
    return q, np.zeros(2 * n)


def best_of(f, repeats=3):
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        f()
        best = min(best, time.perf_counter() - t)
    return best


def time_mici(n, steps):
    _, integrator = mici_chain(n)
    q, p = start(n)

    def go():
        state = mici.states.ChainState(pos=q.copy(), mom=p.copy(), dir=1)
        for _ in range(steps):
            state = integrator.step(state)

    return best_of(go) / steps


def time_ours(system, n, steps):
    q, p = start(n)
    z0 = np.concatenate([q, p])

    def go():
        geoshake.rattle(
            system, z0, H, steps=steps, base="verlet", multipliers=False,
            stride=steps,
        )

    return best_of(go) / steps


def agreement(system, n, steps=100):
    """max |z_ours - z_mici| after `steps` steps: the same scheme, so the
    difference is at the level of mici's projection tolerance."""
    _, integrator = mici_chain(n)
    q, p = start(n)
    state = mici.states.ChainState(pos=q.copy(), mom=p.copy(), dir=1)
    for _ in range(steps):
        state = integrator.step(state)
    ours = geoshake.rattle(system, np.concatenate([q, p]), H, steps=steps, base="verlet")
    z = ours.trajectory[-1]
    return max(np.abs(z[: 2 * n] - state.pos).max(), np.abs(z[2 * n :] - state.mom).max())


def main():
    rows = []
    for name, n, compiled in [
        ("pendulum", 1, geoshake.models.Pendulum),
        ("chain 4", 4, geoshake.models.Chain4),
        ("chain 16", 16, geoshake.models.Chain16),
        ("chain 64", 64, geoshake.models.Chain64),
    ]:
        src = chain_source(n)
        declared = geoshake.declare(src, length=1.0, gravity=GRAVITY)
        comp = compiled(length=1.0, gravity=GRAVITY)
        # Short runs (10 s of a chain falling from horizontal): a long run of
        # a chain whips its last links past what h = 0.01 resolves.
        mici_steps = max(20, 1000 // n)
        ours_steps = 20000 if n == 1 else 1000
        t_mici = time_mici(n, mici_steps)
        t_decl = time_ours(declared, n, ours_steps)
        t_comp = time_ours(comp, n, ours_steps)
        rows.append((name, 2 * n, t_mici, t_decl, t_comp, agreement(declared, n)))
    print(f"h = {H}, tolerance {TOL:g}, RATTLE over Störmer–Verlet, per step")
    print()
    print(
        "| system | d | mici (µs) | ours, string (µs) | mici / string "
        "| ours, compiled (µs) | mici / compiled | max diff after 100 steps |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, d, m, s, c, diff in rows:
        print(
            f"| {name} | {d} | {m * 1e6:.1f} | {s * 1e6:.2f} | {m / s:.0f}× "
            f"| {c * 1e6:.2f} | {m / c:.0f}× | {diff:.1e} |"
        )


if __name__ == "__main__":
    main()
