"""The Python package against the compiled Rust models and the theory.

String-declared systems are evaluated by a tape that computes the macro's
own operations in the macro's order, so they step exactly as the compiled
models do: the comparisons allow a few ulps of the state, far below any
O(h) difference a wrong derivative would make.
"""

import copy
import pickle
import subprocess
import sys

import numpy as np
import pytest

import geoshake

EPS = np.finfo(float).eps

PENDULUM = """
struct Pendulum {
    parameters { length, gravity }
    dof q[2], p[2];
    hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
    constraints { rod: q[0]^2 + q[1]^2 - length^2 }
}"""

HOPF = """
struct HopfGravity {
    parameters { g0, g1, radius2 }
    dof q[2], p[2];
    hamiltonian = (p[0]^2 + p[1]^2) / 2 - (g0 * q[0] + g1 * q[1]);
    constraints { sphere: q[0]^2 + q[1]^2 + p[0]^2 + p[1]^2 - radius2 }
}"""


def close_to_roundoff(a, b):
    scale = max(1.0, np.abs(a).max())
    return np.abs(a - b).max() <= 8 * EPS * scale


@pytest.mark.parametrize("method", ["rattle", "shake"])
@pytest.mark.parametrize("base", ["midpoint", "verlet"])
def test_pendulum_from_a_string_steps_as_the_compiled_model(method, base):
    declared = geoshake.declare(PENDULUM, length=1.5, gravity=9.81)
    compiled = geoshake.models.Pendulum(length=1.5, gravity=9.81)
    assert not declared.compiled and compiled.compiled
    z0 = np.array([1.5, 0.0, 0.0, 0.3])
    a = geoshake.run(declared, z0, 0.05, steps=100, method=method, base=base)
    b = geoshake.run(compiled, z0, 0.05, steps=100, method=method, base=base)
    assert a.trajectory.shape == (101, 4)
    assert close_to_roundoff(a.trajectory, b.trajectory)
    # On M: |q| = length to round-off at every stored state.
    r = np.hypot(a.trajectory[:, 0], a.trajectory[:, 1])
    assert np.abs(r - 1.5).max() <= 1e-13


def test_hopf_from_a_string_steps_as_the_compiled_model():
    params = dict(g0=0.0, g1=-1.0, radius2=0.98)
    declared = geoshake.declare(HOPF, **params)
    compiled = geoshake.models.HopfGravity(**params)
    assert declared.kind == compiled.kind == "quadratic"
    # On M (|q|² + |p|² = 0.98), away from the points where N vanishes.
    z0 = np.array([0.8, 0.2, 0.3, np.sqrt(0.21)])
    a = geoshake.rattle(declared, z0, 0.1, steps=100, base="verlet")
    b = geoshake.rattle(compiled, z0, 0.1, steps=100, base="verlet")
    assert close_to_roundoff(a.trajectory, b.trajectory)
    assert close_to_roundoff(a.lambda_[:-1], b.lambda_[:-1])


def test_times_steps_and_stride():
    sys = geoshake.models.Pendulum(length=1.0, gravity=1.0)
    out = geoshake.rattle(sys, np.array([1.0, 0.0, 0.0, 0.0]), 0.1, steps=10, stride=5)
    assert list(out.steps) == [0, 5, 10]
    assert np.allclose(out.times, [0.0, 0.5, 1.0], rtol=0, atol=4 * EPS)


def test_multipliers_are_returned_and_match_the_rod_tension():
    # At rest at the bottom of a pendulum (q = (0, -1), p = 0) the rod holds
    # the weight: the DAE's multiplier is λ_c = g/2 (p' = -H_q - λ_c ∇g,
    # ∇g = 2q), and for Störmer–Verlet λ = (h/2) λ_c (the first half kick).
    g, h = 9.81, 0.01
    sys = geoshake.declare(PENDULUM, length=1.0, gravity=g)
    out = geoshake.rattle(sys, np.array([0.0, -1.0, 0.0, 0.0]), h, steps=3, base="verlet")
    assert out.lambda_.shape == (4, 1) and out.sigma.shape == (4, 1)
    assert np.isnan(out.lambda_[-1, 0])
    assert abs(out.lambda_[0, 0] - h / 2 * g / 2) <= 1e-12
    assert abs(out.sigma[1, 0] - h / 2 * g / 2) <= 1e-12


