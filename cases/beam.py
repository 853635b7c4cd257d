"""Euler-Bernoulli cantilever: FOM, then L-OpInf / Galerkin / plain OpInf ROMs, and what accuracy costs.

A steel cantilever (Hermite elements on a Gmsh line; clamped at x = 0, free at
x = L) is released from its static deflection under a tip load
(``beam.toml``). The ROM part (:func:`rom_study`, settings :class:`RomStudy`)
runs FOM -> snapshots of a training window -> mass-orthonormal POD ->
intrusive Galerkin, L-OpInf and plain OpInf on the same data and basis, for
several r, and predicts 20x the training window; it is repeated on coarser
snapshots (:data:`COARSE_ROM`), where plain OpInf blows up. The case writes,
into its output folder:

- ``rom_state_error.png``, ``rom_energy_error.png``, ``rom_tip_end.png``,
  ``accuracy_cost_rom.png`` (test error vs online time), ``accuracy_cost_rom_r.png``
  and the same with prefix ``coarse_``; the tables in ``report.md``;

- ``response.png``: tip and midspan deflection and the relative energy change;
- ``accuracy_cost_dt.png`` and the table in ``report.md``: tip error against
  stepping time for a ladder of time steps (reference: dt / 8 on the same mesh);
- ``accuracy_cost_mesh.png``: error of the first four natural frequencies
  against the analytic cantilever roots, for a ladder of mesh sizes, against
  assembly + eigen-solve time;
- ``metrics.json`` (every number above, timings of each stage) and ``scene.toml``.

Run ``python -m femrom run beam [--out DIR] [--quick]``; tests import :func:`run`.
"""


import argparse
import dataclasses
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from femrom.integrators import simulate
from femrom.post import (accuracy_cost_table, machine_description, plot_accuracy_cost, plot_response,
                         write_metrics)
from femrom.scene import Scene, build

SCENE = Path(__file__).with_suffix(".toml")

# beta_n L of a cantilever (Blevins 1979, table 8-1; ../shared/DESIGN.md)
CANTILEVER_ROOTS = np.array([1.8751040687, 4.6940911330, 7.8547574382, 10.9955407349])


def with_time_step(scene: Scene, dt: float) -> Scene:
    return dataclasses.replace(scene, time=dataclasses.replace(scene.time, dt=dt))


def with_mesh_size(scene: Scene, mesh_size: float) -> Scene:
    params = dict(scene.structure.parameters) | {"mesh_size": mesh_size}
    structure = dataclasses.replace(scene.structure, parameters=tuple(sorted(params.items())))
    return dataclasses.replace(scene, structure=structure)


def analytic_frequencies(scene: Scene, count: int = 4) -> np.ndarray:
    """Cantilever omega_n = (beta_n L)^2 sqrt(E I / (rho A L^4)) [rad/s]."""
    m = scene.material
    length = dict(scene.structure.parameters)["length"]
    return CANTILEVER_ROOTS[:count] ** 2 * np.sqrt(
        m.youngs_modulus * m.second_moment / (m.density * m.area * length**4))


def fe_frequencies(model, count: int = 4) -> np.ndarray:
    from scipy.sparse.linalg import eigsh

    s = model.system
    values = eigsh(s.stiffness.tocsc(), k=count, M=s.mass.tocsc(), sigma=0.0, which="LM")[0]
    return np.sqrt(np.sort(values))


