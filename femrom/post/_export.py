"""A reduced model's prediction back in the user's tools: a ParaView series on their mesh, outputs as CSV.

:func:`export_prediction` writes the reconstructed displacement ``V q^(t_k)`` of a
prediction on the mesh the snapshots came with (femrom's own model of an ingested
series, :class:`~femrom.snapshots.IngestedModel`, or any vector P1/P2 space with its
condensation), the error field against a reference trajectory when one is given
(e.g. the ingested test series), and the outputs ``y(t_k)`` as a CSV table with a
``t`` column. Fields are rebuilt one time at a time: nothing of size (n, k) is formed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from femrom._errors import FemromValueError
from femrom.post._render import mesh_arrays, vertex_displacements, write_vtu_series


class _LazySteps:
    """``steps[k]`` -> (n_v, 3) vertex values of the free-dof vector ``column(k)``."""

    def __init__(self, space, condensation, column, size: int):
        self.space, self.condensation, self.column, self.size = space, condensation, column, size

    def __len__(self) -> int:
        return self.size

    def __getitem__(self, k: int) -> np.ndarray:
        return vertex_displacements(self.space.basis, self.condensation.expand(self.column(k)))


def export_prediction(path, space, condensation, times, basis: np.ndarray, reduced: np.ndarray, *,
                      reference=None, outputs: np.ndarray | None = None, output_names=(), every: int = 1) -> dict:
    r"""Write ``<path>.pvd`` (+ ``.vtu`` per written time) and, with ``outputs``, ``<path>_outputs.csv``.

    Parameters
    ----------
    path : str or Path
        The ``.pvd`` file (its stem names the pieces and the CSV).
    space, condensation
        A vector space of femrom (``space.basis`` with ``nodal_dofs``) and its free-dof map.
    times : (k,) ndarray
    basis : (n_free, r) ndarray
        ``V``.
    reduced : (r, k) ndarray
        ``q^(t_k)`` of the prediction.
    reference : callable, optional
        ``reference(k) -> (n_free,)`` displacement of the reference at ``t_k``: the series
        then also holds ``error = V q^ - q_ref``.
    outputs : (p, k) ndarray, optional
        Written as CSV, one column per output (``output_names``, default ``y0, y1, ...``).
    every : int
        Write every ``every``-th time to the ParaView series (the CSV keeps all).

    Returns
    -------
    dict
        ``{"pvd": Path, "csv": Path or None, "written_times": int}``.
    """
    path = Path(path).with_suffix(".pvd")
    times = np.asarray(times, dtype=float)
    reduced = np.asarray(reduced, dtype=float)
    if reduced.shape != (basis.shape[1], times.size):
        raise FemromValueError(f"reduced has shape {reduced.shape}, expected (r, k) = ({basis.shape[1]}, {times.size})")
    picked = np.arange(0, times.size, int(every))
    fields = {"displacement": _LazySteps(space, condensation, lambda i: basis @ reduced[:, picked[i]], picked.size)}
    if reference is not None:
        fields["error"] = _LazySteps(space, condensation,
                                     lambda i: basis @ reduced[:, picked[i]] - reference(picked[i]), picked.size)
    points, cells = mesh_arrays(space.mesh)
    pvd = write_vtu_series(path, points, cells[:, :4], times[picked], fields)
    csv = None
    if outputs is not None:
        outputs = np.atleast_2d(np.asarray(outputs, dtype=float))
        if outputs.shape[1] != times.size:
            raise FemromValueError(f"outputs have {outputs.shape[1]} columns for {times.size} times")
        names = list(output_names) or [f"y{i}" for i in range(outputs.shape[0])]
        csv = path.with_name(f"{path.stem}_outputs.csv")
        np.savetxt(csv, np.column_stack([times, outputs.T]), delimiter=",", header=",".join(["t", *names]),
                   comments="")
    return {"pvd": pvd, "csv": csv, "written_times": int(picked.size)}
