"""SpML against L-OpInf on ring-downs of a small hysteretic (clamped-Iwan) structure: the jointed beam's
ROM study (``femrom/cases/jointed_beam_rom.py``, ``femrom.study.compare_ring_downs``) on a synthetic analogue.

Four nodes in a chain, each on a linear ground spring and a clamped-Iwan pair (the joint a quarter of
the stuck stiffness, slip tractions growing fourfold along the chain), projected on its six stuck
modes (``galerkin``) with modal damping: the reference. A uniform blow excites mode 1 (100.7 Hz
stuck); its ring-down backbone falls by about 2 Hz and its damping ratio roughly doubles over the
trained amplitudes, the beam's behaviour in a stronger form."""

import dataclasses

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

from _required import extra
from femrom.fem import ClampedIwanLaw, JointForce
from femrom.inference import SpMLConfig
from femrom.inference import galerkin
from femrom.scene import SecondOrderSystem, Signal, SignalVector
from femrom.study import ModelSpec, RingDownComparison, compare_ring_downs, reference_ring_down

extra("torch")

N = 4


def blow(peak: float):
    return SignalVector([Signal.from_dict({"kind": "impulse", "amplitude": peak, "start": 0.0, "duration": 2e-3})])


def chain():
    n = 3 * N
    b = np.arange(n).reshape(N, 3)
    K = np.diag(np.full(n, 3e5))
    for m in range(N - 1):
        for c in range(3):
            i, j = b[m, c], b[m + 1, c]
            K[np.ix_([i, j], [i, j])] += 1e6 * np.array([[1.0, -1.0], [-1.0, 1.0]])
    law = ClampedIwanLaw(1e10, 1e9, chi=-0.5, beta=0.5, n_sliders=12)
    joint = JointForce(law, -np.ones_like(b), b, np.tile([0.0, 0.0, 1.0], (N, 1)), np.full(N, 1e-4), n)
    z0 = law.initial_state(N)
    z0[:, -1, 0] = np.linspace(2e5, 8e5, N)     # mu p_0 [Pa]
    z0[:, -1, 1] = 1.0                          # closed
    B = np.zeros((n, 1))
    B[b[:, 0], 0] = 1.0
    system = SecondOrderSystem(mass=sp.identity(n, format="csr"), stiffness=sp.csr_matrix(K), input_matrix=B,
                               inputs=blow(1.0), output_matrix=sp.csr_matrix(np.eye(n)[[b[0, 0]]]), nonlinear=joint)
    stuck = K + joint.tangent(np.zeros(n), None, z0)[0].toarray()
    w, V = sla.eigh(stuck)
    f1 = float(np.sqrt(w[0]) / (2 * np.pi))
    model = galerkin(system, V[:, :6], reference_state=z0, damping_ratios=0.002).system
    return dataclasses.replace(model, inputs=system.inputs), z0, f1


@pytest.fixture(scope="module")
def comparison():
    reference, z0, f1 = chain()
    dt = 1.0 / (32 * f1)
    runs = {peak: dataclasses.replace(reference, inputs=blow(peak)) for peak in (150.0, 300.0, 400.0, 600.0)}
    training = [reference_ring_down(runs[p], z0, 1.0, dt, label=f"{p:g} N") for p in (150.0, 600.0)]
    validation = [reference_ring_down(runs[400.0], z0, 0.3, dt, label="400 N")]
    test = reference_ring_down(runs[300.0], z0, 1.0, dt, label="300 N")
    linear = {"terms": ("damping", "input")}
    models = (ModelSpec("lopinf", options=linear),
              ModelSpec("spml", options={**linear, "config": SpMLConfig(max_iterations=1000)}),
              ModelSpec("iwan_lopinf", "iwan", linear),
              ModelSpec("spml", "spml_hyst", {"terms": ("damping", "input", "hysteresis"),
                                              "config": SpMLConfig(max_iterations=1000, potential_widths=())}))
    settings = RingDownComparison(ranks=(2,), models=models, band=(0.5 * f1, 1.6 * f1), window=0.1)
    out = compare_ring_downs(reference, z0, training, validation, [(test, runs[300.0])], settings,
                             progress=lambda line: None)
    return {row["model"]: row for row in out["rows"]}, out


def test_spml_tracks_the_frequency_shift_that_lopinf_misses(comparison):
    rows, out = comparison
    print({name: {k: row.get(k) for k in ("frequency_shift_hz", "reference_shift_hz", "frequency_shift_error",
                                            "damping_max_error", "time_domain_error")} for name, row in rows.items()})
    spml, lopinf = rows["spml"], rows["lopinf"]
    # the reference does shift: over the trained amplitudes mode 1 moves by more than 1 Hz (about 2 %)
    assert spml["reference_shift_hz"] > 1.0
    # L-OpInf is linear: its backbone is flat up to the Hilbert fit's noise, so it misses at least
    # 80 % of the shift (a learner that picked up the shift would fail this)
    assert lopinf["frequency_shift_error"] > 0.8
    # SpML's learned potential softens with amplitude: its shift has the reference's sign and is within
    # 50 % of it, and it beats L-OpInf's by a wide margin. The fit gets 1000 L-BFGS iterations (stopped
    # on the validation run): with 200 its end point depended on the round-off of the machine's
    # torch/BLAS (measured 0.10 on one machine, 0.58 on another); at 1000 it measured 0.05 here
    assert spml["frequency_shift_hz"] > 0
    assert spml["frequency_shift_error"] < 0.5
    assert spml["frequency_shift_error"] < 0.5 * lopinf["frequency_shift_error"]
    # both stay bounded and decay (no energy from a dissipation that is convex by construction)
    assert spml["stable"] and lopinf["stable"]