def time_step_ladder(scene: Scene, factors=(8, 4, 2, 1), reference_divisor=8) -> list[dict]:
    """Tip error (max over time, relative to the peak tip deflection) against stepping cost."""
    model = build(scene)
    dt0 = scene.time.dt
    reference = simulate(model, dt=dt0 / reference_divisor)
    coarse = max(factors) * dt0
    t_common = np.arange(0.0, scene.time.t_end + 0.5 * coarse, coarse)
    ref_tip = np.interp(t_common, reference.times, reference.outputs[0])
    scale = np.max(np.abs(ref_tip))
    rows = []
    for factor in factors:
        result = simulate(model, dt=factor * dt0)
        tip = np.interp(t_common, result.times, result.outputs[0])
        rows.append({"dt": factor * dt0, "steps": result.summary["n_steps"],
                     "tip_error": float(np.max(np.abs(tip - ref_tip)) / scale),
                     "stepping_seconds": result.summary["stepping_seconds"]})
    dts = np.array([r["dt"] for r in rows])
    errors = np.array([r["tip_error"] for r in rows])
    order = float(np.polyfit(np.log(dts), np.log(errors), 1)[0])
    for r in rows:
        r["observed_order"] = order
    return rows


def mesh_ladder(scene: Scene, mesh_sizes=(0.2, 0.1, 0.05, 0.025)) -> list[dict]:
    exact = analytic_frequencies(scene)
    rows = []
    for h in mesh_sizes:
        tic = time.perf_counter()
        model = build(with_mesh_size(scene, h))
        omega = fe_frequencies(model)
        seconds = time.perf_counter() - tic
        rows.append({"mesh_size": h, "dofs": model.system.n_dofs,
                     "frequency_error": float(np.max(np.abs(omega / exact - 1))),
                     "f1_hz": float(omega[0] / (2 * np.pi)), "seconds": seconds})
    return rows



@dataclass(frozen=True)
class RomStudy:
    """Settings of the ROM part (FOM -> snapshots -> POD -> Galerkin / L-OpInf / plain OpInf).

    Attributes
    ----------
    dt : float
        Step of the FOM run that provides the snapshots (every step is a
        snapshot) and of the ROMs' Newmark average acceleration.
    train_window : float
        Training window [0, T] [s].
    extension : float
        Prediction window in training windows (the seed shows 20x).
    ranks : tuple of int
        Basis sizes r of the accuracy-vs-cost ladder.
    main_rank : int
        The r of the time-history plots.
    derivative_order : int
        Finite-difference order of the reduced velocities and accelerations.
    damping : bool
        Whether the learners fit a damping term ``C^`` (they do not know that
        the structure is undamped).
    mesh_size : float or None
        Mesh size of the FOM (``None``: the scene's).
    """

    dt: float = 5.0e-5
    train_window: float = 0.15
    extension: float = 20.0
    ranks: tuple[int, ...] = (2, 4, 6, 8, 10, 12)
    main_rank: int = 8
    derivative_order: int = 4
    damping: bool = True
    mesh_size: float | None = None


QUICK_ROM = RomStudy(dt=1.0e-4, train_window=0.1, ranks=(2, 4, 6), main_rank=6, mesh_size=0.05)
PAPER_ROM = RomStudy(dt=2.5e-5, train_window=0.15, ranks=(2, 4, 6, 8, 10, 12, 16, 20), main_rank=10,
                     mesh_size=0.01)
# The same comparison on coarser snapshots (the scene's FOM step; 4x the quick step): the
# finite-difference accelerations of the poorly resolved high POD modes are then wrong by
# O(1) (data error), the regime in which the seed shows plain OpInf blowing up.
COARSE_ROM = RomStudy(dt=2.0e-4, ranks=(8, 10, 12), main_rank=12)
QUICK_COARSE_ROM = dataclasses.replace(QUICK_ROM, dt=4.0e-4, ranks=(6, 8), main_rank=8)

METHODS = ("galerkin", "lopinf", "plain_opinf")


def _m_norms(X, M) -> np.ndarray:
    """(k,) ndarray: ``||x_k||_M`` of every column."""
    return np.sqrt(np.maximum(np.sum(X * np.asarray(M @ X), axis=0), 0.0))


def fom_energy(system, Q, Vel) -> np.ndarray:
    """(k,) ndarray ``q'^T M q' / 2 + q^T K q / 2`` of full (n, k) states."""
    return 0.5 * np.sum(Vel * np.asarray(system.mass @ Vel), axis=0) + \
        0.5 * np.sum(Q * np.asarray(system.stiffness @ Q), axis=0)


