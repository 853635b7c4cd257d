r"""Backbone and damping-vs-amplitude extraction from ring-down signals (femrom.post).

Synthetic single-degree-of-freedom free decays with known answers:

* linear: ``x = A exp(-zeta w t) cos(w_d t)``, frequency and damping constant;
* Duffing ``x'' + 2 zeta w x' + w^2 x + gamma x^3 = 0``: the backbone against
  first-order averaging ``w(a) = w (1 + 3 eps / 8)``, ``eps = gamma a^2 / w^2``,
  whose error is the Lindstedt second-order term ``-15/256 eps^2`` (``a`` the
  amplitude of the fundamental, which is what the band-passed envelope measures);
* Jenkins (spring ``k`` plus spring ``k_t`` in series with a Coulomb slider ``F_s``,
  plus a little viscous damping): against the equivalent linearisation of the
  elastic-perfectly-plastic element (see :func:`jenkins_equivalent_linearisation`);

then the measured hammer-impact ring-down of the jointed beam (skipped without the
data, failed under ``FEMROM_REQUIRE_DATA``), the plot helper and the error messages.
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from femrom.fem import JenkinsForce
from femrom.post import (
    Backbone,
    brb_data_dir,
    default_trim,
    hilbert_backbone,
    measured_backbone,
    measured_spectral_peaks,
    peak_backbone,
    plot_backbones,
    read_hammer_impact,
    spectral_peaks,
)

FREQUENCY = 10.0                  # undamped linear frequency of the synthetic oscillators [Hz]
OMEGA = 2 * np.pi * FREQUENCY
RATE = 500.0                      # samples per second (50 per cycle)
BAND = (5.0, 20.0)                # pass band around 10 Hz; the Duffing rises to 10.7 Hz


# ----------------------------------------------------------------------------- linear


def test_linear_decay_frequency_and_damping_constant_over_amplitude():
    """Both estimators on ``x = 3 exp(-zeta w t) cos(w_d t + 0.3)``, 20 s (a 535x decay).

    Exact: ``f_d = f sqrt(1 - zeta^2)``, ``zeta`` (poles ``-zeta w +- i w_d``, and the
    estimators' ``zeta = sigma / sqrt(sigma^2 + w_d^2)`` is exactly this ``zeta``),
    amplitude ``3 exp(-zeta w t)`` at the window centre.
    """
    zeta = 0.005
    omega_d = OMEGA * np.sqrt(1 - zeta ** 2)
    t = np.arange(int(20 * RATE)) / RATE
    x = 3.0 * np.exp(-zeta * OMEGA * t) * np.cos(omega_d * t + 0.3)

    hilbert = hilbert_backbone(x, RATE, BAND, window=0.5)
    peaks = peak_backbone(x, RATE, BAND, cycles=5)
    assert hilbert.method == "hilbert" and peaks.method == "peaks"
    # 0.5 s windows half overlapping over 20 s less 2 x 1.21 s trim: 69 windows; 35 groups of 5 cycles
    assert len(hilbert) == 69 and len(peaks) == 35
    for backbone in (hilbert, peaks):
        frequency_error = np.abs(backbone.frequency_hz / (omega_d / (2 * np.pi)) - 1)
        zeta_error = np.abs(backbone.damping_ratio / zeta - 1)
        amplitude_error = np.abs(backbone.amplitude / (3.0 * np.exp(-zeta * OMEGA * backbone.time)) - 1)
        # measured max: frequency 6.4e-7 (hilbert) / 7.1e-7 (peaks); zeta 9.0e-5 / 5.5e-5;
        # amplitude 2.2e-6 / 1.8e-5 (peaks: parabola through 3 samples of 50 per cycle).
        # Tolerances: the brief's 1e-4 relative in f and 1 % in zeta, tightened to 1e-5 and
        # 1e-3, still 10x above the measured (filter-transient residue 1e-4 at the trim)
        assert frequency_error.max() < 1e-5
        assert zeta_error.max() < 1e-3
        assert amplitude_error.max() < 1e-4
        # the amplitudes span the decay: 1.89 down to 0.0091 (windows kept after the trim)
        assert backbone.amplitude.max() / backbone.amplitude.min() > 100
    # the two estimators agree where they overlap (interpolated at the peaks' amplitudes)
    inside = (peaks.amplitude >= hilbert.amplitude.min()) & (peaks.amplitude <= hilbert.amplitude.max())
    frequency, damping = hilbert.at_amplitude(peaks.amplitude[inside])
    assert np.max(np.abs(frequency / peaks.frequency_hz[inside] - 1)) < 1e-5
    assert np.max(np.abs(damping / peaks.damping_ratio[inside] - 1)) < 1e-3


def test_backbone_rows_decay_rate_and_interpolation():
    backbone = Backbone(time=[0.5, 1.0, 1.5], amplitude=[4.0, 2.0, 1.0], frequency_hz=[10.2, 10.1, 10.0],
                        damping_ratio=[0.003, 0.002, 0.001], method="test")
    assert backbone.rows()[1] == {"amplitude": 2.0, "frequency_hz": 10.1, "damping_ratio": 0.002}
    with pytest.raises(ValueError):   # read-only arrays in a frozen result
        backbone.amplitude[0] = 1.0
    # sigma = zeta w_d / sqrt(1 - zeta^2), the inverse of zeta = sigma / sqrt(sigma^2 + w_d^2)
    sigma = backbone.decay_rate
    assert np.allclose(sigma / np.hypot(sigma, 2 * np.pi * backbone.frequency_hz), backbone.damping_ratio,
                       rtol=1e-14)
    # linear in log amplitude: sqrt(2) is half way between 1 and 2
    frequency, damping = backbone.at_amplitude(np.sqrt(2.0))
    assert frequency == pytest.approx(10.05, rel=1e-14) and damping == pytest.approx(0.0015, rel=1e-12)
    with pytest.raises(ValueError, match="amplitude must lie in"):
        backbone.at_amplitude(8.0)


# ----------------------------------------------------------------------------- Duffing


@pytest.fixture(scope="module")
def duffing_decay():
    """Free decay of ``x'' + 2 zeta w x' + w^2 x + gamma x^3 = 0`` from rest at ``eps = 0.2``
    down to ``eps ~ 0.025`` (15 s), DOP853 at rtol 1e-11, sampled at 500 Hz."""
    zeta, gamma = 0.001, 1.0
    amplitude0 = np.sqrt(0.2 * OMEGA ** 2 / gamma)
    t = np.arange(int(15 * RATE)) / RATE

    def rhs(_, state):
        x, v = state
        return [v, -2 * zeta * OMEGA * v - OMEGA ** 2 * x - gamma * x ** 3]

    solution = solve_ivp(rhs, (0, t[-1]), [amplitude0, 0.0], method="DOP853", rtol=1e-11,
                         atol=1e-12 * amplitude0, t_eval=t)
    assert solution.success
    return solution.y[0], zeta, gamma


@pytest.mark.parametrize("method", ["hilbert", "peaks"])
def test_duffing_backbone_against_averaging(duffing_decay, method):
    r"""Frequency: ``f(a) / f - 1 - 3 eps / 8 = -15/256 eps^2 + O(eps^3)`` (Lindstedt to second
    order with ``a`` the fundamental's amplitude: ``w^2 = w_0^2 (1 + 3 eps/4 + 3 eps^2/128)``).

    Decay rate: energy balance ``dE/dt = -2 zeta w <x'^2>`` with ``E = w^2 a^2 (1 + 9 eps/16) / 2``
    (energy at the turning point, peak = ``a (1 + eps/32)``) and ``<x'^2> = w(a)^2 a^2 / 2`` gives
    ``sigma = zeta w (1 + 3 eps/4) / (1 + 9 eps/8) = zeta w (1 - 3 eps/8 + O(eps^2))``; first-order
    averaging alone gives ``sigma = zeta w`` (the ``zeta eps`` cross term is second order).
    """
    x, zeta, gamma = duffing_decay
    if method == "hilbert":
        backbone = hilbert_backbone(x, RATE, BAND, window=0.3)
    else:
        backbone = peak_backbone(x, RATE, BAND, cycles=3)
    eps = gamma * backbone.amplitude ** 2 / OMEGA ** 2
    weak = (eps > 0.04) & (eps < 0.15)
    assert weak.sum() >= 10
    eps = eps[weak]
    first_order = 1 + 3 * eps / 8
    ratio = (backbone.frequency_hz[weak] / FREQUENCY - first_order) / eps ** 2
    # measured ratio: hilbert -0.0580 .. -0.0564, peaks -0.0582 .. -0.0565 (eps 0.04 .. 0.15);
    # theory -15/256 = -0.0586 plus O(eps) (about +0.015 eps, so -0.0564 at eps = 0.15) and the
    # window's averaging over a decaying eps (+ (2 sigma T_w)^2 / 24 * 3/8 / eps, +1e-4 here).
    # Lower AND upper side within 8 %: a first-order formula that were wrong by even 0.5 % of
    # its eps-term (2e-3 eps) would move the ratio by 2e-3 / eps >= 0.013, i.e. by >= 22 %
    assert np.all(ratio < -15 / 256 * 0.92), ratio
    assert np.all(ratio > -15 / 256 * 1.08), ratio
    # the frequency shift itself is seen: f(a) / f - 1 from 5.6 % down to 1.5 %
    shift = backbone.frequency_hz[weak] / FREQUENCY - 1
    assert np.allclose(shift, 3 * eps / 8, rtol=0.03)

    sigma = backbone.decay_rate[weak] / (zeta * OMEGA)
    slope, curvature = np.linalg.lstsq(np.column_stack([eps, eps ** 2]), sigma - 1, rcond=None)[0]
    # measured: sigma / (zeta w) = 1 - 0.372 eps + 0.32 eps^2 (both estimators): the slope is
    # the energy balance's -3/8 (asserted within 10 %), and sigma itself is within 1e-2 of
    # 1 - 3 eps / 8 (measured max 7.3e-3 at eps = 0.15, where the drop 3 eps / 8 is 5.6e-2)
    assert -0.375 * 1.1 < slope < -0.375 * 0.9
    assert np.max(np.abs(sigma - (1 - 3 * eps / 8))) < 1e-2


# ----------------------------------------------------------------------------- Jenkins

JENKINS_RATE = 1000.0             # samples per second of the Jenkins decays (100 per cycle)
JENKINS_BAND = (4.0, 20.0)        # around 10 - 10.5 Hz, the 3rd harmonic (30 Hz) outside
SLIP_DISPLACEMENT = 1.0           # x_s = F_s / k_t
JENKINS_ZETA = 0.002              # viscous damping ratio (of sqrt(k / m))
JENKINS_STRENGTHS = (0.1, 0.05)   # eps = k_t / k


def jenkins_equivalent_linearisation(amplitude, strength):
    r"""Damped frequency [Hz] and damping ratio of ``m x'' + c x' + k x + g(x) = 0`` at
    displacement amplitude ``a`` (``m = 1``, ``k = w^2``, ``k_t = eps k``, ``F_s = k_t x_s``).

    Harmonic balance of the elastic-perfectly-plastic Jenkins force over ``x = a cos(theta)``:
    on the way down from ``a`` the element sticks, ``g = F_s - k_t a (1 - cos theta)``, until
    ``g = -F_s`` at ``cos theta* = 1 - 2 x_s / a``, then slides at ``-F_s`` (and the way up is the
    mirror image). Its ``cos`` coefficient gives the equivalent stiffness and the loop area the
    dissipation per cycle:

    .. math::

        k_{eq}(a) = \frac{k_t}{\pi}\left(\theta^* - \tfrac12 \sin 2\theta^*\right), \qquad
        W(a) = 4 F_s (a - x_s) \qquad (a > x_s),

    and ``k_eq = k_t``, ``W = 0`` below (stuck, linear). Then ``w_eq^2 = (k + k_eq) / m``, the
    equivalent viscous ``c_eq = W / (pi w_eq a^2)``, ``sigma = (c + c_eq) / 2m``,
    ``zeta = sigma / w_eq`` and ``f_d = sqrt(w_eq^2 - sigma^2) / 2 pi`` (the same definitions
    as the estimators). Its error is second order in ``eps`` (first-order averaging).
    """
    amplitude = np.asarray(amplitude, dtype=float)
    mass, stiffness = 1.0, OMEGA ** 2
    tangential = strength * stiffness
    slip_force = tangential * SLIP_DISPLACEMENT
    slipping = amplitude > SLIP_DISPLACEMENT
    switch = np.arccos(np.clip(1 - 2 * SLIP_DISPLACEMENT / amplitude, -1, 1))
    k_eq = np.where(slipping, tangential / np.pi * (switch - 0.5 * np.sin(2 * switch)), tangential)
    dissipation = np.where(slipping, 4 * slip_force * (amplitude - SLIP_DISPLACEMENT), 0.0)
    omega_eq = np.sqrt((stiffness + k_eq) / mass)
    viscous = 2 * JENKINS_ZETA * OMEGA * mass
    sigma = (viscous + dissipation / (np.pi * omega_eq * amplitude ** 2)) / (2 * mass)
    return np.sqrt(omega_eq ** 2 - sigma ** 2) / (2 * np.pi), sigma / omega_eq


def test_jenkins_closed_form_limits():
    """At a = x_s the element is just stuck (k_eq = k_t, continuous); far above it slips
    (k_eq -> 16 k_t x_s^(3/2) / (3 pi a^(3/2)) -> 0) and the Jenkins damping ratio falls like
    ``W / (4 pi E) = 4 F_s a / (2 pi k a^2)`` for ``eps -> 0``."""
    frequency_stuck, _ = jenkins_equivalent_linearisation(SLIP_DISPLACEMENT * 0.5, 0.1)
    frequency_edge, _ = jenkins_equivalent_linearisation(SLIP_DISPLACEMENT * (1 + 1e-12), 0.1)
    assert frequency_edge == pytest.approx(frequency_stuck, rel=1e-6)
    tiny = 1e-4
    _, damping = jenkins_equivalent_linearisation(1e4, tiny)
    jenkins_part = damping - JENKINS_ZETA
    assert jenkins_part == pytest.approx(4 * tiny * OMEGA ** 2 * 1e4 / (2 * np.pi * OMEGA ** 2 * 1e8), rel=1e-3)


@pytest.fixture(scope="module")
def jenkins_decays():
    """Free decays from ``x = 8 x_s`` at rest, one column per strength, 8 s.

    Central differences at h = T / 600 (``m (x+ - 2x + x-)/h^2 + c (x+ - x-)/2h + k x + g = 0``)
    with the library's return map (:class:`femrom.fem.JenkinsForce`: force clipped to
    ``+-F_s``, slider committed after each step); both columns in one vectorised run.
    The element is rate-independent, so the only error of the map is where the path turns
    between samples, O(h^2); the scheme's frequency error is ``(w h)^2 / 24 = 4.6e-6``.
    """
    strengths = np.array(JENKINS_STRENGTHS)
    stiffness = OMEGA ** 2
    tangential = strengths * stiffness
    element = JenkinsForce(tangential, tangential * SLIP_DISPLACEMENT, strengths.size)
    substeps = 6
    h = 1 / (JENKINS_RATE * substeps)
    damping = 2 * JENKINS_ZETA * OMEGA
    lead, lag = 1 / h ** 2 + damping / (2 * h), 1 / h ** 2 - damping / (2 * h)
    n_samples = int(8 * JENKINS_RATE)
    samples = np.empty((n_samples, strengths.size))
    slider = element.initial_state()
    x = np.full(strengths.size, 8.0 * SLIP_DISPLACEMENT)
    force = element.local_force(x, None, slider)
    slider = element.local_commit(x, None, slider)
    x_previous = x - 0.5 * h ** 2 * (stiffness * x + force)       # from rest
    samples[0] = x
    for step in range(1, n_samples * substeps):
        x, x_previous = ((2 / h ** 2 - stiffness) * x - lag * x_previous - force) / lead, x
        force = element.local_force(x, None, slider)
        slider = element.local_commit(x, None, slider)
        if step % substeps == 0:
            samples[step // substeps] = x
    return samples


def test_jenkins_backbone_against_equivalent_linearisation(jenkins_decays):
    """Frequency and damping vs displacement amplitude of the Jenkins oscillator, both
    estimators, against :func:`jenkins_equivalent_linearisation`; the damping error scales
    like eps^2 (halving eps quarters it)."""
    worst_damping_error = {}
    for column, strength in enumerate(JENKINS_STRENGTHS):
        x = jenkins_decays[:, column]
        for backbone in (hilbert_backbone(x, JENKINS_RATE, JENKINS_BAND, window=0.2),
                         peak_backbone(x, JENKINS_RATE, JENKINS_BAND, cycles=2)):
            frequency, damping = jenkins_equivalent_linearisation(backbone.amplitude, strength)
            frequency_stuck, damping_stuck = jenkins_equivalent_linearisation(0.0 + 1e-9, strength)

            # micro-slip range, away from the kink at a = x_s that a window would straddle
            slip = (backbone.amplitude > 1.5 * SLIP_DISPLACEMENT) & (backbone.amplitude < 6.5)
            assert slip.sum() >= 3
            frequency_error = backbone.frequency_hz[slip] / frequency[slip] - 1
            damping_error = backbone.damping_ratio[slip] - damping[slip]
            # measured |frequency error| / eps^2 <= 0.016, |damping error| / eps^2 <= 0.115
            # (eps = 0.1: 0.095 / 0.098 hilbert / peaks; 0.05: 0.115 / 0.115): the O(eps^2) of
            # first-order averaging, largest near a = 1.5 x_s where the loop is fattest
            assert np.max(np.abs(frequency_error)) < 0.03 * strength ** 2
            assert np.max(np.abs(damping_error)) < 0.15 * strength ** 2
            # lower side: the amplitude dependence itself is resolved - the frequency falls
            # below the stuck one by 1.4 - 3.2 % (eps = 0.1) / 0.8 - 2.0 % (0.05), measured
            # within 1.1 % of that fall; the Jenkins part of zeta, 1.3 - 1.5 % / 0.55 - 0.77 %,
            # within 7.4 % (eps = 0.1) / 4.1 % (0.05)
            softening = 1 - frequency[slip] / frequency_stuck
            measured_softening = 1 - backbone.frequency_hz[slip] / frequency_stuck
            assert np.allclose(measured_softening, softening, rtol=0.03)
            jenkins_damping = damping[slip] - JENKINS_ZETA
            assert np.all(np.abs(damping_error) < 0.1 * jenkins_damping)
            # stuck: the linear oscillator with k + k_t (zeta relative to sqrt((k + k_t)/m))
            stuck = backbone.amplitude < 0.95 * SLIP_DISPLACEMENT
            assert stuck.sum() >= 3
            # measured: frequency within 6.2e-6 (the scheme's 4.6e-6 dispersion), zeta within 0.1 %
            assert np.max(np.abs(backbone.frequency_hz[stuck] / frequency_stuck - 1)) < 2e-5
            assert np.max(np.abs(backbone.damping_ratio[stuck] / damping_stuck - 1)) < 0.01
            key = (strength, backbone.method)
            worst_damping_error[key] = np.max(np.abs(damping_error))
    for method in ("hilbert", "peaks"):
        ratio = worst_damping_error[(0.1, method)] / worst_damping_error[(0.05, method)]
        # O(eps^2): 4; measured 3.32 (hilbert) / 3.41 (peaks); O(eps) would give 2, O(eps^3) 8
        assert 2.8 < ratio < 5.6, (method, ratio)


# ----------------------------------------------------------------------------- measured data


@pytest.fixture(scope="module")
def impact_record(brb_data):
    return read_hammer_impact(brb_data)


def test_measured_backbone_of_the_jointed_beam(impact_record):
    """acc1, band 60-100 Hz, 0.2 s windows, default trim (0.25 s each end), after the impact.

    Measured (this test's numbers, 23 windows centred 0.35 .. 4.75 s):

    ======  ==========  =========  =========
    t [s]   a [m/s^2]   f [Hz]     zeta [%]
    ======  ==========  =========  =========
    0.35    23.9        80.411     0.228
    1.35     8.89       80.464     0.178
    2.35     3.83       80.515     0.155
    3.35     1.79       80.555     0.147
    4.55     0.753      80.593     0.139
    4.75     0.654      80.596     0.139
    ======  ==========  =========  =========

    The issue's "31 -> 0.75 m/s^2, 80.33 -> 80.59 Hz, 0.26 -> 0.14 %" is reproduced only if the
    first window starts 0.05 s after the impact (trim 0.05 s: 30.6 m/s^2, 80.325 Hz, 0.266 %);
    that window lies inside the band-pass transient (slowest pole 36.9 / s: e^-1.8 = 0.16 left
    at 0.05 s), so the default keeps 0.25 s. Windows at the same place do not depend on the
    trim or on the band (checked below), so the early fall of the frequency is the beam's.
    """
    assert impact_record.sample_rate == 12800.0
    assert impact_record.acceleration.shape == (3, 65536) and impact_record.time[0] == pytest.approx(-0.01)
    backbone = measured_backbone(impact_record)
    assert len(backbone) == 23
    assert backbone.time[0] == pytest.approx(0.35, abs=1e-3) and backbone.time[-1] == pytest.approx(4.75, abs=1e-3)
    # amplitude range 23.91 -> 0.654 m/s^2 (tolerance 2 %: the data are fixed, a looser bound
    # would hide a change of processing), decaying monotonically
    assert backbone.amplitude[0] == pytest.approx(23.91, rel=0.02)
    assert backbone.amplitude[-1] == pytest.approx(0.654, rel=0.02)
    assert np.all(np.diff(backbone.amplitude) < 0)
    # the frequency rises as the amplitude falls: 80.411 -> 80.596 Hz (the joint stiffens as it
    # sticks), in every window (smallest step measured +0.003 Hz)
    assert backbone.frequency_hz[0] == pytest.approx(80.411, abs=0.005)
    assert backbone.frequency_hz[-1] == pytest.approx(80.596, abs=0.005)
    assert np.all(np.diff(backbone.frequency_hz) > 0)
    # the damping falls: 0.228 % -> 0.139 %, with at most one step up of 0.0019 % (noise); the
    # low-amplitude level matches the 0.13-0.14 % of Chen et al.
    assert 100 * backbone.damping_ratio[0] == pytest.approx(0.228, abs=0.005)
    assert 100 * backbone.damping_ratio[-3:] == pytest.approx([0.139, 0.139, 0.139], abs=0.005)
    assert np.all(np.diff(backbone.damping_ratio) < 3e-5)

    # the peaks estimator (16 cycles per group) agrees: measured differences at the Hilbert
    # amplitudes up to 0.0017 Hz and 0.0023 % (the noise in the last windows)
    peaks = measured_backbone(impact_record, method="peaks")
    inside = (backbone.amplitude >= peaks.amplitude.min()) & (backbone.amplitude <= peaks.amplitude.max())
    assert inside.sum() >= 20
    frequency, damping = peaks.at_amplitude(backbone.amplitude[inside])
    assert np.max(np.abs(frequency - backbone.frequency_hz[inside])) < 0.005
    assert np.max(np.abs(damping - backbone.damping_ratio[inside])) < 5e-5

    # the first window: trim 0.05 s -> 30.6 m/s^2, 80.325 Hz, 0.266 %
    early = measured_backbone(impact_record, trim=0.05)
    assert early.amplitude[0] == pytest.approx(30.6, rel=0.02)
    assert early.frequency_hz[0] == pytest.approx(80.325, abs=0.005)
    assert 100 * early.damping_ratio[0] == pytest.approx(0.266, abs=0.005)
    # a window [0.1, 0.2] s gives the same with trim 0.1 or 0.0 and with a 45-140 Hz band
    # (measured 80.3311 / 80.3296 / 80.3354 Hz): the low frequency there is not the filter's
    t, a = impact_record.post_trigger("acc1")
    at_015 = []
    for band, trim in (((60, 100), 0.1), ((60, 100), 0.0), ((45, 140), 0.1)):
        b = hilbert_backbone(a, impact_record.sample_rate, band, window=0.1, overlap=0.5, trim=trim)
        at_015.append(b.frequency_hz[np.argmin(np.abs(b.time - 0.15))])
    assert np.ptp(at_015) < 0.01
    assert np.all(np.array(at_015) < 80.35)


def test_measured_spectral_peaks(impact_record):
    """Periodogram peaks of acc1 above 40 Hz (the bungee modes at 0.6, 12 and 27 Hz excluded).

    Measured: 80.494, 160.95, 221.694, 297.674, 378.12, 580.39, 664.62, 845.610, 1526.831,
    1765.93, 2014.72 Hz; the issue's 221.7, 297.7, 845.6, 1526.9 Hz are all there (within the
    0.2 Hz bin; 1526.83 rounds to 1526.8), and 80.49 Hz is mode 1 averaged over the decay.
    """
    peaks = measured_spectral_peaks(impact_record, min_frequency=40.0)
    for expected in (80.49, 221.7, 297.7, 845.6, 1526.9):
        assert np.min(np.abs(peaks - expected)) < 0.1, (expected, peaks)
    assert peaks.min() > 40
    # below 40 Hz the suspension (README: 0.6, 12, 27 Hz); measured peaks 7.2, 12.6, 17.1, 19.8,
    # 22.1, 23.1, 27.4, 32.0, 33.3, 35.2, 38.6 Hz (0.6 Hz is 3 bins from 0 and not resolved)
    low = measured_spectral_peaks(impact_record, max_frequency=40.0, floor_db=80.0)
    assert np.all(low < 40)
    assert np.min(np.abs(low - 12.5)) < 0.5 and np.min(np.abs(low - 27.4)) < 0.5


def test_spectral_peaks_of_two_tones():
    """Two decaying tones at 80.5 and 221.7 Hz, 2 s at 12.8 kHz: both found to within 0.02 Hz
    (bin 0.5 Hz, parabolic refinement of the Hann-windowed periodogram; measured 0.003 Hz)."""
    rate = 12800.0
    t = np.arange(int(2 * rate)) / rate
    x = (np.exp(-1.0 * t) * np.cos(2 * np.pi * 80.5 * t) + 0.1 * np.exp(-2.0 * t) * np.sin(2 * np.pi * 221.7 * t))
    peaks = spectral_peaks(x, rate, max_frequency=1000.0)
    assert peaks.size == 2
    assert peaks == pytest.approx([80.5, 221.7], abs=0.02)


# ----------------------------------------------------------------------------- plot


def test_plot_backbones_writes_png(tmp_path):
    t = np.arange(int(10 * RATE)) / RATE
    x = np.exp(-0.3 * t) * np.cos(OMEGA * t)
    backbones = {"hilbert": hilbert_backbone(x, RATE, BAND, window=0.5),
                 "peaks": peak_backbone(x, RATE, BAND, cycles=5)}
    path = plot_backbones(tmp_path / "figures" / "backbone.png", backbones, title="linear",
                          amplitude_label="x")
    assert path == tmp_path / "figures" / "backbone.png"
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 5000
    with pytest.raises(ValueError, match="at least one Backbone"):
        plot_backbones(tmp_path / "empty.png", {})
    with pytest.raises(ValueError, match=r"backbones\['x'\] must be a Backbone"):
        plot_backbones(tmp_path / "bad.png", {"x": [1, 2]})


# ----------------------------------------------------------------------------- errors


def test_bad_input_gives_clear_value_errors():
    t = np.arange(2000) / RATE
    x = np.exp(-0.3 * t) * np.cos(OMEGA * t)
    with pytest.raises(ValueError, match="Nyquist = 250 Hz"):
        hilbert_backbone(x, RATE, (5.0, 300.0), window=0.5)
    with pytest.raises(ValueError, match="band must satisfy"):
        peak_backbone(x, RATE, (20.0, 5.0))
    with pytest.raises(ValueError, match="band must be a pair"):
        hilbert_backbone(x, RATE, 10.0, window=0.5)
    with pytest.raises(ValueError, match="window = 3 s is longer than the signal after trimming"):
        hilbert_backbone(x, RATE, BAND, window=3.0)
    with pytest.raises(ValueError, match="window must be a positive length"):
        hilbert_backbone(x, RATE, BAND, window=-1.0)
    bad = x.copy()
    bad[100] = np.nan
    with pytest.raises(ValueError, match="1 non-finite samples \\(first at index 100\\)"):
        hilbert_backbone(bad, RATE, BAND, window=0.5)
    with pytest.raises(ValueError, match="1 non-finite"):
        peak_backbone(bad, RATE, BAND)
    with pytest.raises(ValueError, match="1-D array"):
        hilbert_backbone(np.ones((2, 100)), RATE, BAND, window=0.5)
    with pytest.raises(ValueError, match="sample_rate must be a positive"):
        hilbert_backbone(x, -1.0, BAND, window=0.5)
    with pytest.raises(ValueError, match="sample_rate must be a positive"):
        hilbert_backbone(x, "fast", BAND, window=0.5)
    with pytest.raises(ValueError, match="overlap must be a fraction"):
        hilbert_backbone(x, RATE, BAND, window=0.5, overlap=1.0)
    with pytest.raises(ValueError, match="filter_order must be a positive integer"):
        hilbert_backbone(x, RATE, BAND, window=0.5, filter_order=2.5)
    with pytest.raises(ValueError, match="trim = 2 s from each end leaves nothing"):
        peak_backbone(x, RATE, BAND, trim=2.0)
    with pytest.raises(ValueError, match="trim must be a non-negative"):
        peak_backbone(x, RATE, BAND, trim=-0.1)
    with pytest.raises(ValueError, match="cycles must be a positive integer"):
        peak_backbone(x, RATE, BAND, cycles=0)
    with pytest.raises(ValueError, match="cycles = 40: the trimmed signal has only"):
        peak_backbone(x, RATE, BAND, cycles=40)
    with pytest.raises(ValueError, match="min_frequency < max_frequency"):
        spectral_peaks(x, RATE, min_frequency=100.0, max_frequency=50.0)
    with pytest.raises(ValueError, match="need one length"):
        Backbone(time=[0.0, 1.0], amplitude=[1.0], frequency_hz=[1.0, 1.0], damping_ratio=[0.0, 0.0])
    # default trim: 1.21 s for 5-20 Hz at 500 Hz (slowest pole 7.6 / s), 0.25 s for the beam's band
    assert default_trim(RATE, BAND) == pytest.approx(1.2146, rel=1e-3)
    assert default_trim(12800.0, (60.0, 100.0)) == pytest.approx(0.2497, rel=1e-3)


def test_data_folder_and_reader_errors(tmp_path, monkeypatch):
    missing = tmp_path / "nowhere"
    monkeypatch.setenv("FEMROM_BRB_DATA", str(missing))
    with pytest.raises(FileNotFoundError) as error:
        brb_data_dir()
    message = str(error.value)
    assert "FEMROM_BRB_DATA" in message and str(missing) in message and "femrom data fetch brb" in message
    with pytest.raises(FileNotFoundError):
        read_hammer_impact()
    # unset: the fetched copy in the cache, here none
    monkeypatch.delenv("FEMROM_BRB_DATA")
    monkeypatch.setenv("FEMROM_CACHE", str(tmp_path / "cache"))
    with pytest.raises(FileNotFoundError, match="femrom data fetch brb"):
        brb_data_dir()
    monkeypatch.setenv("FEMROM_BRB_DATA", str(tmp_path))
    assert brb_data_dir() == tmp_path
    with pytest.raises(FileNotFoundError, match="hammer_impact.npz"):
        read_hammer_impact()
    np.savez(tmp_path / "hammer_impact.npz", t=np.arange(10) / 100.0)
    with pytest.raises(ValueError, match=r"missing arrays \['acc'\]"):
        read_hammer_impact(tmp_path)
    np.savez(tmp_path / "uneven.npz", t=np.array([0.0, 0.1, 0.3]), acc=np.zeros((1, 3)))
    with pytest.raises(ValueError, match="uniformly increasing"):
        read_hammer_impact(tmp_path / "uneven.npz")
    t = np.arange(-2, 30) / 100.0
    np.savez(tmp_path / "ok.npz", t=t, acc=np.vstack([np.sin(t), np.cos(t)]))
    record = read_hammer_impact(tmp_path / "ok.npz")
    assert record.channels == ("acc1", "acc2") and record.sample_rate == 100.0
    assert record.post_trigger("acc2")[0][0] == 0.0
    with pytest.raises(ValueError, match="channel must be one of acc1, acc2"):
        record.channel("acc3")
    with pytest.raises(ValueError, match="method must be 'hilbert' or 'peaks'"):
        measured_backbone(record, method="wavelet")