def test_variables_and_constraints_carry_their_declared_names():
    src = """
struct Polar {
    parameters { length }
    coordinates x, y;
    momenta p_x, p_y;
    hamiltonian = (p_x^2 + p_y^2) / 2;
    constraints { rod: x^2 + y^2 - length^2 }
}"""
    sys = geoshake.declare(src, length=1.0)
    assert sys.variable_names == ["x", "y", "p_x", "p_y"]
    assert sys.constraint_names == ["rod"]
    pendulum = geoshake.declare(PENDULUM, length=1.0, gravity=9.81)
    assert pendulum.variable_names == ["q[0]", "q[1]", "p[0]", "p[1]"]


def test_a_bad_declaration_raises_with_its_position():
    src = PENDULUM.replace("gravity * q[1]", "gravty * q[1]")
    with pytest.raises(geoshake.DeclarationError) as info:
        geoshake.declare(src, length=1.0, gravity=9.81)
    e = info.value
    lines = src.splitlines()
    assert e.line == next(i for i, l in enumerate(lines, 1) if "gravty" in l)
    line = lines[e.line - 1]
    assert e.column == line.index("gravty") + 1
    assert "gravity" in e.message
    assert isinstance(e, geoshake.ShakeError)


def test_a_refused_system_raises_the_theory_check():
    src = """struct Bad {
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2;
        constraints { a: q[0], b: p[0] }
    }"""
    with pytest.raises(geoshake.DeclarationError) as info:
        geoshake.declare(src)
    assert "coisotropic" in info.value.message
    assert (info.value.line, info.value.column) == (4, 23)


def test_parameters_by_name_are_checked():
    with pytest.raises(geoshake.ParameterError):
        geoshake.declare(PENDULUM, length=1.0)
    with pytest.raises(geoshake.ParameterError):
        geoshake.declare(PENDULUM, length=1.0, gravity=1.0, mass=2.0)
    with pytest.raises(geoshake.ParameterError):
        geoshake.models.Pendulum(length=1.0)


def test_a_failing_run_raises_with_the_partial_trajectory():
    # h = 0.3 is far past the pendulum's stability limit at this energy
    # (period ~2, velocity 3): after a few steps the fibre no longer meets
    # M near the base map's point and SHAKE's Newton for λ fails.
    sys = geoshake.declare(PENDULUM, length=1.0, gravity=9.81)
    z0 = np.array([1.0, 0.0, 0.0, 3.0])
    with pytest.raises(geoshake.NewtonError) as info:
        geoshake.rattle(sys, z0, 0.3, steps=1000, base="midpoint")
    e = info.value
    assert isinstance(e, geoshake.ShakeError)
    assert e.step >= 2
    n = e.trajectory.shape[0]
    assert e.trajectory.shape == (n, 4) and n >= 2
    assert e.times.shape == (n,) and e.lambda_.shape == (n, 1)
    assert e.times[-1] <= e.time
    assert np.isfinite(e.residual) and e.residual > 0
    # What was stored is good: every state on M.
    r = np.hypot(e.trajectory[:, 0], e.trajectory[:, 1])
    assert np.abs(r - 1.0).max() <= 1e-12


@pytest.mark.parametrize("stride", [1, 2**62])
def test_a_run_of_more_steps_than_f64_counts_is_refused(stride):
    # 2**63 steps: stride 1 killed the interpreter (the trajectory grew
    # until the allocator aborted), stride 2**62 never returned. Beyond
    # 2**53 the step index k is not exact in f64, nor the times t0 + k*h.
    sys = geoshake.models.Pendulum(length=1.0, gravity=9.81)
    z0 = np.array([0.0, -1.0, 0.0, 0.0])
    with pytest.raises(geoshake.InvalidInputError) as info:
        geoshake.rattle(sys, z0, 0.01, steps=2**63, stride=stride)
    assert "2^53" in str(info.value)
    assert info.value.step == 0


