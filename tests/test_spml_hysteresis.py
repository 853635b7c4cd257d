"""SpML with learned sliders (its ``"hysteresis"`` term) on a system whose truth lies in its class.

One coordinate: ``q'' + c q' + k q + k_3 q^3 + k_s e(q) = b u`` with a Jenkins slider (a spring
``k_s`` in series with a dry-friction element slipping at stretch ``phi_s``) and a hardening cubic
spring, driven from rest by half-sine blows. The data are the Newmark steps of that model (its
return mapping committed at every step), so at every sample the balance holds with the play
operator of the sampled history: exact data, inside the class of SpML with sliders when ``phi_s``
is one of the thresholds. Plain SpML (the same terms without the hysteresis) has a smooth potential
and a history-free convex dissipation, which can only approximate the slider.
"""

import numpy as np
import pytest

from _required import extra
from femrom._errors import FemromValueError
from femrom.inference import (
    LearnedHysteresis,
    LearnedPotential,
    ReducedOperators,
    SecondOrderData,
    SpML,
    SpMLConfig,
    concatenate,
    term_class,
)
from femrom.inference._networks import SymmetricPolynomial
from femrom.rom import SecondOrderROM

extra("torch")

PHI = 0.1 * np.geomspace(0.02, 1.0, 12)          # the thresholds both the truth and the learner use
K_SLIDERS = np.zeros(12)
K_SLIDERS[9] = 10.0                              # one slider, phi_s = 0.0245 (a quarter of the largest motion)
K, C, B, K3 = 10.0, 0.05, 1.0, 40.0
DT, STEPS = 5e-3, 1500


def spring() -> LearnedPotential:
    """``U = k_3 q^4 / 4``: the cubic spring as a potential."""
    return LearnedPotential(1, SymmetricPolynomial(1, {4: (np.zeros((1, 4), dtype=int), np.array([K3 / 4]))}), None)


def truth() -> ReducedOperators:
    return ReducedOperators((term_class("stiffness")(np.array([[K]])), term_class("damping")(np.array([[C]])),
                             term_class("input")(np.array([[B]])), spring(), LearnedHysteresis([1.0], PHI, K_SLIDERS)))


def blow(peak: float) -> SecondOrderData:
    """A 0.05 s half-sine blow of ``peak`` from rest, then 7.45 s of ring-down (Newmark, dt = 5 ms)."""
    t = np.arange(STEPS) * DT
    u = np.where(t < 0.05, peak * np.sin(np.pi * t / 0.05), 0.0)[None]
    s = SecondOrderROM(truth(), np.eye(1)).predict(t, u, initial=np.zeros(1), scheme="newmark")
    return SecondOrderData(s.q, s.v, s.a, inputs=u, times=t)


@pytest.fixture(scope="module")
def fits():
    train, validation, test = [blow(4.0), blow(12.0)], blow(8.0), blow(10.0)
    config = SpMLConfig(seed=0, max_iterations=100, hysteresis_thresholds=tuple(PHI))
    out = {"data": (train, validation, test)}
    for name, terms in (("plain", ["damping", "input"]), ("sliders", ["damping", "input", "hysteresis"])):
        out[name] = SpML(terms, config=config, progress=False).fit(train, validation=validation)
    return out


def _force_error(learner, data) -> float:
    """The learned nonlinear force (potential, dissipation, sliders) against the truth's along the history."""
    true = spring().forces(data.states) + LearnedHysteresis([1.0], PHI, K_SLIDERS).forces(data.states,
                                                                                           starts=data.starts)
    learned = learner.nonlinear_forces(data.states, data.velocities, data.starts)
    # both models put the linear part in K^: compare what each adds to it, with K^'s difference
    learned = learned + (learner.linear_matrices_["stiffness"] - K) @ data.states
    return float(np.linalg.norm(learned - true) / np.linalg.norm(true))


