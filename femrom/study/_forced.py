r"""Stepped-sine forced responses: one model's beside its linearisation, several models against a reference.

:func:`stepped_sine_response` runs a model with a stateful force from its committed rest state at
force levels ``F`` and lists, beside each first-harmonic output amplitude, the amplitude ``F H(f)``
of the model linearised there (:func:`femrom.post.linear_accelerance`: a stuck joint), the
small-force limit the nonlinear response tends to.

For :func:`compare_stepped_sines`, every model on its :class:`~femrom.integrators.Shaker` (the full model,
a Galerkin or a learned ROM alike) runs the same :class:`~femrom.integrators.SteppedSine` at the same
force levels. Per model and level, the
first-harmonic amplitude of one output is compared with the reference's: the peak (parabolic
interpolation around the discrete maximum) in frequency and in amplitude, and the worst relative
amplitude difference over the frequencies.
"""

from __future__ import annotations

import time

import numpy as np

from femrom._errors import FemromValueError
from femrom.integrators import HarmonicBalance, HarmonicBalanceError, Shaker, SteadyStateCriterion, SteppedSine, StepResult
from femrom.post import linear_accelerance
from femrom.study.experiments.stepped_sine import peak_rows


def stepped_sine_response(system, rest_state, input: int, frequencies, levels, *, steps_per_period: int,
                          tolerance: float, linear_key: str = "linear_amplitude", progress=None,
                          batched: bool = False):
    """``(result, rows)``: the stepped sine of ``system`` driven through input column ``input`` at the force
    ``levels`` [N] over ``frequencies`` [Hz], from rest in the committed force state ``rest_state``
    (:class:`~femrom.integrators.Shaker`, :class:`~femrom.integrators.SteppedSine` with
    ``steps_per_period`` steps per period and :class:`~femrom.integrators.SteadyStateCriterion` at
    ``tolerance``).

    ``batched``: step the levels together (:meth:`~femrom.integrators.SteppedSine.run_batched`, the same
    result; one compiled call per period for all levels on a reduced model with a compiled joint).

    ``rows``: ``result.rows()`` with, in every point of every output, ``linear_key``: ``F |H(f)|`` of the
    model linearised at rest (:func:`femrom.post.linear_accelerance`), in the outputs' acceleration units."""
    force = np.asarray(system.input_matrix[:, input]).ravel()
    plant = Shaker(system, force, rest=StepResult.at_rest(system.n_dofs, state=rest_state))
    sweep = SteppedSine(np.asarray(frequencies), steps_per_period=steps_per_period,
                        steady_state=SteadyStateCriterion(tolerance=tolerance))
    result = (sweep.run_batched if batched else sweep.run)(plant, list(levels), progress=progress)
    per_newton = linear_accelerance(system, rest_state, force, frequencies)
    rows = result.rows()
    for level in rows:
        for i, name in enumerate(system.output_names):
            for j, point in enumerate(level["outputs"][name]):
                point[linear_key] = float(level["force_n"] * per_newton[i, j])
    return result, rows




def compare_stepped_sines(reference, plants: dict, sweep: SteppedSine, levels, *, output: int = 0,
                          progress=None) -> dict:
    """Run ``sweep`` on ``reference`` and on every plant of ``plants`` (by name) at the force ``levels``.

    Returns
    -------
    dict with ``results`` (``{name: SteppedSineResult}``, the reference under ``"reference"``),
    ``seconds`` (per plant) and ``rows``: one per model and level (:func:`peak_rows`: ``peak_frequency_hz``,
    ``peak_amplitude``, ``peak_frequency_difference_hz`` (model - reference), ``peak_amplitude_error``
    (relative, signed), ``amplitude_max_error`` (max over frequencies of ``|A_model / A_reference - 1|``)).
    """
    results, seconds = {}, {}
    for name, plant in {"reference": reference, **plants}.items():
        tic = time.perf_counter()
        results[name] = sweep.run(plant, list(levels))
        seconds[name] = time.perf_counter() - tic
        if progress is not None:
            peaks = ", ".join(f"{level.force_n:g} N: {level.peaks()[output].frequency_hz:.3f} Hz / "
                              f"{level.peaks()[output].amplitude:.4g}" for level in results[name].levels)
            progress(f"  stepped sine {name}: {peaks} ({seconds[name]:.1f} s)")
    rows = [{"model": name, **row, "seconds": seconds[name]}
            for name in plants for row in peak_rows(results[name], results["reference"], output)]
    return {"results": results, "rows": rows, "seconds": seconds}


