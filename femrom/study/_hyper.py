r"""Hyper-reduction of a study's learned ROMs: the known force's potential sampled by ECSW.

A learned ROM with a known conservative force ``V^T f(V q^)`` (``projected_force``,
``O(n r)`` a call) gets the reduced potential sampled on a few nodes ``S`` with
weights ``xi_j >= 0`` (:func:`femrom.rom.ecsw_weights`),

.. math::

    \Phi^(q^) = \sum_{j \in S} \xi_j\, \phi_j((V q^)_j), \qquad
    f^(q^) = \nabla \Phi^(q^) = V_S^T (\xi \odot \phi'(V_S q^)),

so the reduced force stays the exact gradient of a reduced potential (the ROM stays
Lagrangian). The ROM's other terms (the learned ``K^``, ``M^``, ...) are kept.
"""

from __future__ import annotations

from femrom.rom import HyperReducedPotential, SecondOrderROM, ecsw_weights
from femrom.study._histories import extra_rom_rows
from femrom._timing import call_cost

#: what a hyper-reduced row adds to a study's row: samples, the ECSW fit, seconds per call of
#: the sampled force and tangent and of the unsampled (projected) ones, the learner's step
#: timed alongside
HYPER_COLUMNS = ("samples", "ecsw_residual", "ecsw_seconds", "force_call_seconds", "tangent_call_seconds",
                 "projected_force_call_seconds", "projected_tangent_call_seconds")


def hyper_reduced_rows(state, *, learner: str = "lopinf", tolerance: float = 1e-3, stride: int = 1,
                       label: str | None = None) -> tuple[list[dict], dict]:
    """Per r, the study's ``learner`` ROM with its ``projected_force`` replaced by the ECSW-sampled
    potential of the system's nonlinear force, as rows of the study's form (:func:`extra_rom_rows`).

    The ECSW fit (relative residual ``tolerance``) matches the reduced force on every
    ``stride``-th training state reconstructed from the basis, ``V_r Q^_train[:, ::stride]``.
    Each row (learner ``label``, default ``learner + "_hyper"``) is evaluated like the
    study's ROMs and timed interleaved with the ``learner`` ROMs (``{learner}_seconds_per_step``,
    ``speedup_over_{learner}``); it carries :data:`HYPER_COLUMNS` (the calls timed at the
    training run's initial state), and ``nodes`` (k,) and ``weights`` (k,) of the sampled potential.

    Returns the rows (in the order of r) and their evaluations by ``(r, label, run)``.
    """
    label = label or f"{learner}_hyper"
    nl, V, product = state.model.system.nonlinear, state.basis, state.product
    train_states = state.projections[state.config.train[0].name].coordinates
    q0 = state.runs[state.config.train[0].name].q0
    roms, fits = {}, {}
    for row in state.rows:
        if row["learner"] != learner:
            continue
        r, learned = row["r"], row["_rom"]
        Vr = V[:, :r]
        nodes, xi, info = ecsw_weights(nl, Vr, Vr @ train_states[:r, ::stride], tolerance=tolerance)
        hyper = HyperReducedPotential.from_potential(nl, Vr, nodes, xi)
        roms[(r, label)] = SecondOrderROM(learned.operators_.without("projected_force").with_terms(hyper), Vr,
                                          product=product)
        projected = learned.operators_.term("projected_force")
        q0_r = Vr.T @ (product @ q0)
        calls = {"force": hyper.force, "tangent": hyper.tangent, "projected_force": projected.force,
                 "projected_tangent": projected.tangent}
        fits[r] = {"samples": int(nodes.size), "nodes": nodes, "weights": hyper.weights,
                   "ecsw_residual": info["residual"], "ecsw_seconds": info["seconds"],
                   **{f"{name}_call_seconds": call_cost(fn, q0_r).seconds for name, fn in calls.items()}}
    rows, evaluations = extra_rom_rows(state, roms, alongside=(learner,))
    return [row | fits[row["r"]] for row in rows], evaluations