def newmark_frequencies(omega: np.ndarray, dt: float) -> np.ndarray:
    """Frequencies of Newmark average acceleration: ``tan(Omega dt / 2) = omega dt / 2`` (no amplitude error)."""
    return 2.0 / dt * np.arctan(0.5 * omega * dt)


def dispersion_error(system, q0: np.ndarray, dt: float, times: np.ndarray, r: int, norm: float) -> float:
    r"""A priori test-window error of a ROM that learned the FOM's *discrete* frequencies.

    Released from ``q0`` at rest, the Newmark FOM is exactly
    ``q_n = sum_k a_k cos(Omega_k t_n) phi_k`` (``phi_k`` mass-orthonormal modes,
    ``Omega_k`` :func:`newmark_frequencies` of ``omega_k``). Finite differences of
    order p of ``cos(Omega t)`` return ``Omega`` up to ``O((Omega dt)^p)``, so a
    learner that fits the data exactly learns ``Omega_k``, not ``omega_k``; the
    ROM's own Newmark step then runs at ``Omega'_k = newmark_frequencies(Omega_k)``.
    Over the modes 1..r (those a POD basis of this data spans) that phase error is

    .. math::

        d(r) = \Big(\sum_{t \in \text{test}} \sum_{k \le r}
               a_k^2 (\cos\Omega'_k t - \cos\Omega_k t)^2\Big)^{1/2} / \|Q_{test}\|_M,

    and such a ROM's error is ``sqrt(projection^2 + d(r)^2)``. ``norm`` is
    ``||Q_test||_M``, ``times`` the test window's times.
    """
    import scipy.linalg as sl

    omega2, modes = sl.eigh(system.stiffness.toarray(), system.mass.toarray())
    amplitudes = modes[:, :r].T @ np.asarray(system.mass @ q0)
    learned = newmark_frequencies(np.sqrt(omega2[:r]), dt)
    stepped = newmark_frequencies(learned, dt)
    phase = np.cos(np.outer(stepped, times)) - np.cos(np.outer(learned, times))
    return float(np.sqrt(np.sum(amplitudes[:, None] ** 2 * phase**2)) / norm)


