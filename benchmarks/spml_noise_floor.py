"""What the noisy data of the SpML convergence systems determine: the output-error (maximum-likelihood) fit.

The truth's class is known here (unit mass, linear stiffness and damping, a polynomial potential of
degrees 3 and 4): this script fits exactly that class by output error, i.e. it simulates each training
trajectory from estimated initial conditions (DOP853, rtol 1e-10) and minimises

    sum_trajectories sum_fields ||x_sim - x_data||^2 / sigma_x^2,      x = q, q', q'' (the equation's)

over ``K``, ``C``, the monomials' coefficients and the initial states (Gauss-Newton with a trust region,
``scipy.optimize.least_squares``, finite-difference Jacobian, from the truth). With Gaussian noise of
known level this is the maximum-likelihood estimate, the most any estimator can extract from these
data up to the Cramer-Rao bound; it knows the mass (SpML learns it) and has no networks, so it is a
bound from below for SpML's errors. Its final cost against the noise's expectation (half the number
of residuals) shows that it reached the noise floor.

Run ``python -m benchmarks.spml_noise_floor [--systems chain3 duffing2] [--seeds 0 1]``; it prints one
line per fit and writes ``benchmarks/results/spml_noise_floor.json``. Minutes per fit on one thread.
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from pathlib import Path

import numpy as np

from benchmarks.spml_systems import SYSTEMS, polynomial_potential, prediction_errors
from femrom.inference import ReducedOperators, multi_indices

ROOT = Path(__file__).resolve().parents[1]


def _symmetric_tensor(r: int, index: list, coefficients) -> np.ndarray:
    T = np.zeros((r,) * len(index[0]))
    for m, c in zip(index, coefficients):
        perms = set(itertools.permutations(m))
        for p in perms:
            T[p] = c / len(perms)
    return T


def output_error_fit(system, train: list, max_evaluations: int = 15) -> dict:
    """The output-error fit of ``system``'s class to ``train`` (noisy runs from :meth:`KnownSystem.training`)."""
    from scipy.integrate import solve_ivp
    from scipy.optimize import least_squares
    from scipy.sparse import lil_matrix

    r, truth = system.r, system.operators
    upper = np.triu_indices(r)
    index = {d: [tuple(m) for m in multi_indices(r, d)] for d in (3, 4)}
    poly = truth.term("learned_potential").polynomial
    tensors_true = {3: poly.T3, 4: poly.T4}
    theta_true = np.concatenate([truth.stiffness[upper], truth.damping[upper]] +
                                [[tensors_true[d][m] * len(set(itertools.permutations(m))) for m in index[d]]
                                 for d in (3, 4)])
    n_sym, n_par = upper[0].size, theta_true.size

    def unpack(theta):
        def sym(x):
            S = np.zeros((r, r))
            S[upper] = x
            return S + S.T - np.diag(np.diag(S))
        K, C = sym(theta[:n_sym]), sym(theta[n_sym:2 * n_sym])
        T3 = _symmetric_tensor(r, index[3], theta[2 * n_sym:2 * n_sym + len(index[3])])
        T4 = _symmetric_tensor(r, index[4], theta[2 * n_sym + len(index[3]):n_par])
        return K, C, T3, T4

    def acceleration(K, C, T3, T4):
        def f(q, v):
            grad = 3.0 * np.einsum("ijk,j...,k...->i...", T3, q, q) \
                + 4.0 * np.einsum("ijkl,j...,k...,l...->i...", T4, q, q, q)
            return -(K @ q + C @ v + grad)
        return f

    # the noise level of each field: 1 % of its RMS (the data's noise model, benchmarks/spml_systems.py)
    sigma = [[float(np.sqrt(np.mean(x ** 2))) for x in (d.states, d.velocities, d.accelerations)] for d in train]
    sigma = [[0.01 * s for s in row] for row in sigma]
    size = 3 * r * train[0].n_samples

    def residual(x):
        f = acceleration(*unpack(x[:n_par]))
        out = []
        for i, d in enumerate(train):
            y0 = x[n_par + 2 * r * i:n_par + 2 * r * (i + 1)]
            sol = solve_ivp(lambda t, y: np.concatenate([y[r:], f(y[:r], y[r:])]), (d.times[0], d.times[-1]), y0,
                            t_eval=d.times, method="DOP853", rtol=1e-10, atol=1e-12)
            if sol.y.shape[1] != d.n_samples:
                return np.full(size * len(train), 1e3)
            q, v = sol.y[:r], sol.y[r:]
            out += [((x_sim - x_data) / s).ravel() for x_sim, x_data, s in
                    zip((q, v, f(q, v)), (d.states, d.velocities, d.accelerations), sigma[i])]
        return np.concatenate(out)

    x0 = np.concatenate([theta_true] + [np.concatenate([d.states[:, 0], d.velocities[:, 0]]) for d in train])
    pattern = lil_matrix((size * len(train), x0.size), dtype=int)
    pattern[:, :n_par] = 1
    for i in range(len(train)):
        pattern[size * i:size * (i + 1), n_par + 2 * r * i:n_par + 2 * r * (i + 1)] = 1
    tic = time.perf_counter()
    result = least_squares(residual, x0, jac_sparsity=pattern, x_scale="jac", max_nfev=max_evaluations)
    K, C, T3, T4 = unpack(result.x[:n_par])
    model = ReducedOperators.from_matrices(K, damping=C, nonlinear=polynomial_potential(r, {3: T3, 4: T4}))
    return {"model": model, "seconds": time.perf_counter() - tic, "cost": float(result.cost),
            "noise_cost": 0.5 * result.fun.size}


def main(argv=None) -> int:
    from femrom.study import spml_error_split

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--systems", nargs="+", default=sorted(SYSTEMS), choices=sorted(SYSTEMS))
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "spml_noise_floor.json"))
    args = parser.parse_args(argv)
    rows = []
    for name in args.systems:
        system = SYSTEMS[name]()
        test = system.test(3.0)
        for seed in args.seeds:
            train, _ = system.training(0.01, seed)
            fit = output_error_fit(system, train)
            split = spml_error_split(fit["model"], system.operators, train, test)
            errors = prediction_errors(fit["model"], system, test)
            rows.append({"system": name, "seed": seed, "seconds": fit["seconds"], "cost": fit["cost"],
                         "noise_cost": fit["noise_cost"], "force": split.potential,
                         "dissipation": split.dissipation, "window": errors["window"], "total": errors["total"]})
            row = rows[-1]
            print(f"| {name} | {seed} | {row['seconds']:.0f} | {row['cost']:.0f} / {row['noise_cost']:.0f} | "
                  f"{row['force']:.1e} | {row['dissipation']:.1e} | {row['window']:.1e} | {row['total']:.1e} |",
                  flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps({"rows": rows}, indent=2, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