def harmonic_balance_sweep(system, rest_state, input: int, frequencies, levels, *, harmonics: int = 3,
                           samples: int | None = None, progress=None) -> dict:
    r"""The stepped sine of ``system`` by harmonic balance: per force level [N] the periodic solution at each of
    ``frequencies`` [Hz] in the given order (a sweep, as the test does it), each from the previous one with its Jacobian (chord steps:
    :meth:`~femrom.integrators.HarmonicBalance.solve`).

    :class:`~femrom.integrators.HarmonicBalance` with ``harmonics`` and ``samples`` (AFT), the force
    ``F sin(Omega t)`` on input column ``input``, the force's march starting from ``rest_state``. Where a
    fold makes Newton fail from the previous point, the step is split in two, then the point is solved
    from the model linearised at rest; a point that still fails raises
    :class:`~femrom.integrators.HarmonicBalanceError`.

    Returns ``{"rows": [...], "iterations": [...], "seconds": s}``: ``rows`` in the stepped sine's format
    (:func:`stepped_sine_response`): per level ``force_n``, ``quantity`` "acceleration" and per output the
    points ``frequency_hz``, ``amplitude_m_s2`` (``Omega^2 |Y|``), ``phase_rad`` (the acceleration's
    fundamental relative to the force, in ``(-pi, pi]``), ``linear_amplitude_m_s2`` (the model
    linearised at rest), ``harmonics_ratio`` (the higher harmonics' acceleration amplitude over the
    fundamental's); ``iterations`` per level the Newton iterations per point.
    """
    tic = time.perf_counter()
    frequencies, levels = _sweep_grid(frequencies, levels)
    hb = HarmonicBalance(system, input, harmonics=harmonics, samples=samples, state=rest_state)
    names = list(system.output_names or [f"y{i}" for i in range(hb.output_matrix.shape[0])])
    per_newton = linear_accelerance(system, rest_state, hb.force_vector, frequencies)
    H = hb.basis.harmonics
    order = np.repeat(np.arange(1, H + 1), 2)
    rows, iterations = [], []
    for level in levels:
        level = float(level)
        points = {name: [] for name in names}
        counts, z, chord = [], None, {}
        for j, f in enumerate(frequencies):
            omega = 2 * np.pi * f
            solution = _sweep_point(hb, omega, level, z, None if j == 0 else 2 * np.pi * frequencies[j - 1], chord)
            z = solution.coefficients.reshape(-1)
            counts.append(solution.iterations)
            Y = hb.phasor(solution.coefficients)
            coefficients = hb.output_coefficients(solution.coefficients)[1:]        # (2H, p)
            accelerations = (order[:, None] * omega) ** 2 * np.abs(coefficients)
            for i, name in enumerate(names):
                fundamental = omega**2 * abs(Y[i])
                pairs = accelerations[:, i].reshape(H, 2)
                higher = float(np.sqrt(np.sum(pairs[1:] ** 2))) if H > 1 else 0.0
                phase = float(np.angle(-Y[i]))             # acceleration -Omega^2 y: the phasor turned by pi
                points[name].append({"frequency_hz": float(f), "amplitude_m_s2": float(fundamental),
                                     "phase_rad": phase,
                                     "linear_amplitude_m_s2": float(level * per_newton[i, j]),
                                     "harmonics_ratio": higher / fundamental if fundamental > 0 else 0.0})
        rows.append({"force_n": level, "quantity": "acceleration", "method": f"harmonic balance, H = {H}",
                     "outputs": points})
        iterations.append(counts)
        if progress is not None:
            peak = max(p["amplitude_m_s2"] for p in points[names[-1]])
            progress(f"{level:g} N: {len(frequencies)} frequencies, {np.mean(counts):.1f} Newton iterations a point, "
                     f"peak {names[-1]} {peak:.3g} m/s^2 ({time.perf_counter() - tic:.1f} s)")
    return {"rows": rows, "iterations": iterations, "seconds": time.perf_counter() - tic}


def _sweep_grid(frequencies, levels) -> tuple[np.ndarray, list]:
    """Checked ``(frequencies (k,), levels)``: positive finite frequencies [Hz], finite forces >= 0 [N], neither
    empty (one FemromValueError naming the culprit)."""
    f = np.asarray(frequencies, dtype=float).reshape(-1)
    if f.size == 0 or not np.all(np.isfinite(f)) or not np.all(f > 0):
        raise FemromValueError(f"frequencies must be positive and finite (Hz), at least one, got {f.tolist()}")
    F = np.asarray(levels, dtype=float).reshape(-1)
    if F.size == 0 or not np.all(np.isfinite(F)) or not np.all(F >= 0):
        raise FemromValueError(f"levels must be finite forces >= 0 (N), at least one, got {F.tolist()}")
    return f, [float(x) for x in F]


def _sweep_point(hb, omega, force, z, previous_omega, chord, depth: int = 0):
    """One point of :func:`harmonic_balance_sweep`: from ``z`` (the previous point) reusing its Jacobian
    (``chord``), splitting the step on failure."""
    try:
        return hb.solve(omega, force, initial=z, chord=chord)
    except HarmonicBalanceError:
        if z is None or depth >= 2:
            if z is not None:
                return hb.solve(omega, force)
            raise
    middle = 0.5 * (omega + previous_omega)
    half = _sweep_point(hb, middle, force, z, previous_omega, chord, depth + 1)
    return _sweep_point(hb, omega, force, half.coefficients.reshape(-1), middle, chord, depth + 1)


def periodic_training(system, rest_state, input: int, frequency: float, forces, *, harmonics: int = 1,
                      samples: int | None = None) -> list:
    """Training states of a hyper-reduction from periodic solutions: ``[(q (n,), state), ...]``.

    The periodic solution of ``system`` under ``F sin(2 pi frequency t)`` on input ``input`` at each of
    ``forces`` (harmonic balance, each from the previous), and at every AFT sample the coordinates
    with the force's state there (:meth:`~femrom.integrators.HarmonicBalance.periodic_states`): the
    motions a frequency-domain study computes, for :func:`femrom.rom.ecsw_joint`."""
    (frequency,), forces = _sweep_grid([frequency], forces)
    hb = HarmonicBalance(system, input, harmonics=harmonics, samples=samples, state=rest_state)
    omega, z, snapshots = 2 * np.pi * frequency, None, []
    for force in forces:
        solution = hb.solve(omega, float(force), initial=z)
        z = solution.coefficients.reshape(-1)
        q, _, states = hb.periodic_states(solution.coefficients, omega)
        snapshots.extend(zip(q, states))
    return snapshots