def rom_study(scene: Scene, study: RomStudy) -> dict:
    """Run the ROM comparison; returns metrics, curves (for plots) and the accuracy-cost rows.

    Errors are relative in the mass norm: ``||Q - V Q^||_M / ||Q||_M`` over a
    window, and over time ``||q(t) - V q^(t)||_M / max_t ||q(t)||_M``. The
    energy error is the full model's energy evaluated on the reconstructed
    ROM state, ``|E(V q^, V q^') - E(q_0, 0)| / E(q_0, 0)``. Every row also
    carries ``dispersion_error`` (:func:`dispersion_error`) and
    ``predicted_learned_error = sqrt(projection_error^2 + dispersion_error^2)``:
    what a learner that recovered the data's discrete frequencies exactly would score.
    """
    from femrom.basis import POD
    from femrom.inference import LagrangianOpInf, SecondOrderOpInf, reduce_snapshots
    from femrom.integrators import Newmark, Trajectory, integrate
    from femrom.rom import SecondOrderROM

    if study.mesh_size is not None:
        scene = with_mesh_size(scene, study.mesh_size)
    model = build(scene)
    system = model.system
    M = system.mass
    dt = study.dt
    n_train = int(round(study.train_window / dt))
    n_total = int(round(study.extension * n_train))
    # one FOM run over the whole prediction window: its first n_train steps are the
    # training snapshots, the rest is the reference the predictions are scored against
    trajectory = Trajectory()
    tic = time.perf_counter()
    fom_summary = integrate(system, Newmark(), model.initial_displacement, model.initial_velocity,
                            dt, n_total, consumers=[trajectory])
    fom_seconds = time.perf_counter() - tic
    fom_train_seconds = fom_seconds * n_train / n_total
    Q, Qd = trajectory.q, trajectory.v
    times = trajectory.t
    train = slice(0, n_train + 1)
    test = slice(n_train + 1, None)
    E_fom = fom_energy(system, Q, Qd)
    E0 = E_fom[0]
    scale = np.max(_m_norms(Q, M))
    q_norm = {"train": np.linalg.norm(_m_norms(Q[:, train], M)),
              "test": np.linalg.norm(_m_norms(Q[:, test], M))}
    tip = system.output_matrix[0] if system.output_matrix is not None else None

    rows, curves = [], {}
    for r in study.ranks:
        tic = time.perf_counter()
        pod = POD(r, product=M).fit(Q[:, train])
        V = pod.basis_
        pod_seconds = time.perf_counter() - tic
        tic = time.perf_counter()
        data = reduce_snapshots(V, Q[:, train], dt, product=M, order=study.derivative_order,
                                velocities=Qd[:, train])
        reduce_seconds = time.perf_counter() - tic
        residual = Q - V @ (V.T @ np.asarray(M @ Q))
        proj_t = _m_norms(residual, M)
        projection = {"train": float(np.linalg.norm(proj_t[train]) / q_norm["train"]),
                      "test": float(np.linalg.norm(proj_t[test]) / q_norm["test"])}
        dispersion = None
        if not np.any(model.initial_velocity):        # the formula is for a release from rest
            dispersion = dispersion_error(system, model.initial_displacement, dt, times[test], r, q_norm["test"])
        q0 = data.states[:, 0]
        for method in METHODS:
            tic = time.perf_counter()
            if method == "galerkin":
                rom = SecondOrderROM.galerkin(system, V, product=M, mass_orthonormal=True)
            else:
                learner = (LagrangianOpInf if method == "lopinf" else SecondOrderOpInf)(
                    ["damping"] if study.damping else ())
                rom = SecondOrderROM(learner=learner, basis=V, product=M).fit(data)
            fit_seconds = time.perf_counter() - tic
            with np.errstate(over="ignore", invalid="ignore"):
                tic = time.perf_counter()
                solution = rom.predict(q0, times, v0=np.zeros(r))
                online = time.perf_counter() - tic
                err_t = _m_norms(Q - V @ solution.q, M)
                energy = fom_energy(system, V @ solution.q, V @ solution.v)
            energy_error = np.abs(energy - E0) / E0
            finite = np.all(np.isfinite(solution.q))
            blowup = None
            if not finite or np.nanmax(np.abs(solution.energy)) > 1e6 * abs(solution.energy[0]):
                big = ~np.isfinite(solution.energy) | (np.abs(solution.energy) > 1e6 * abs(solution.energy[0]))
                blowup = float(times[np.argmax(big)])
            ops = rom.operators_
            eig = ops.eigenvalues()
            row = {
                "method": method, "r": r, "dt": dt,
                "train_error": float(np.linalg.norm(err_t[train]) / q_norm["train"]),
                "test_error": float(np.linalg.norm(err_t[test]) / q_norm["test"]),
                "projection_error": projection["test"],
                "projection_error_train": projection["train"],
                "dispersion_error": dispersion,
                "predicted_learned_error": None if dispersion is None else float(np.hypot(projection["test"],
                                                                                          dispersion)),
                "error_over_projection": float(np.linalg.norm(err_t[test]) / q_norm["test"]
                                               / projection["test"]),
                "energy_error_max": float(np.nanmax(energy_error)) if finite else float("inf"),
                "energy_error_train_max": float(np.nanmax(energy_error[train])),
                "rom_energy_growth": float(np.nanmax(np.abs(solution.energy)) / abs(solution.energy[0])),
                "blowup_time": blowup,
                "stiffness_min_eig": float(eig["stiffness"][0]),
                "stiffness_asymmetry": float(np.linalg.norm(ops.stiffness - ops.stiffness.T)
                                             / np.linalg.norm(ops.stiffness)),
                "damping_min_eig": float(eig["damping"][0]) if "damping" in eig else None,
                "online_seconds": online,
                "offline_seconds": fom_train_seconds + pod_seconds + reduce_seconds + fit_seconds,
                "fit_seconds": fit_seconds,
                "fom_seconds": fom_seconds,
                "speedup": fom_seconds / online,
            }
            rows.append(row)
            if r == study.main_rank:
                curves[method] = {"state_error": err_t / scale, "energy_error": energy_error,
                                  "tip": None if tip is None else np.asarray(tip @ (V @ solution.q)).ravel()}
        if r == study.main_rank:
            curves["projection"] = {"state_error": proj_t / scale}
    return {
        "settings": asdict(study), "n_dofs": system.n_dofs, "times": times,
        "train_window": float(times[n_train]), "fom_seconds": fom_seconds,
        "fom_summary": asdict(fom_summary), "fom_energy_drift": float(np.max(np.abs(E_fom - E0)) / E0),
        "fom_tip": None if tip is None else np.asarray(tip @ Q).ravel(),
        "rows": rows, "curves": curves,
    }


