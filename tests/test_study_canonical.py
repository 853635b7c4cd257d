"""Canonical Hamiltonian learners in the [rom] pipeline: H-OpInf on a conservative scene.

The cantilever of ``femrom/cases/beam.toml`` (Hermite elements, 100 free dofs, no damping,
no inputs) is released from its static deflection; with ``V^T M V = I`` it is
canonical in ``(q^, p^ = q^')`` and ``hopinf`` learns symmetric ``D^_q``, ``D^_p``.
"""

from pathlib import Path

import numpy as np
import pytest

from femrom.cases import scene_file
from femrom.inference import ForcePotential
from femrom.scene import Scene, SceneError, build
from femrom.study import run_study
from femrom.study._canonical import check_canonical_learners

DATA = Path(__file__).parent / "data"


def _beam(folder, learners, *, cubic=None, damping=False, product="mass", ranks=(4, 8)) -> Scene:
    text = scene_file("beam").read_text().replace("t_end = 2.0", "t_end = 0.03")
    if cubic is not None:   # a hardening spring at the tip: the cubic force equals the beam's tip stiffness at ~9 mm
        text = text.replace("bending = {}", "bending = {}\nspring_layer = { at = \"right\", component = \"w\", "
                                            f"cubic = {cubic} }}")
    if damping:
        text = text.replace("bending = {}", "bending = {}\ndamping = { kind = \"rayleigh\", alpha = 1.0, beta = 0.0 }")
    text += f"""
[rom]
learners = {list(learners)!r}
basis = {{ ranks = {list(ranks)!r}, product = {product!r} }}
extension = 2.0
timing = {{ repeats = 3, min_block_seconds = 0.01 }}
[[rom.train]]
name = "release"
[[rom.test]]
name = "longer"
t_end = 0.09
score_after = 0.03
""".replace("'", '"')
    path = Path(folder) / "beam.toml"
    path.write_text(text)
    return Scene.from_toml(path)


def _rows(metrics):
    return {(row["r"], row["learner"]): row for row in metrics["roms"]}


def test_hopinf_from_newmark_data_is_the_galerkin_rom(tmp_path):
    """Newmark (average acceleration) data satisfy the reduced equations exactly, ``Q^'' = -K~ Q^``,
    so H-OpInf recovers ``D^_q = K~`` and ``D^_p = I``; and on a linear system the implicit
    midpoint rule is the trapezoidal rule, i.e. Newmark average acceleration: the learned
    canonical ROM is the Galerkin ROM, to the conditioning of the fit."""
    rows = _rows(run_study(_beam(tmp_path, ["galerkin", "hopinf"]), tmp_path / "out", progress=None))
    for r in (4, 8):
        hop, gal = rows[r, "hopinf"], rows[r, "galerkin"]
        # an SVD-conditioned Lyapunov solve in the Gram of Q^ (kappa ~ 1e6-1e8 at r = 8):
        # 1e-6 relative is far below the 3e-4-3e-3 errors the rows compare
        assert hop["test_output_error"] == pytest.approx(gal["test_output_error"], rel=1e-6)
        assert hop["test_field_error"] == pytest.approx(gal["test_field_error"], rel=1e-6)
        assert hop["momentum_identity_error"] < 1e-8        # D^_p = I from p^ = q^' (measured ~1e-15)
        assert hop["stiffness_min_eig"] > 0 and hop["stiffness_symmetric"]
        assert 0.99 < hop["test_energy_ratio"] < 1.01      # midpoint keeps a quadratic H^ exactly
    # more modes, smaller error: the learned model converges with the basis, like Galerkin
    assert rows[8, "hopinf"]["test_field_error"] < 0.3 * rows[4, "hopinf"]["test_field_error"]


