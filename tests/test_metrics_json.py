"""metrics.json is strict JSON: no NaN or infinity anywhere, a null where no number is finite."""

import json
import math

import numpy as np

from femrom.post import write_metrics
from femrom.study.experiments.canonical_window import window_metrics


def _numbers(value):
    if isinstance(value, dict):
        for v in value.values():
            yield from _numbers(v)
    elif isinstance(value, list):
        for v in value:
            yield from _numbers(v)
    else:
        yield value


def test_non_finite_values_are_written_as_null_and_the_file_is_strict_json(tmp_path):
    path = write_metrics(tmp_path / "metrics.json", {
        "rows": [{"error": float("inf"), "growth": np.float64("nan"), "ok": 1.5, "array": np.array([1.0, -np.inf])}],
        "finite": np.float32(2.0)})
    text = path.read_text()
    # json.loads accepts NaN and Infinity unless told not to: parse strictly
    saved = json.loads(text, parse_constant=lambda name: (_ for _ in ()).throw(ValueError(name)))
    assert saved == {"rows": [{"error": None, "growth": None, "ok": 1.5, "array": [1.0, None]}], "finite": 2.0}
    assert "nan" not in text.lower() and "inf" not in text.lower()
    assert all(v is None or not isinstance(v, float) or math.isfinite(v) for v in _numbers(saved))


def test_a_diverged_reconstruction_says_when():
    class Conservative:
        @staticmethod
        def hamiltonian(Q, P):
            return 0.5 * np.sum(Q**2 + P**2, axis=0)

    Q = np.ones((2, 10))
    Qr = Q.copy()
    Qr[:, 6:] = np.inf
    out = window_metrics(Conservative, Q, Q, Qr, Q, slice(0, 5), slice(5, 10), 0.1)
    assert out["finite"] is False and abs(out["blowup_time"] - 0.6) < 1e-12
    assert out["diverged"] == "at t = 0.6 (reconstructed state not finite)"
    assert out["train_error"] == 0.0 and out["test_error"] == float("inf")