def write_rom_report(out_dir: Path, study_result: dict, prefix: str = "") -> dict:
    """Plots (file names start with ``prefix``) and the table of the ROM study; returns the metrics part."""
    from femrom.post import plot_accuracy_cost_groups, plot_time_series

    res = study_result
    t, T = res["times"], res["train_window"]
    r = res["settings"]["main_rank"]
    c = res["curves"]
    names = {"galerkin": "intrusive Galerkin", "lopinf": "L-OpInf", "plain_opinf": "plain OpInf"}
    series = {f"{names[m]} (r={r})": c[m]["state_error"] for m in METHODS}
    series[f"projection (r={r})"] = c["projection"]["state_error"]
    plot_time_series(out_dir / f"{prefix}rom_state_error.png", t, series, logy=True, shade=(0.0, T),
                     envelope=400, ymax=10.0,
                     ylabel="||q - V q^||_M / max ||q||_M (bin max)",
                     title=f"beam ROMs (dt = {res['settings']['dt']:g}): state error, trained on [0, {T:g}] s")
    plot_time_series(out_dir / f"{prefix}rom_energy_error.png", t,
                     {f"{names[m]} (r={r})": c[m]["energy_error"] for m in METHODS}, logy=True,
                     envelope=400, ymax=10.0,
                     shade=(0.0, T), ylabel="|E(V q^, V q^') - E0| / E0",
                     title=f"beam ROMs (dt = {res['settings']['dt']:g}): energy error "
                           "(FOM energy of the reconstructed state)")
    if res["fom_tip"] is not None:
        last = t >= t[-1] - 2 * T
        tips = {"FOM": res["fom_tip"][last]}
        tips.update({names[m]: c[m]["tip"][last] for m in METHODS})
        plot_time_series(out_dir / f"{prefix}rom_tip_end.png", t[last], tips, ylabel="tip deflection [m]",
                         title=f"tip deflection over the last {2 * T:g} s of the prediction (r={r})")
    rows = res["rows"]
    plot_accuracy_cost_groups(out_dir / f"{prefix}accuracy_cost_rom.png", rows, "online_seconds", "test_error", "r",
                              "method", title="ROM test error vs online time (labels: r)")
    plot_accuracy_cost_groups(out_dir / f"{prefix}accuracy_cost_rom_r.png",
                              [dict(x, r_=x["r"]) for x in rows], "r", "test_error", "r", "method",
                              title="ROM test error vs r")
    return {k: v for k, v in res.items() if k not in ("times", "curves", "fom_tip")}


ROM_COLUMNS = ["method", "r", "train_error", "test_error", "projection_error", "error_over_projection",
               "predicted_learned_error", "energy_error_max", "blowup_time", "online_seconds", "offline_seconds",
               "speedup"]


