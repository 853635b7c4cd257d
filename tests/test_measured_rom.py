"""Data-only ROMs from band-limited multi-channel records (issue 17, part 4).

``femrom.post.modal_record`` on synthetic records with known modal coordinates, then
the jointed beam's measured hammer-impact ring-down (``cases/jointed_beam_measured.py``;
skipped when the data folder is absent: ``$FEMROM_BRB_DATA`` or ``../shared/data/brb``).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from femrom.post import band_limited_integrals, modal_record, read_hammer_impact

RATE = 2000.0
BAND = (60.0, 100.0)


def _decay(f_hz, zeta, amplitude, t):
    w = 2 * np.pi * f_hz
    return amplitude * np.exp(-zeta * w * t) * np.cos(w * np.sqrt(1 - zeta**2) * t)


def _shapes(c, r, seed=0):
    return np.linalg.qr(np.random.default_rng(seed).standard_normal((c, r)))[0]


def test_two_in_band_modes_are_recovered_exactly_by_their_subspace():
    t = np.arange(4000) / RATE
    modal = np.vstack([_decay(72.0, 0.01, 5.0, t), _decay(91.0, 0.02, 2.0, t)])   # accelerations
    phi = _shapes(3, 2)
    record = modal_record(phi @ modal, RATE, BAND, rank=2, trim=0.1)
    # the channels' band displacement has rank 2: the third singular value is round-off
    # (observed 1.2e-15 relative; 1e-12 leaves room for the FFT's round-off), the second is
    # mode 2's (observed 0.079 s[0]: weaker and faster decaying; > 0.03 says it is seen)
    s = record.singular_values
    assert s[2] < 1e-12 * s[0] and s[1] > 0.03 * s[0]
    # the shapes span the true shapes (projectors equal to round-off)
    np.testing.assert_allclose(record.shapes @ record.shapes.T, phi @ phi.T, atol=1e-10)
    # the coordinates are the true modal band integrals in the recovered frame, exactly
    # (by linearity of the band integration; round-off of two FFTs)
    truth = band_limited_integrals(modal, RATE, BAND)
    R = record.shapes.T @ phi
    kept = slice(200, 4000 - 200)
    for got, ref in ((record.data.states, truth.displacement), (record.data.velocities, truth.velocity),
                     (record.data.accelerations, truth.acceleration)):
        scale = np.abs(ref).max()
        np.testing.assert_allclose(got, R @ ref[:, kept], atol=1e-10 * scale)
    assert record.data.times[0] == pytest.approx(0.1) and record.data.inputs is None
    # acceleration of one channel from modal accelerations
    np.testing.assert_allclose(record.channel_acceleration(record.data.accelerations, 1),
                               (phi @ truth.acceleration)[1, kept], atol=1e-10 * np.abs(modal).max())


def test_one_mode_in_the_band_gives_rank_one_and_its_shape():
    t = np.arange(8000) / RATE
    phi = _shapes(3, 2, seed=1)
    # mode 1 at 80 Hz in the band, mode 2 at 300 Hz (ten times stronger) outside it
    acc = phi @ np.vstack([_decay(80.0, 0.005, 1.0, t), _decay(300.0, 0.005, 10.0, t)])
    record = modal_record(acc, RATE, BAND, rank=1, trim=0.25, every=2)
    s = record.singular_values
    # what leaks of the 300 Hz mode through the band's flanks (the abrupt start) is tiny:
    # observed s2/s1 1.6e-4; 1e-3 bounds it well below the in-band mode
    assert s[1] < 1e-3 * s[0]
    # the shape is mode 1's up to the sign convention (largest entry positive): observed 9e-6 off; 1e-3
    shape = phi[:, 0] * np.sign(phi[np.argmax(np.abs(phi[:, 0])), 0])
    np.testing.assert_allclose(record.shapes[:, 0], shape, atol=1e-3)
    assert record.data.states.shape == (1, (8000 - 1000 + 1) // 2)
    assert record.data.diagnostics["dt"] == pytest.approx(2 / RATE)


@pytest.mark.parametrize("kwargs, word", [({"rank": 4}, "rank"), ({"rank": 0}, "rank"),
                                          ({"every": 0}, "every"), ({"trim": 10.0}, "trim")])
def test_bad_arguments_raise_one_line(kwargs, word):
    acc = np.random.default_rng(0).standard_normal((3, 1000))
    with pytest.raises(ValueError, match=word):
        modal_record(acc, RATE, BAND, **kwargs)