def test_hysteretic_spml_recovers_the_slider_and_the_spring(fits):
    """Exact data in the class: the least-squares stage solves the linear-in-parameters model (mass,
    K^, C^, B^, the monomials, the sliders' non-negative weights in the monotone shape) exactly, so the
    weights, the cubic spring and the linear terms come back to round-off (observed 1e-10 and below;
    the tolerances leave a factor 100-1000 for the conditioning of other machines' BLAS)."""
    learner = fits["sliders"]
    np.testing.assert_allclose(learner.hysteresis_.weights, K_SLIDERS, rtol=0, atol=1e-6 * K_SLIDERS.max())
    np.testing.assert_allclose(learner.hysteresis_.thresholds, PHI)
    for name, value in (("stiffness", K), ("damping", C), ("input", B)):
        np.testing.assert_allclose(learner.linear_matrices_[name], [[value]], rtol=1e-7)
    np.testing.assert_allclose(learner.mass_, [[1.0]], rtol=1e-8)       # the gauge tr M^ = tr M_0 = 1
    train = concatenate(fits["data"][0])
    assert _force_error(learner, train) < 1e-7                            # observed 1e-11
    assert learner.loss_ < 1e-16                                          # observed 1e-22
    # the sliders are the learned dissipation: no convex dissipation beside them by default (plain SpML
    # with a damping term learns one)
    assert learner.config_.learn_dissipation is False and learner.dissipation_ is None
    assert fits["plain"].config_.learn_dissipation is True
    # the stages: the sliders' start (IwanLOpInf), step 1, least squares, L-BFGS
    assert learner.stages_[0]["stage"] == "sliders (IwanLOpInf)"
    assert {s["stage"] for s in learner.stages_} >= {"least squares", "L-BFGS"}


def test_plain_spml_cannot_follow_the_slider(fits):
    """Plain SpML on the same data: its smooth potential and history-free dissipation leave most of the
    slider's force unexplained (force error with K^'s change, observed 0.21; the sliders' 1e-11), and the unseen 10 N blow
    predicted by both with the same Newmark step drifts away (observed 0.23 against 2e-11)."""
    train, _, test = fits["data"]
    plain, sliders = fits["plain"], fits["sliders"]
    assert plain.hysteresis_ is None and not plain.operators_.stateful
    assert _force_error(plain, concatenate(train)) > 0.1
    assert plain.loss_ > 1e6 * sliders.loss_                              # observed 5e-3 against 1e-22
    t = np.arange(STEPS) * DT
    errors = {}
    for name in ("plain", "sliders"):
        s = SecondOrderROM(fits[name].operators_, np.eye(1)).predict(t, test.inputs, initial=np.zeros(1),
                                                                     scheme="newmark")
        errors[name] = float(np.linalg.norm(s.q - test.states) / np.linalg.norm(test.states))
    assert errors["sliders"] < 1e-6
    assert errors["plain"] > 0.1


def test_the_hysteresis_term_is_named_like_the_others(fits):
    """``"hysteresis"``, ``"learned_hysteresis"`` and the class select the same term; it is listed
    among the learned terms (what a study's ``extra_terms`` compare with); named twice, or combined
    with the rollout stage (which steps no sliders), it is refused in one line."""
    for name in ("hysteresis", "learned_hysteresis", LearnedHysteresis):
        learner = SpML(["damping", name])
        assert learner.hysteresis and LearnedHysteresis in learner.learned_terms
        assert [c.name for c in learner.linear.learned_terms] == ["damping"]
    assert not SpML(["damping"]).hysteresis
    with pytest.raises(FemromValueError, match="named once"):
        SpML(["hysteresis", "learned_hysteresis"])
    train, validation, _ = fits["data"]
    with pytest.raises(FemromValueError, match="rollout"):
        SpML(["damping", "input", "hysteresis"], config=SpMLConfig(rollout_steps=4)).fit(train[0])
    with pytest.raises(FemromValueError, match="hysteresis_thresholds"):
        SpMLConfig(hysteresis_thresholds=1)
    with pytest.raises(FemromValueError, match="hysteresis_span"):
        SpMLConfig(hysteresis_span=(0.5, 0.1))


def test_the_model_with_sliders_saves_and_steps(fits, tmp_path):
    """The fitted model saves with its sliders and steps the same after loading (the slider state is
    the model's: Newmark with the return mapping), without torch in the step."""
    _, _, test = fits["data"]
    rom = SecondOrderROM(fits["sliders"].operators_, np.eye(1))
    assert rom.operators_.stateful
    t = np.arange(300) * DT
    before = rom.predict(t, test.inputs[:, :300], initial=np.zeros(1), scheme="newmark")
    rom.save(tmp_path / "spml_sliders.h5")
    after = SecondOrderROM.load(tmp_path / "spml_sliders.h5").predict(t, test.inputs[:, :300], initial=np.zeros(1),
                                                                      scheme="newmark")
    np.testing.assert_array_equal(before.q, after.q)