def test_ensembles_run_every_member():
    sys = geoshake.models.Pendulum(length=1.0, gravity=9.81)
    z0s = np.array([[np.cos(a), np.sin(a), 0.0, 0.0] for a in np.linspace(-1, 1, 8)])
    outs = geoshake.ensemble(sys, z0s, 0.01, steps=50)
    assert len(outs) == 8
    for z0, out in zip(z0s, outs):
        single = geoshake.rattle(sys, z0, 0.01, steps=50)
        assert np.array_equal(out.trajectory, single.trajectory)


def test_chains_compiled_and_declared_agree():
    n = 4
    src = f"""struct Chain {{
        parameters {{ length, gravity }}
        const N = {n};
        dof q[2*N], p[2*N];
        hamiltonian = sum i in 0..N {{ (p[2*i]^2 + p[2*i+1]^2) / 2 + gravity * q[2*i+1] }};
        constraints {{
            link[k in 0..N]: if k == 0 {{ q[0]^2 + q[1]^2 - length^2 }}
                else {{ (q[2*k] - q[2*k-2])^2 + (q[2*k+1] - q[2*k-1])^2 - length^2 }},
        }}
    }}"""
    declared = geoshake.declare(src, length=1.0, gravity=9.81)
    compiled = geoshake.models.Chain4(length=1.0, gravity=9.81)
    q = np.ravel([[k + 1.0, 0.0] for k in range(n)])
    z0 = np.concatenate([q, np.zeros(2 * n)])
    a = geoshake.rattle(declared, z0, 0.01, steps=50, base="verlet")
    b = geoshake.rattle(compiled, z0, 0.01, steps=50, base="verlet")
    assert close_to_roundoff(a.trajectory, b.trajectory)


def test_states_of_integers_or_other_real_dtypes_are_converted():
    sys = geoshake.models.Pendulum(length=1.0, gravity=9.81)
    want = geoshake.rattle(sys, np.array([1.0, 0.0, 0.0, 0.0]), 0.01, steps=5).trajectory
    for z0 in (
        np.array([1, 0, 0, 0]),
        [1, 0, 0, 0],
        np.array([1.0, 0.0, 0.0, 0.0], dtype=np.float32),
        np.array([1.0, 0.0, 0.0, 0.0], dtype=">f8"),
        np.array([1.0, 9.0, 0.0, 9.0, 0.0, 9.0, 0.0])[::2],
    ):
        out = geoshake.rattle(sys, z0, 0.01, steps=5)
        assert np.array_equal(out.trajectory, want), z0
    z0s = np.array([[1, 0, 0, 0], [0, -1, 1, 0]])
    assert len(geoshake.ensemble(sys, z0s, 0.01, steps=5)) == 2
    assert sys.hamiltonian([0, -1, 1, 0]) == 0.5 - 9.81


@pytest.mark.parametrize(
    "z0, says",
    [
        (np.array([1 + 0j, 0, 0, 0]), "real numbers"),
        (np.array([1.0, 0.0, 0.0, 0.0], dtype=object), "real numbers"),
        (np.array([True, False, False, False]), "real numbers"),
        (np.array(["1", "0", "0", "0"]), "real numbers"),
        (np.zeros((2, 2)), "shape (4,)"),
        (np.zeros(3), "not (3,)"),
        ([1.0, [0.0, 0.0], 0.0], "array of real numbers"),
    ],
)
def test_a_state_of_the_wrong_kind_or_shape_says_what_is_expected(z0, says):
    # Each of these said "'ndarray' object cannot be cast as 'ndarray'".
    sys = geoshake.models.Pendulum(length=1.0, gravity=9.81)
    with pytest.raises(geoshake.InvalidInputError) as info:
        geoshake.rattle(sys, z0, 0.01, steps=5)
    assert says in str(info.value)
    assert "z0" in str(info.value)