def test_hopinf_with_a_known_potential_tracks_galerkin_on_a_nonlinear_scene(tmp_path):
    """A cubic spring at the tip (``U = k_3 w^4 / 4``): the learners get ``V^T f(Q)`` of the stored
    snapshots, H-OpInf steps ``J grad H^`` with ``H^_nl = U(V q^)`` by the midpoint rule, Galerkin
    steps Newmark with Newton. The two schemes differ at O(dt^2) on the nonlinear term only."""
    rows = _rows(run_study(_beam(tmp_path, ["galerkin", "hopinf"], cubic=1.0e7, ranks=(8,)), tmp_path / "out",
                           progress=None))
    hop, gal = rows[8, "hopinf"], rows[8, "galerkin"]
    assert "failed" not in hop
    # measured: both ~1e-4 (0.3 % apart); 1.5x leaves room for the schemes' difference, not for
    # a force left out (without it the tip stiffens by 2x at the release amplitude: errors of O(1))
    assert hop["test_field_error"] < 1.5 * gal["test_field_error"]
    assert hop["test_field_error"] > 0.5 * gal["test_field_error"]   # not better than its own basis allows
    assert 0.99 < hop["test_energy_ratio"] < 1.01


@pytest.mark.parametrize("edit, fragment", [
    ({"damping": True}, "damping dissipates energy"),
    ({"product": "euclidean"}, "product must be 'mass'"),
])
def test_a_scene_a_canonical_model_cannot_represent_is_one_clear_error(tmp_path, edit, fragment):
    scene = _beam(tmp_path, ["lopinf", "hopinf"], **edit)
    with pytest.raises(SceneError, match=r"\[rom.learners\[1\]\] 'hopinf' learns conservative systems") as info:
        check_canonical_learners(build(scene).system, scene.rom)
    assert fragment in str(info.value)


def test_a_scene_with_inputs_is_refused_for_hopinf(tmp_path):
    text = (DATA / "bracket.toml").read_text().replace('learners = ["galerkin", "lopinf", "opinf"]',
                                                        'learners = ["hopinf"]')
    text = text.replace("damping = {", "# damping = {")      # conservative but for its input
    (tmp_path / "bracket.geo").write_text((DATA / "bracket.geo").read_text())
    (tmp_path / "bracket.toml").write_text(text)
    scene = Scene.from_toml(tmp_path / "bracket.toml")
    with pytest.raises(SceneError, match=r"'hopinf' learns conservative systems .* without inputs, "
                                         r"but the scene has 1 input\(s\)"):
        check_canonical_learners(build(scene).system, scene.rom)


def test_force_potential_is_the_force_of_a_conservative_layer(tmp_path):
    """``ForcePotential``: gradient = the force, Hessian = its tangent, value = the potential whose
    central difference is the force (cubic potential: the O(h^2) difference error is exact in h)."""
    model = build(_beam(tmp_path, ["hopinf"], cubic=1.0e7))
    force = model.system.nonlinear
    pot = ForcePotential(force)
    rng = np.random.default_rng(3)
    q = 1e-2 * rng.standard_normal(model.system.n_dofs)
    gq, gp = pot.gradient(q, np.zeros_like(q))
    np.testing.assert_array_equal(gq, force.force(q))
    assert not np.any(gp)
    h = 1e-6 * rng.standard_normal(q.size)
    fd = (pot.value(q + h, q) - pot.value(q - h, q)) / 2
    # U is a quartic polynomial: the central difference errs by h^3 terms, ~1e-12 of g.h here
    assert fd == pytest.approx(gq @ h, rel=1e-6)
    hqq, hqp, hpp = pot.hessian(q, q)
    assert hqp is None and hpp is None
    np.testing.assert_allclose(hqq @ h, force.force(q + h) - force.force(q), rtol=1e-4,
                               atol=1e-6 * np.abs(force.force(q)).max())
    # columns: (n, k) in, (k,) values and (n, k) gradients out
    Q = np.column_stack([q, 2 * q])
    np.testing.assert_allclose(pot.value(Q, Q), [pot.value(q, q), pot.value(2 * q, q)])
    np.testing.assert_allclose(pot.gradient(Q, Q)[0][:, 1], force.force(2 * q))


def test_force_potential_refuses_a_force_without_one():
    class Viscous:
        stateful, conservative = False, False

    with pytest.raises(ValueError, match="not a conservative stateless force"):
        ForcePotential(Viscous())
