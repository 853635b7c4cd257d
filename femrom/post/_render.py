r"""Deformed-shape renders (PyVista, off-screen) and ParaView time series (.pvd of .vtu).

Solid displacement fields live on the vertices of a tetrahedral mesh here:
:func:`vertex_displacements` reads the vertex values of a full (P1 or P2)
field ``u`` of length ``n_total`` (P2 edge-midpoint values are not drawn:
the surface is the linear interpolant of the vertex values).

- :func:`render_grid`: a rows x columns grid of deformed meshes, each coloured
  by ``|u|`` with one colour range for all panels (e.g. rows FOM / ROM,
  columns times), to a PNG;
- :func:`write_vtu_series`: one ``.vtu`` per time (meshio) and the ``.pvd``
  collection ParaView opens as a time series.

PyVista is optional (``pip install pyvista``); :func:`render_available` says
whether it can draw here and why not. Headless machines render through EGL
(``VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow``, set before pyvista is
imported unless the caller set another window class).
"""

from __future__ import annotations

import os
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from femrom._errors import FemromRuntimeError, FemromValueError

_REASON: list[str] = []


def _pyvista():
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista

    pyvista.OFF_SCREEN = True
    return pyvista


def render_available() -> tuple[bool, str]:
    """``(True, version)`` if PyVista draws off-screen here, else ``(False, reason)``.

    Draws one small test image once per process (a missing EGL/OSMesa
    library or display shows up only when a window is made).
    """
    if _REASON:
        return _REASON[0] == "ok", _REASON[1]
    try:
        pv = _pyvista()
        plotter = pv.Plotter(off_screen=True, window_size=(32, 24))
        plotter.add_mesh(pv.Cube())
        image = plotter.screenshot(return_img=True)
        plotter.close()
        if image is None or image.size == 0:
            raise FemromRuntimeError("the off-screen window returned no image")
        window = os.environ.get("VTK_DEFAULT_OPENGL_WINDOW", "default window")
        _REASON.extend(["ok", f"pyvista {pv.__version__}, vtk {pv.vtk_version_info}, {window}"])
    except Exception as exc:  # ImportError, missing GL libraries, no display
        _REASON.extend(["no", f"{type(exc).__name__}: {exc}"])
    return _REASON[0] == "ok", _REASON[1]


def mesh_arrays(mesh) -> tuple[np.ndarray, np.ndarray]:
    """``(points (n_v, 3), cells (n_e, 4))`` of a skfem ``MeshTet``."""
    return np.ascontiguousarray(mesh.p.T, dtype=float), np.ascontiguousarray(mesh.t.T, dtype=np.int64)


def vertex_displacements(basis, field: np.ndarray) -> np.ndarray:
    """(n_v, 3) vertex values of a full vector field on ``basis`` (skfem vector P1/P2).

    Parameters
    ----------
    basis : skfem.CellBasis
        ``ElementVector(ElementTetP1/P2)``; ``basis.nodal_dofs`` is (3, n_v).
    field : (n_total,) ndarray
        All dofs, fixed ones included (``Condensation.expand``).
    """
    field = np.asarray(field, dtype=float)
    if field.shape != (basis.N,):
        raise FemromValueError(f"field has shape {field.shape}, expected ({basis.N},)")
    return field[np.asarray(basis.nodal_dofs)].T.copy()


def _surface(grid):
    """Outer surface (the explicit algorithm keeps pyvista >= 0.47 quiet; older ones lack it)."""
    try:
        return grid.extract_surface(algorithm="dataset_surface")
    except TypeError:
        return grid.extract_surface()


def _grid(pv, points, cells):
    cell_array = np.hstack([np.full((cells.shape[0], 1), 4, dtype=np.int64), cells]).ravel()
    types = np.full(cells.shape[0], pv.CellType.TETRA, dtype=np.uint8)
    return pv.UnstructuredGrid(cell_array, types, points)