def test_unknown_option_values_are_refused():
    # errors="bogus" was taken as "raise".
    sys = geoshake.models.Pendulum(length=1.0, gravity=9.81)
    z0s = np.array([[1.0, 0.0, 0.0, 0.0]])
    with pytest.raises(geoshake.InvalidInputError) as info:
        geoshake.ensemble(sys, z0s, 0.01, steps=5, errors="bogus")
    assert "bogus" in str(info.value)
    with pytest.raises(geoshake.InvalidInputError):
        geoshake.ensemble(sys, np.zeros(4), 0.01, steps=5)


@pytest.mark.parametrize(
    "kw, says",
    [
        ({"steps": -1}, "`steps` = -1"),
        ({"steps": 2**64}, "`steps` = 18446744073709551616"),
        ({"steps": 5, "stride": -1}, "`stride` = -1"),
        ({"steps": 5, "max_iterations": -3}, "`max_iterations` = -3"),
    ],
)
def test_counts_out_of_range_are_the_packages_error_naming_them(kw, says):
    # -1 was Python's OverflowError from the conversion to an unsigned
    # integer, not an error of the package, and did not name the argument.
    sys = geoshake.models.Pendulum(length=1.0, gravity=9.81)
    z0 = np.array([0.0, -1.0, 0.0, 0.0])
    for call in (
        lambda: geoshake.rattle(sys, z0, 0.01, **kw),
        lambda: geoshake.ensemble(sys, z0[None, :], 0.01, **kw),
    ):
        with pytest.raises(geoshake.InvalidInputError) as info:
            call()
        assert says in str(info.value), str(info.value)
    with pytest.raises(TypeError):
        geoshake.rattle(sys, z0, 0.01, steps=2.0)


def test_numpy_integers_are_counts():
    # A count computed with NumPy (np.int64, np.uint32) was a TypeError:
    # counts are read as operator.index reads them, as range() does.
    sys = geoshake.models.Pendulum(length=1.0, gravity=9.81)
    z0 = np.array([0.0, -1.0, 0.0, 0.0])
    plain = geoshake.rattle(sys, z0, 0.01, steps=20, stride=5)
    numpy = geoshake.rattle(sys, z0, 0.01, steps=np.int64(20), stride=np.uint32(5), max_iterations=np.int16(50))
    assert np.array_equal(plain.trajectory, numpy.trajectory)
    with pytest.raises(geoshake.InvalidInputError) as info:
        geoshake.rattle(sys, z0, 0.01, steps=np.int64(-1))
    assert "`steps` = -1" in str(info.value)
    for wrong in (np.float64(20.0), np.bool_(True), True, "20"):
        with pytest.raises(TypeError):
            geoshake.rattle(sys, z0, 0.01, steps=wrong)


def test_results_and_systems_name_the_package():
    sys = geoshake.models.Pendulum(length=1.0, gravity=9.81)
    r = geoshake.rattle(sys, np.array([0.0, -1.0, 0.0, 0.0]), 0.01, steps=2)
    assert type(r).__module__ == "geoshake"
    assert type(sys).__module__ == "geoshake"


@pytest.mark.parametrize("protocol", range(pickle.HIGHEST_PROTOCOL + 1))
def test_systems_pickle_and_take_the_same_steps(protocol):
    # A system sent to another process (multiprocessing, joblib) is rebuilt
    # from its declaration or model name and the parameters as given.
    z0 = np.array([0.0, -1.0, 0.3, 0.0])
    declared = geoshake.declare(PENDULUM, length=1.0, gravity=9.81)
    compiled = geoshake.models.Pendulum(length=1.0, gravity=9.81)
    for sys in (declared, compiled):
        back = pickle.loads(pickle.dumps(sys, protocol=protocol))
        assert type(back) is type(sys) and repr(back) == repr(sys)
        assert back.compiled == sys.compiled and back.parameters == sys.parameters
        a = geoshake.rattle(sys, z0, 0.01, steps=50)
        b = geoshake.rattle(back, z0, 0.01, steps=50)
        assert np.array_equal(a.trajectory, b.trajectory)
    assert copy.deepcopy(declared).compiled is False