def test_learned_sliders_follow_the_joint_where_a_history_free_dissipation_cannot(comparison):
    rows, _ = comparison
    iwan, spml = rows["iwan"], rows["spml"]
    # IwanLOpInf (learned Jenkins sliders along the leading coordinate) on the same data: the shift
    # within 5 % (observed 1.0 %) and the damping curve within the 15 % (observed 4.6 %), where
    # SpML's history-free dissipation misses the damping by more than 100 % (observed 131 %)
    assert iwan["frequency_shift_hz"] > 0
    assert iwan["frequency_shift_error"] < 0.05
    assert iwan["damping_max_error"] < 0.15
    assert spml["damping_max_error"] > 4 * iwan["damping_max_error"]
    # in time too (observed 0.063 against SpML's 0.46), and it decays
    assert iwan["time_domain_error"] < 0.5 * spml["time_domain_error"]
    assert iwan["stable"]


def test_spml_with_sliders_does_better_than_plain_spml_on_the_joint(comparison):
    rows, _ = comparison
    hyst, iwan, spml = rows["spml_hyst"], rows["iwan"], rows["spml"]
    # SpML with its hysteresis term (sliders, monomials, no convex dissipation: the study's spml_hyst) on the
    # same data: the shift within 15 % (observed 9.7 %) and the damping error under half of plain SpML's
    # (observed 27 % against 63 %). It does not reach IwanLOpInf here (1.0 % and 4.6 %): from the Iwan start,
    # L-BFGS lowers the validation residual 2.5-fold (mass, K^, C^, monomials refined) while the mode-1
    # backbone moves away (docs/spml.md, "SpML with learned sliders")
    assert hyst["frequency_shift_hz"] > 0
    assert hyst["frequency_shift_error"] < 0.15
    assert spml["damping_max_error"] > 2 * hyst["damping_max_error"]
    assert hyst["damping_max_error"] > iwan["damping_max_error"]
    assert hyst["stable"]


@pytest.mark.slow
def test_the_jointed_beam_rom_case_quick_mode_writes_its_metrics(tmp_path):
    """``python -m femrom run jointed_beam_rom --quick -o DIR`` (r = 2, 200 SpML iterations, a 0.9 s
    test, a two-frequency stepped sine at 0.2 N): 2-4 minutes on 2 shared cores, most of it the
    jointed beam's model chain (calibration, ECSW). Its metrics.json, and what docs/cases/
    jointed_beam_rom.md claims that a quick run can check. Measured: Galerkin shift / damping error
    4.1 % / 0.6 % (the 3 s test of the docs: 0.77 % / 0.67 %), Iwan-L-OpInf 5.1 % / 9.6 % (3.6 % / 9.6 %),
    L-OpInf 100 % / 83 %; stepped sine at 0.2 N, peak amplitude error Galerkin -0.7 %, Iwan -6.4 %
    (the docs' r = 3: -0.6 % and -7.1 %)."""
    import json

    from femrom.cases import jointed_beam_rom
    from femrom.study import RING_DOWN_COLUMNS

    out = tmp_path / "jointed_beam_rom"
    assert jointed_beam_rom.main(["--quick", "-o", str(out)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics) >= {"case", "columns", "reference", "config", "dt", "f1_hz", "trained_amplitude_range_m_s2",
                            "pod_singular_values", "reference_seconds_per_step", "full_model", "rows", "backbones",
                            "stepped_sine", "seconds"}
    assert metrics["case"] == "jointed_beam_rom" and metrics["full_model"] is None      # quick: no full-model steps
    assert metrics["f1_hz"] == pytest.approx(80.5, rel=1e-6)                             # the calibrated mode 1
    assert (out / "backbone_300N.png").stat().st_size > 0
    rows = {row["model"]: row for row in metrics["rows"]}
    assert set(rows) == {"galerkin", "lopinf", "spml", "spml_hyst", "iwan", "iwan_band"}
    for name, row in rows.items():
        assert set(row) >= set(RING_DOWN_COLUMNS) and row["r"] == 2 and row["test"] == "300 N", name
        assert row["stable"], name                                # every model decays over the test
        for key in ("time_domain_error", "seconds_per_step", "fit_seconds"):
            assert np.isfinite(row[key]) and row[key] >= 0, (name, key)
        if row["frequency_shift_error"] is not None:              # None: no overlap with the trained range
            assert np.isfinite(row["frequency_shift_error"]) and np.isfinite(row["damping_max_error"]), name
    # the projection with the sampled joint is the accurate ROM (bands 2-3x the measured values)
    assert rows["galerkin"]["frequency_shift_error"] < 0.1 and rows["galerkin"]["damping_max_error"] < 0.02
    # the docs' targets for the learned sliders, met at r = 2 on the short test too: shift within 10 %,
    # damping within 15 %
    assert rows["iwan"]["frequency_shift_error"] < 0.1 and rows["iwan"]["damping_max_error"] < 0.15
    # L-OpInf is linear: its backbone is flat by construction, so it misses the whole shift
    assert 0.95 < rows["lopinf"]["frequency_shift_error"] < 1.05
    sine = {row["model"]: row for row in metrics["stepped_sine"]["rows"]}
    assert set(sine) == set(rows) and all(row["all_converged"] for row in sine.values())
    assert abs(sine["galerkin"]["peak_amplitude_error"]) < 0.03
    assert abs(sine["iwan"]["peak_amplitude_error"]) < 0.15     # the docs' -7.1 % at r = 3