def run(out_dir, *, quick: bool = False, scene_path=SCENE, rom: RomStudy | None = None,
        paper: bool = False, ladders: bool = True) -> dict:
    """Run the case; return its metrics (also written to ``out_dir/metrics.json``).

    ``rom`` overrides the ROM study's settings (default :class:`RomStudy`,
    :data:`QUICK_ROM` with ``quick``, :data:`PAPER_ROM` with ``paper``);
    ``ladders=False`` skips the FOM dt and mesh ladders.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    scene = Scene.from_toml(scene_path)
    if quick:
        scene = with_time_step(dataclasses.replace(
            scene, time=dataclasses.replace(scene.time, t_end=0.5)), 4 * scene.time.dt)

    tic = time.perf_counter()
    model = build(scene)
    build_seconds = time.perf_counter() - tic
    result = simulate(model)
    energy = result.energy
    drift = float(np.max(np.abs(energy - energy[0])) / energy[0])

    plot_response(out_dir / "response.png", result.times, result.outputs, model.system.output_names,
                  energy, title=f"cantilever FOM, {model.system.n_dofs} dofs, {result.summary['scheme']}")
    (out_dir / "scene.toml").write_text(scene.source_text)

    dt_rows = mesh_rows = []
    if ladders:
        dt_rows = time_step_ladder(scene, factors=(8, 4, 2, 1) if not quick else (4, 2, 1))
        mesh_rows = mesh_ladder(scene, (0.1, 0.05, 0.025) if quick else (0.2, 0.1, 0.05, 0.025, 0.0125))
        plot_accuracy_cost(out_dir / "accuracy_cost_dt.png", dt_rows, "stepping_seconds", "tip_error", "dt",
                           title="FOM time step: tip error vs stepping time")
        plot_accuracy_cost(out_dir / "accuracy_cost_mesh.png", mesh_rows, "seconds", "frequency_error",
                           "dofs", title="FOM mesh: frequency error vs build + eigensolve time")

    study = rom if rom is not None else (QUICK_ROM if quick else PAPER_ROM if paper else RomStudy())
    tic = time.perf_counter()
    rom_metrics = write_rom_report(out_dir, rom_study(Scene.from_toml(scene_path), study))
    rom_metrics["total_seconds"] = time.perf_counter() - tic
    coarse = QUICK_COARSE_ROM if quick else COARSE_ROM
    with np.errstate(over="ignore", invalid="ignore"):
        coarse_metrics = write_rom_report(out_dir, rom_study(Scene.from_toml(scene_path), coarse),
                                          prefix="coarse_")

    omega = fe_frequencies(model)
    exact = analytic_frequencies(scene)
    metrics = {
        "case": "beam", "scene": scene.name, "n_dofs": model.system.n_dofs,
        "machine": machine_description(),
        "build_seconds": build_seconds, "build_timings": model.timings,
        "simulation": result.summary,
        "energy_relative_drift": drift,
        "frequencies_hz": omega / (2 * np.pi), "analytic_frequencies_hz": exact / (2 * np.pi),
        "time_step_ladder": dt_rows, "mesh_ladder": mesh_rows,
        "boundary_conditions": "cantilever: deflection and slope clamped at x = 0, free at x = L",
        "rom": rom_metrics,
        "rom_coarse_data": coarse_metrics,
    }
    write_metrics(out_dir / "metrics.json", metrics)
    report = [
        f"# {scene.description}", "",
        f"{model.system.n_dofs} free dofs, {result.summary['n_steps']} steps of {scene.time.dt:g} s "
        f"with {result.summary['scheme']} in {result.summary['stepping_seconds']:.2f} s; "
        f"relative energy drift {drift:.2e}.", "",
    ]
    if dt_rows:
        report += [            "## Time step: tip error (vs dt/8) against stepping time", "",
            accuracy_cost_table(dt_rows, ["dt", "steps", "tip_error", "stepping_seconds"]), "",
            f"Observed order {dt_rows[0]['observed_order']:.2f}; Newmark average acceleration is second "
            "order once every excited mode is resolved (omega dt << 1). The release from a static tip "
            "load excites the whole spectrum (modal amplitudes fall only as 1/omega^2), so at these steps "
            "the phase errors of the higher modes, which grow with their frequency, keep the observed "
            "tip-error order below 2 (pre-asymptotic); the energy stays conserved at every step size.", "",
            "## Mesh: first four natural frequencies against the analytic roots", "",
            accuracy_cost_table(mesh_rows, ["mesh_size", "dofs", "frequency_error", "f1_hz", "seconds"]), "",
        ]
    st = rom_metrics["settings"]
    report += [
        "## ROMs: intrusive Galerkin, L-OpInf and plain OpInf on the same data and basis", "",
        f"FOM with {rom_metrics['n_dofs']} dofs, Newmark dt = {st['dt']:g} s over "
        f"{st['extension']:g} x the training window [0, {rom_metrics['train_window']:g}] s "
        f"({rom_metrics['fom_seconds']:.2f} s); mass-orthonormal POD of the training snapshots; "
        f"order-{st['derivative_order']} finite differences; both learners fit K^ and "
        f"{'C^' if st['damping'] else 'no C^'}; every ROM integrated by Newmark average acceleration "
        "at the FOM step. Errors in the mass norm over the test window (after training); energy "
        "error = FOM energy of the reconstructed ROM state against E(0), maximum over the whole window; "
        "blowup_time = first time the ROM energy exceeds 1e6 x its initial value; predicted_learned_error = "
        "sqrt(projection_error^2 + d^2), d the a priori phase error of a model that learned the data's discrete "
        "Newmark frequencies exactly and is stepped by Newmark once more (`dispersion_error` in cases/beam.py).", "",
        accuracy_cost_table(rom_metrics["rows"], ROM_COLUMNS), "",
        f"## The same on coarser snapshots (dt = {coarse_metrics['settings']['dt']:g} s)", "",
        accuracy_cost_table(coarse_metrics["rows"], ROM_COLUMNS), "",
    ]
    (out_dir / "report.md").write_text("\n".join(report))
    return metrics


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="femrom run beam", description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=Path("results") / "beam")
    parser.add_argument("--quick", action="store_true", help="short window and ladders (tests)")
    parser.add_argument("--paper", action="store_true",
                        help="finer mesh (h = 0.01, 200 dofs), dt = 2.5e-5, r up to 20")
    parser.add_argument("--ranks", type=int, nargs="+", help="basis sizes r of the ROM ladder")
    parser.add_argument("--train-window", type=float, help="training window [s]")
    parser.add_argument("--no-ladders", action="store_true", help="skip the FOM dt and mesh ladders")
    args = parser.parse_args(argv)
    study = QUICK_ROM if args.quick else PAPER_ROM if args.paper else RomStudy()
    if args.ranks:
        study = dataclasses.replace(study, ranks=tuple(args.ranks),
                                    main_rank=args.ranks[min(len(args.ranks) - 1, 3)])
    if args.train_window:
        study = dataclasses.replace(study, train_window=args.train_window)
    metrics = run(args.out, quick=args.quick, rom=study, ladders=not args.no_ladders)
    print(f"beam: {metrics['n_dofs']} dofs, {metrics['simulation']['n_steps']} steps in "
          f"{metrics['simulation']['stepping_seconds']:.2f} s, energy drift {metrics['energy_relative_drift']:.1e}, "
          f"f1 = {metrics['frequencies_hz'][0]:.3f} Hz (analytic {metrics['analytic_frequencies_hz'][0]:.3f}); "
          f"report in {args.out}")
    for row in metrics["rom"]["rows"] + metrics["rom_coarse_data"]["rows"]:
        print(f"  dt={row['dt']:g} {row['method']:>12s} r={row['r']:2d}: test error {row['test_error']:.2e} "
              f"(projection {row['projection_error']:.2e}), energy error {row['energy_error_max']:.2e}, "
              f"online {row['online_seconds']:.3f} s, speedup {row['speedup']:.0f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