def _rattle_50(sys, z0):
    return geoshake.rattle(sys, z0, 0.01, steps=50).trajectory


def test_a_system_runs_in_a_spawned_process():
    # What a ProcessPoolExecutor does with a system given as an argument:
    # pickle it, start a fresh interpreter, unpickle and run it there.
    import multiprocessing

    sys = geoshake.declare(PENDULUM, length=1.0, gravity=9.81)
    z0 = np.array([0.0, -1.0, 0.3, 0.0])
    with multiprocessing.get_context("spawn").Pool(1) as pool:
        there = pool.apply(_rattle_50, (sys, z0))
    assert np.array_equal(there, _rattle_50(sys, z0))


def _fail_off_m(sys):
    return geoshake.rattle(sys, np.array([2.0, 0.0, 0.0, 0.0]), 0.01, steps=5, project=False)


def test_errors_and_results_pickle_with_what_they_carry():
    # A worker's error or result crossed back to the parent as
    # MaybeEncodingError: the exceptions said module `_geoshake`.
    sys = geoshake.models.Pendulum(length=1.0, gravity=9.81)
    with pytest.raises(geoshake.NotOnConstraintError) as info:
        _fail_off_m(sys)
    e = info.value
    back = pickle.loads(pickle.dumps(e))
    assert type(back) is geoshake.NotOnConstraintError and str(back) == str(e)
    assert (back.step, back.time, back.residual) == (e.step, e.time, e.residual)
    assert np.array_equal(back.trajectory, e.trajectory)
    r = geoshake.rattle(sys, np.array([0.0, -1.0, 0.3, 0.0]), 0.01, steps=5)
    for protocol in range(pickle.HIGHEST_PROTOCOL + 1):
        b = pickle.loads(pickle.dumps(r, protocol=protocol))
        for name in ("trajectory", "times", "steps", "lambda_", "sigma"):
            assert np.array_equal(getattr(b, name), getattr(r, name), equal_nan=name != "steps")
    import multiprocessing

    with multiprocessing.get_context("spawn").Pool(1) as pool:
        with pytest.raises(geoshake.NotOnConstraintError):
            pool.apply(_fail_off_m, (sys,))


def test_a_singular_n_is_a_nondegeneracy_error_with_its_time():
    # g = (|q|² − 1)²: ∇g = 0 on M, N = {{H,g},g} = 0. It was the base class
    # with time NaN.
    d = geoshake.declare(
        "struct D { dof q[2], p[2]; hamiltonian = (p[0]^2+p[1]^2)/2; constraints { c: (q[0]^2+q[1]^2-1)^2 } }"
    )
    with pytest.raises(geoshake.NondegeneracyError) as info:
        geoshake.rattle(d, [1.0, 0.0, 0.0, 1.0], 0.01, steps=3)
    assert info.value.time == 0.0
    assert repr(d) == "<geoshake.System D (declared, d=2, m=1)>"


@pytest.mark.parametrize(
    "make, says",
    [
        (lambda: geoshake.models.Pendulum(length=float("nan"), gravity=1.0), "length"),
        (lambda: geoshake.models.Pendulum(length=1.0, gravity=float("inf")), "gravity"),
        (lambda: geoshake.declare(PENDULUM, length=True, gravity=9.81), "`length` must be a real number"),
        (lambda: geoshake.declare(PENDULUM, length="1", gravity=9.81), "`length` must be a real number"),
        (lambda: geoshake.declare(PENDULUM, length=10**400, gravity=9.81), "`length` must be a real number"),
        (lambda: geoshake.models.Pendulum(length=1.0, gravity=None), "`gravity` must be a real number"),
    ],
)
def test_parameters_must_be_finite_real_numbers(make, says):
    with pytest.raises(geoshake.ParameterError) as info:
        make()
    assert says in str(info.value), str(info.value)