def render_grid(path, points: np.ndarray, cells: np.ndarray, panels, *, titles=(), row_labels=(),
                warp: float | None = None, window_size=(1400, 700), camera=None,
                scalar_label="|u| [mm]", scale: float = 1e3) -> Path:
    r"""Deformed meshes ``x + warp u`` coloured by ``scale |u|``, one panel per field.

    Parameters
    ----------
    path : str or Path
        PNG to write.
    points : (n_v, 3) ndarray
        Undeformed vertex coordinates.
    cells : (n_e, 4) int ndarray
        Tetrahedra.
    panels : list of lists of (n_v, 3) ndarray
        ``panels[i][j]`` is the displacement drawn in row ``i``, column ``j``.
    titles : sequence of str
        One per column (e.g. the times).
    row_labels : sequence of str
        One per row (e.g. ``"FOM"``, ``"L-OpInf r = 8"``), prefixed to titles.
    warp : float, optional
        Displacement magnification; default: the largest ``|u|`` drawn is 10 %
        of the mesh's largest extent (stated in the first title).
    camera : str or list, optional
        PyVista camera position (default: an oblique view from above).
    scalar_label : str
        Colour-bar title; ``scale`` converts ``|u|`` to its unit (1e3: mm).

    Returns
    -------
    Path
    """
    pv = _pyvista()
    points = np.asarray(points, dtype=float)
    rows = len(panels)
    cols = max(len(r) for r in panels)
    peak = max(float(np.max(np.linalg.norm(u, axis=1))) for row in panels for u in row)
    extent = float(np.max(np.ptp(points, axis=0)))
    if warp is None:
        warp = 0.1 * extent / peak if peak > 0 else 1.0
    limits = (0.0, scale * peak if peak > 0 else 1.0)
    base = _grid(pv, points, np.asarray(cells))
    plotter = pv.Plotter(off_screen=True, shape=(rows, cols), window_size=tuple(window_size),
                         border=False)
    for i, row in enumerate(panels):
        for j, u in enumerate(row):
            plotter.subplot(i, j)
            grid = base.copy()
            grid.points = points + warp * np.asarray(u, dtype=float)
            grid.point_data[scalar_label] = scale * np.linalg.norm(u, axis=1)
            surface = _surface(grid)
            plotter.add_mesh(surface, scalars=scalar_label, clim=limits, cmap="viridis",
                             show_edges=False, show_scalar_bar=(i == rows - 1 and j == cols - 1),
                             scalar_bar_args={"title": scalar_label, "vertical": False, "fmt": "%.2g",
                                              "position_x": 0.2, "position_y": 0.03, "width": 0.6,
                                              "height": 0.08, "title_font_size": 12,
                                              "label_font_size": 10})
            outline = _surface(base).extract_feature_edges(feature_angle=30)
            plotter.add_mesh(outline, color="grey", line_width=1, opacity=0.5)
            label = " ".join(x for x in ((row_labels[i] if i < len(row_labels) else ""),
                                         (titles[j] if j < len(titles) else "")) if x)
            if i == 0 and j == 0:
                label += f"  (x{warp:.3g})"
            plotter.add_text(label, font_size=9, position="upper_left")
            if camera is None:
                plotter.camera_position = "xy"
                plotter.camera.elevation = -55
                plotter.camera.azimuth = -25
            else:
                plotter.camera_position = camera
            plotter.reset_camera()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    plotter.screenshot(str(path))
    plotter.close()
    return path


def write_vtu_series(path, points: np.ndarray, cells: np.ndarray, times, fields: dict) -> Path:
    """ParaView time series: ``<stem>_NNNN.vtu`` per time and the ``<stem>.pvd`` collection.

    Parameters
    ----------
    path : str or Path
        The ``.pvd`` file; the ``.vtu`` files go next to it.
    points, cells : as :func:`render_grid`
    times : (k,) array_like
    fields : dict of str to (k, n_v, 3) or (k, n_v) ndarray
        Point data per time (e.g. ``{"displacement": U}``); a vector field
        also gets its magnitude as ``"<name>_magnitude"``.

    Returns
    -------
    Path
        The ``.pvd`` file.
    """
    import meshio

    path = Path(path).with_suffix(".pvd")
    path.parent.mkdir(parents=True, exist_ok=True)
    times = np.asarray(times, dtype=float)
    entries = []
    for k, t in enumerate(times):
        data = {}
        for name, values in fields.items():
            values = np.asarray(values[k], dtype=float)
            data[name] = values
            if values.ndim == 2:
                data[f"{name}_magnitude"] = np.linalg.norm(values, axis=1)
        piece = path.with_name(f"{path.stem}_{k:04d}.vtu")
        meshio.write(piece, meshio.Mesh(points, [("tetra", cells)], point_data=data), binary=True)
        entries.append(f'    <DataSet timestep="{t:.9g}" group="" part="0" file={quoteattr(piece.name)}/>')
    text = "\n".join(['<?xml version="1.0"?>',
                      '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
                      "  <Collection>", *entries, "  </Collection>", "</VTKFile>", ""])
    path.write_text(text)
    return path


__all__ = ["mesh_arrays", "render_available", "render_grid", "vertex_displacements", "write_vtu_series"]