def test_a_newton_tolerance_is_refused_by_its_python_name():
    sys = geoshake.models.Pendulum(length=1.0, gravity=9.81)
    z0 = np.array([0.0, -1.0, 0.0, 0.0])
    for bad in (1.0, -1e-12, float("nan")):
        with pytest.raises(geoshake.InvalidInputError, match="`newton_tolerance`") as info:
            geoshake.rattle(sys, z0, 0.01, steps=5, newton_tolerance=bad)
        assert "step_tolerance" not in str(info.value)


def test_iteration_budgets_say_their_range():
    sys = geoshake.models.Pendulum(length=1.0, gravity=9.81)
    z0 = np.array([0.0, -1.0, 0.0, 0.0])
    for bad in (0, -1, 10**6):
        with pytest.raises(geoshake.InvalidInputError, match="an integer from 1 to 10000"):
            geoshake.rattle(sys, z0, 0.01, steps=5, max_iterations=bad)


def test_what_an_index_method_raises_is_passed_on():
    sys = geoshake.models.Pendulum(length=1.0, gravity=9.81)
    z0 = np.array([0.0, -1.0, 0.0, 0.0])

    class Broken:
        def __index__(self):
            raise ValueError("no count here")

    class NotInt:
        def __index__(self):
            return 2.5

    with pytest.raises(ValueError, match="no count here"):
        geoshake.rattle(sys, z0, 0.01, steps=Broken())
    with pytest.raises(TypeError, match="non-int"):
        geoshake.rattle(sys, z0, 0.01, steps=NotInt())
    plain = object.__new__(type("Plain", (), {}))
    plain.__index__ = lambda: 5  # on the instance: not an integer type
    with pytest.raises(TypeError):
        geoshake.rattle(sys, z0, 0.01, steps=plain)


def test_a_constant_outside_a_function_domain_is_a_declaration_error():
    # sqrt(-1) in H was accepted, and H was NaN at every state.
    with pytest.raises(geoshake.DeclarationError) as info:
        geoshake.declare(PENDULUM.replace("gravity * q[1]", "sqrt(-1) * q[1]"), length=1.0, gravity=9.81)
    assert "sqrt" in str(info.value)


def run_isolated(code):
    """Runs `code` in a fresh interpreter: a crash there (a stack overflow
    was one) fails the test instead of killing pytest."""
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=600
    )


def test_a_sum_of_100000_terms_is_declared():
    # A left-deep tree of 12 000 terms overflowed the main thread's stack.
    r = run_isolated("""
import geoshake
terms = " + ".join(f"q[{k % 2}]^2" for k in range(100_000))
system = geoshake.declare(
    "struct S { dof q[2], p[2]; hamiltonian = (p[0]^2 + p[1]^2) / 2 + "
    + terms + "; constraints { c: q[0]^2 + q[1]^2 - 1 } }")
print(system.hamiltonian([0.6, 0.8, 0.0, 0.0]))
""")
    assert r.returncode == 0, r.stderr
    assert float(r.stdout) == pytest.approx(50_000 * (0.6**2 + 0.8**2), rel=1e-12)


@pytest.mark.parametrize("n", [40_000, 1_000_000])
def test_deeply_nested_parentheses_are_a_declaration_error(n):
    # 40 000 overflowed the stack before the parser's depth check.
    r = run_isolated(f"""
import geoshake
head = "struct S {{ dof q[2], p[2]; hamiltonian = (p[0]^2 + p[1]^2) / 2 + "
try:
    geoshake.declare(head + "(" * {n} + "q[0]" + ")" * {n} + "; }}")
except geoshake.DeclarationError as e:
    assert isinstance(e, geoshake.ShakeError)
    assert "nested too deeply" in e.message, e.message
    print(e.line, e.column - len(head))
else:
    raise SystemExit("declared")
""")
    assert r.returncode == 0, r.stderr
    # At the first bracket past the limit of 259: the struct's braces are
    # the first level, the first `(` the second.
    assert r.stdout.split() == ["1", "259"]
